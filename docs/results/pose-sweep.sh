#!/bin/bash
# The pose sweep of docs/results.md, Results 11: 5 UR5e pose goals x 5 seeds; for each, the
# expert (true cost), then LQR+GAIfO from its 5 demonstrations for 20 iterations, with the
# default settings and with the critic's terminal pairs (critic_terminal_pairs = 10,
# docs/design.md §5 D44).
# Run from the workspace root after `cargo build --release`: bash docs/results/pose-sweep.sh OUT
set -euo pipefail
B=$PWD/target/release
OUT=${1:-runs/pose-sweep}
mkdir -p "$OUT" && cd "$OUT"
poses=("-0.4383,-0.2993,0.3748,0.4667,-0.108,-0.8096" "-0.5573,0.1783,0.437,-0.2501,-0.1565,-2.3545"
       "-0.1903,-0.439,0.363,0.7739,-0.3294,0.2644" "-0.6709,-0.2014,0.4699,-0.0232,0.0221,-1.4707"
       "-0.4208,0.2432,0.449,1.2021,-0.5946,-2.5508")
printf '[sim]\nmodel = "ur5e"\n' > train.toml
printf 'critic_terminal_pairs = 10\n[sim]\nmodel = "ur5e"\n' > terminal.toml
for i in 0 1 2 3 4; do
  printf '[sim]\nmodel = "ur5e"\n\n[task]\njoints = 6\ngoal_pose = [%s]\n' "${poses[$i]}" > pose$i.toml
  for s in 0 1 2 3 4; do
    "$B/learner" expert --config pose$i.toml --seed $s --out e$i-$s --threads 2 --json | sed "s/^/expert $i $s /" >> results.txt
    "$B/learner" train --demos e$i-$s/demos.npz --config train.toml --seed $s --iterations 20 \
      --out t$i-$s --threads 2 --json | sed "s/^/train $i $s /" >> results.txt
    "$B/learner" train --demos e$i-$s/demos.npz --config terminal.toml --seed $s --iterations 20 \
      --out p$i-$s --threads 2 --json | sed "s/^/terminal $i $s /" >> results.txt
  done
done
