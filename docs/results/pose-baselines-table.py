#!/usr/bin/env python3
"""The table of docs/results.md for the baselines on the six-joint pose goals: reads OUT/results.txt
of docs/results/pose-baselines.sh and each run's gaifo_log.csv; prints per pose and learner the
mean (worst) final distance (mm) and orientation error (deg) of the last noise-free episode and
the runs within 1 cm and 3 deg; over all poses the same, the seeds, the mean normalised
performance and the median learner CPU per episode (ms). Usage: python3 docs/results/pose-baselines-table.py OUT"""
import csv, json, os, statistics, sys

out = sys.argv[1] if len(sys.argv) > 1 else "runs/pose-baselines"
rows = {}
for line in open(os.path.join(out, "results.txt")):
    parts = line.split(" ", 4)
    if parts[0] != "train":
        continue
    pose, seed, algo, j = int(parts[1]), int(parts[2]), parts[3], json.loads(parts[4])
    log = list(csv.DictReader(open(os.path.join(out, j["out"], "gaifo_log.csv"))))
    cpu = [float(r["cpu_learner_s"]) for r in log]
    rows.setdefault((algo, pose), []).append(
        (seed, 1e3 * j["final_distance_m"], j["final_orientation_error_deg"], j["final_performance"],
         1e3 * statistics.median(cpu) / 5.0, j["iterations"]))
names = {"lqr-gaifo": "LQR+GAIfO", "replay-mean": "mean path", "bco": "BCO", "gaifo-td3": "GAIfO (TD3)"}
algos = [a for a in names if any(k[0] == a for k in rows)]
print("| pose | " + " | ".join(names[a] for a in algos) + " |")
print("|---|" + "---|" * len(algos))


def cell(r):
    d, o = [x[1] for x in r], [x[2] for x in r]
    ok = sum(1 for x in r if x[1] <= 10 and x[2] <= 3)
    return f"{statistics.mean(d):.1f} ({max(d):.1f}) mm, {statistics.mean(o):.1f} ({max(o):.1f})°, {ok}/{len(r)}"


for pose in range(5):
    print(f"| {pose} | " + " | ".join(cell(rows[(a, pose)]) if (a, pose) in rows else "–" for a in algos) + " |")
every = {a: [x for (b, _), r in rows.items() if b == a for x in r] for a in algos}
print("| all | " + " | ".join(cell(every[a]) for a in algos) + " |")
print("| seeds | " + " | ".join(",".join(str(s) for s in sorted({x[0] for x in every[a]})) for a in algos) + " |")
print("| normalised | " + " | ".join(f"{statistics.mean(x[3] for x in every[a]):.3f}" for a in algos) + " |")
print("| learner CPU per episode (ms) | " + " | ".join(f"{statistics.median(x[4] for x in every[a]):.0f}" for a in algos) + " |")
