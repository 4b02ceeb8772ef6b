#!/bin/bash
# The baselines on the six-joint pose task of docs/results.md, Results 11 (its five UR5e pose
# goals, the experts of docs/results/pose-sweep.sh): for each pose and seed 0-4 the expert (true
# cost) and, on its 5 demonstrations, LQR+GAIfO and the mean path; BCO on seeds 0-2 and
# GAIfO (TD3) on seed 0 (their learner costs 20-40x LQR+GAIfO's per iteration). 20 iterations of
# 5 noisy episodes, as the sweep. The mean path learns nothing and its noise-free episode is the
# same at every iteration, so it runs one.
# Run from the workspace root after `cargo build --release`: bash docs/results/pose-baselines.sh OUT
set -euo pipefail
B=$PWD/target/release
OUT=${1:-runs/pose-baselines}
T=${THREADS:-1}
mkdir -p "$OUT" && cd "$OUT"
poses=("-0.4383,-0.2993,0.3748,0.4667,-0.108,-0.8096" "-0.5573,0.1783,0.437,-0.2501,-0.1565,-2.3545"
       "-0.1903,-0.439,0.363,0.7739,-0.3294,0.2644" "-0.6709,-0.2014,0.4699,-0.0232,0.0221,-1.4707"
       "-0.4208,0.2432,0.449,1.2021,-0.5946,-2.5508")
printf '[sim]\nmodel = "ur5e"\n' > train.toml
train() { # pose seed algo iterations
  "$B/learner" train --algo "$3" --demos "e$1-$2/demos.npz" --config train.toml --seed "$2" \
    --iterations "$4" --out "$3-$1-$2" --threads "$T" --json | sed "s/^/train $1 $2 $3 /" >> results.txt
}
for i in 0 1 2 3 4; do
  printf '[sim]\nmodel = "ur5e"\n\n[task]\njoints = 6\ngoal_pose = [%s]\n' "${poses[$i]}" > pose$i.toml
  for s in 0 1 2 3 4; do
    [ -f "e$i-$s/demos.npz" ] || "$B/learner" expert --config pose$i.toml --seed $s --out e$i-$s \
      --threads "$T" --json | sed "s/^/expert $i $s /" >> results.txt
    train $i $s lqr-gaifo 20
    train $i $s replay-mean 1
    if [ $s -le 2 ]; then train $i $s bco 20; fi
    if [ $s -eq 0 ]; then train $i $s gaifo-td3 20; fi
  done
done
