#!/usr/bin/env bash
# What servoj's lookahead_time and gain do to learning over RTDE: the expert learning in
# lockstep over RTDE against `hil-sim ur-sim --lockstep`, once with the ideal servo and once
# per (lookahead_time, gain) with `--servoj tracking` (docs/ur.md, "servoj").
# Usage: scripts/servoj-learning.sh [OUT_DIR] [ITERATIONS]   (binaries from target/release)
# Prints one CSV line per setting and iteration: setting,iteration,eval_cost,final_distance_m.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
bin="$root/target/release"
out="${1:-servoj-learning}"
iters="${2:-10}"
mkdir -p "$out"
out="$(cd "$out" && pwd)"
cat > "$out/learner.toml" <<TOML
samples = 5
seed = 7
iterations = $iters
random_episodes = 1
[serve]
wait_report_s = 1.0
idle_sleep_us = 200
TOML
echo "setting,iteration,eval_cost,final_distance_m"
n=0
for setting in ideal 0.03:2000 0.1:300 0.2:300 0.1:100 0.2:100; do
  n=$((n + 1))
  d="$out/$setting"
  rm -rf "$d"; mkdir -p "$d"
  if [ "$setting" = ideal ]; then servoj=ideal; la=0.1; g=300; else servoj=tracking; la=${setting%:*}; g=${setting#*:}; fi
  "$bin/hil-sim" ur-sim --lockstep --servoj "$servoj" --rtde-port 0 --secondary-port 0 \
    --dashboard-port 0 > "$d/sim.json" 2> "$d/sim.log" &
  sim=$!
  for _ in $(seq 100); do [ -s "$d/sim.json" ] && break; sleep 0.1; done
  ports=$(python3 -c "import json,sys;j=json.load(open('$d/sim.json'));print(j['rtde'].rsplit(':',1)[1],j['secondary'].rsplit(':',1)[1],j['dashboard'].rsplit(':',1)[1])")
  read -r rtde sec dash <<< "$ports"
  cat > "$d/ctl.toml" <<TOML
seed = 7
noisy_episodes = 5
eval_episodes = 1
cycles_per_table = 1
mode = "lockstep"
[arm]
backend = "ur"
[arm.ur]
host = "127.0.0.1"
rtde_port = $rtde
secondary_port = $sec
dashboard_port = $dash
check_model = false
reverse_port = 0
receive_timeout_ms = 1000
servoj_lookahead_time_s = $la
servoj_gain = $g
TOML
  prefix="servoj-$$-$n"
  "$bin/learner" serve --config "$out/learner.toml" --prefix "$prefix" --out "$d/run" --json \
    > "$d/learner.json" 2> "$d/learner.log" &
  learner=$!
  "$bin/rt-controller" run --config "$d/ctl.toml" --prefix "$prefix" --json \
    > "$d/ctl.json" 2> "$d/ctl.log" &
  ctl=$!
  wait $learner
  kill -TERM $ctl; wait $ctl || true
  kill -TERM $sim; wait $sim || true
  python3 - "$d/learner.json" "$setting" <<'PY'
import json, sys
j = json.loads(open(sys.argv[1]).read().strip().splitlines()[-1])
for i, row in enumerate(j["log"]):
    print(f"{sys.argv[2]},{i + 1},{j['eval_costs'][i]:.6g},{row['final_distance_m']:.6g}")
PY
done
