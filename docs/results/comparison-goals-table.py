#!/usr/bin/env python3
"""The tables of docs/results.md for the comparison on the workspace goals: reads summary_goals.json
and summary.json of each `learner experiment comparison` output folder given (with
comparison_workspace_goals) and prints (1) per learner over all goals and seeds: runs, episodes to
normalised 0.9 and to 1 cm, final distance (cm) and normalised performance at iterations 10, 20, 50,
100, learner CPU per episode (median per iteration / N); (2) per goal, the final distance at
iterations 20 and 100. Usage: python3 docs/results/comparison-goals-table.py DIR..."""
import json, os, sys

names = {"lqr-gaifo": "LQR+GAIfO", "replay-mean": "mean path", "bco": "BCO(α = 1)", "gaifo-td3": "GAIfO (TD3)"}


def at(points, it, scale):
    for i, m, _ in points:
        if i == it - 1:
            return f"{m:.3f}" if scale == 1 else f"{scale * m:.2f}"
    # A learner with fewer iterations (the mean path) stands at its last one.
    return (f"{scale * points[-1][1]:.2f}" if scale != 1 else f"{points[-1][1]:.3f}") + "*"


def reach(r):
    if r["seeds_reached"] == 0:
        return f"never (0/{r['seeds']})"
    bound = "≥ " if r["seeds_reached"] < r["seeds"] else ""
    return f"{bound}{r['episodes_mean']:.0f} ± {r['episodes_se']:.0f} ({r['seeds_reached']}/{r['seeds']})"


print("| learner | runs (goals × seeds) | episodes to 0.9 | episodes to 1 cm | final distance at 10 / 20 / 50 / 100 (cm) | normalised at 10 / 20 / 50 / 100 | learner CPU per episode (ms) |")
print("|---|---|---|---|---|---|---|")
per_goal = {}
for d in sys.argv[1:]:
    for row in json.load(open(os.path.join(d, "summary_goals.json"))):
        its = [10, 20, 50, 100]
        dist = " / ".join(at(row["final_distance_m"], i, 100.0) for i in its)
        perf = " / ".join(at(row["performance"], i, 1) for i in its)
        cpu = row["learner_cpu_ms_median"] / row["episodes_per_iteration"]
        print(f"| {names.get(row['variant'], row['variant'])} | {row['seeds']} | {reach(row['to_performance_0_9'])} "
              f"| {reach(row['to_within_1cm'])} | {dist} | {perf} | {cpu:.1f} |")
    for row in json.load(open(os.path.join(d, "summary.json"))):
        v, g = row["variant"].split(" goal ")
        per_goal.setdefault(g, {})[v] = " / ".join(at(row["final_distance_m"], i, 100.0) for i in [20, 100])
print()
learners = [v for v in names if any(v in x for x in per_goal.values())]
print("| goal | " + " | ".join(names[v] for v in learners) + " |")
print("|---|" + "---|" * len(learners))
for g, x in per_goal.items():
    print(f"| {g} | " + " | ".join(x.get(v, "–") for v in learners) + " |")
