#!/usr/bin/env python3
"""The tables of docs/results.md for the comparison on the workspace goals, from the comparison.csv
of each `learner experiment comparison` output folder given (run with comparison_workspace_goals;
folders of one learner's other seeds pool with it): (1) per learner over all goals and seeds:
runs, training episodes to normalised 0.9 and to 1 cm (i * N for a run whose noise-free episode
first reached it at iteration i, counted from 0; mean ± standard error over the runs that did,
k/n), final distance (cm) and normalised performance at iterations 10, 20, 50, 100 (means; a
learner with fewer iterations, the mean path, stands at its last, marked *), learner CPU per
episode (median cpu_learner_s per iteration / N, ms); (2) per goal, the final distance at
iterations 20 and 100. Usage: python3 docs/results/comparison-goals-table.py DIR..."""
import csv, os, statistics, sys

names = {"lqr-gaifo": "LQR+GAIfO", "replay-mean": "mean path", "bco": "BCO(α = 1)", "gaifo-td3": "GAIfO (TD3)"}
N = 5
runs = {}  # (learner, goal, seed) -> rows in iteration order
for d in sys.argv[1:]:
    for r in csv.DictReader(open(os.path.join(d, "comparison.csv"))):
        learner, goal = r["variant"].split(" goal ")
        runs.setdefault((learner, goal, r["seed"]), []).append(r)


def at(rs, it, key):
    return float(rs[min(it, len(rs)) - 1][key]), it > len(rs)


def reach(curves, ok):
    eps = [N * next(i for i, v in enumerate(c) if ok(v)) for c in curves if any(ok(v) for v in c)]
    if not eps:
        return f"never (0/{len(curves)})"
    se = statistics.stdev(eps) / len(eps) ** 0.5 if len(eps) > 1 else 0.0
    bound = "≥ " if len(eps) < len(curves) else ""
    return f"{bound}{statistics.mean(eps):.0f} ± {se:.0f} ({len(eps)}/{len(curves)})"


learners = [l for l in names if any(k[0] == l for k in runs)]
goals = list(dict.fromkeys(k[1] for k in runs))
print("| learner | runs (goals × seeds) | episodes to 0.9 | episodes to 1 cm | final distance at 10 / 20 / 50 / 100 (cm) | normalised at 10 / 20 / 50 / 100 | learner CPU per episode (ms) |")
print("|---|---|---|---|---|---|---|")
for l in learners:
    rs = [v for k, v in runs.items() if k[0] == l]
    perf = [[float(r["normalised_performance"]) for r in x] for x in rs]
    dist = [[float(r["final_distance_m"]) for r in x] for x in rs]
    cells = []
    for key, scale, fmt in [("final_distance_m", 100.0, "{:.2f}"), ("normalised_performance", 1.0, "{:.3f}")]:
        c = []
        for it in [10, 20, 50, 100]:
            vals = [at(x, it, key) for x in rs]
            c.append(fmt.format(scale * statistics.mean(v for v, _ in vals)) + ("*" if vals[0][1] else ""))
        cells.append(" / ".join(c))
    cpu = 1e3 * statistics.median(float(r["cpu_learner_s"]) for x in rs for r in x) / N
    seeds = sorted({k[2] for k in runs if k[0] == l}, key=int)
    print(f"| {names[l]} | {len(rs)} (seeds {','.join(seeds)}) | {reach(perf, lambda p: p >= 0.9)} "
          f"| {reach(dist, lambda d: d <= 0.01)} | {cells[0]} | {cells[1]} | {cpu:.1f} |")
print()
print("| goal | " + " | ".join(names[l] for l in learners) + " |")
print("|---|" + "---|" * len(learners))
for g in goals:
    row = []
    for l in learners:
        rs = [v for k, v in runs.items() if k[0] == l and k[1] == g]
        row.append(" / ".join(f"{100 * statistics.mean(at(x, it, 'final_distance_m')[0] for x in rs):.2f}" for it in [20, 100]))
    print(f"| {g} | " + " | ".join(row) + " |")
