"""An independent DDS implementation against hil-sim and rt-controller: CycloneDDS (PyPI
`cyclonedds`, C underneath) with the ROS 2 types declared as IDL in `ros2_idl.py`, on the
loopback only (no multicast; peers found by unicast on 127.0.0.1), as a ROS 2 node would see
the topics.

1. `hil-sim ros2-sim`: reads `/joint_states` (six named joints, their rate, the start pose),
   the robot and safety modes, then moves the arm by publishing
   `/forward_position_controller/commands` (shoulder pan +0.2 rad) and sees it arrive there.
2. `hil-sim ros2-sim` + `rt-controller run` (the `ros2` arm) + `learner serve`: reads the
   controller's commands on `/forward_position_controller/commands` beside ros2-sim, and checks
   them against the joint states (six values, the wrist's as configured, within the limits).

Exits 0 when every check passes, and prints one line per check. Run from the repository root
after `cargo build --release --workspace --all-targets`, with a venv that has `cyclonedds`:

    python3 -m venv /tmp/ros2-venv && /tmp/ros2-venv/bin/pip install cyclonedds
    /tmp/ros2-venv/bin/python scripts/ros2/ros2_check.py
"""

import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
BIN = ROOT / "target" / "release"
DOMAIN = 140  # a ROS domain of its own: the Rust tests use 120-125 and 201

# Loopback only, no multicast, peers by unicast on the well-known ports of 127.0.0.1 (what the
# Rust side's `network = "loopback"` does).
os.environ["CYCLONEDDS_URI"] = (
    "<CycloneDDS><Domain id='any'><General><Interfaces><NetworkInterface name='lo'/>"
    "</Interfaces><AllowMulticast>false</AllowMulticast></General><Discovery>"
    "<ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>30</MaxAutoParticipantIndex>"
    "<Peers><Peer address='127.0.0.1'/></Peers></Discovery></Domain></CycloneDDS>"
)

sys.path.insert(0, str(HERE))
from cyclonedds.core import Qos, Policy  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.pub import DataWriter  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402

import ros2_idl as m  # noqa: E402

UR_JOINTS = [
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
]
START_Q = [0.0, -2.0, 2.4]  # the task's default start pose (shared TaskConfig)
QOS = Qos(
    Policy.Reliability.Reliable(duration(milliseconds=100)),
    Policy.History.KeepLast(10),
    Policy.Durability.Volatile,
)

failures = []


def check(ok, what):
    print(("ok    " if ok else "FAIL  ") + what, flush=True)
    if not ok:
        failures.append(what)


def spawn(args, log):
    return subprocess.Popen(args, stdout=subprocess.PIPE, stderr=open(log, "w"), cwd=ROOT)


def take_for(reader, seconds):
    out, t0 = [], time.monotonic()
    while time.monotonic() - t0 < seconds:
        got = reader.take(N=100)
        out.extend(got)
        if not got:
            time.sleep(0.002)
    return out


def by_name(js):
    return dict(zip(js.name, js.position))


def part1(dp, tmp):
    sim = spawn([str(BIN / "hil-sim"), "ros2-sim", "--domain-id", str(DOMAIN)], tmp / "sim1.log")
    try:
        js_r = DataReader(dp, Topic(dp, "rt/joint_states", m.JointState), qos=QOS)
        sm_r = DataReader(dp, Topic(dp, "rt/io_and_status_controller/safety_mode", m.SafetyMode), qos=QOS)
        rm_r = DataReader(dp, Topic(dp, "rt/io_and_status_controller/robot_mode", m.RobotMode), qos=QOS)
        cmd_w = DataWriter(dp, Topic(dp, "rt/forward_position_controller/commands", m.Float64MultiArray), qos=QOS)
        t0 = time.monotonic()
        first = []
        while not first and time.monotonic() - t0 < 20:
            first = js_r.take(N=10)
            time.sleep(0.01)
        check(bool(first), f"CycloneDDS reads hil-sim's /joint_states (after {time.monotonic() - t0:.2f} s)")
        if not first:
            return
        states = take_for(js_r, 2.0)
        stamps = [s.header.stamp.sec + 1e-9 * s.header.stamp.nanosec for s in states]
        rate = (len(stamps) - 1) / (stamps[-1] - stamps[0]) if len(stamps) > 1 else 0
        check(sorted(states[-1].name) == sorted(UR_JOINTS), f"six UR joints, in the order {states[-1].name}")
        check(abs(rate - 500) < 5, f"stamps at {rate:.1f} Hz (500 expected); {len(states)} received in 2 s")
        q = by_name(states[-1])
        check(all(abs(q[UR_JOINTS[j]] - START_Q[j]) < 1e-3 for j in range(3)),
              f"at the start pose: {[round(q[n], 4) for n in UR_JOINTS[:3]]}")
        modes = (rm_r.take(N=100), sm_r.take(N=100))
        check(bool(modes[0]) and modes[0][-1].mode == 7 and bool(modes[1]) and modes[1][-1].mode == 1,
              f"robot mode RUNNING (7), safety mode NORMAL (1): {modes[0][-1:]}, {modes[1][-1:]}")
        target = [START_Q[0] + 0.2, START_Q[1], START_Q[2], -math.pi / 2, math.pi / 2, 0.0]
        layout = m.MultiArrayLayout([], 0)
        t0 = time.monotonic()
        moved = None
        while time.monotonic() - t0 < 5:
            cmd_w.write(m.Float64MultiArray(layout, target))
            for s in take_for(js_r, 0.05):
                q = by_name(s)
                if abs(q["shoulder_pan_joint"] - target[0]) < 2e-3:
                    moved = (time.monotonic() - t0, q)
            if moved:
                break
        check(moved is not None,
              "a command from CycloneDDS moves the arm: shoulder pan at "
              + (f"{moved[1]['shoulder_pan_joint']:.4f} rad after {moved[0]:.2f} s" if moved else "no"))
    finally:
        sim.terminate()
        sim.wait(10)


def part2(dp, tmp):
    prefix = f"ros2-check-{os.getpid()}"
    (tmp / "ctl.toml").write_text(
        "mode = \"real_time\"\npacing = \"arm\"\nseed = 1\n[task]\nhorizon = 20\n"
        f"[arm]\nbackend = \"ros2\"\n[arm.ros2]\ndomain_id = {DOMAIN}\n"
    )
    (tmp / "learner.toml").write_text("samples = 2\nseed = 1\niterations = 2\n[task]\nhorizon = 20\n")
    sim = spawn([str(BIN / "hil-sim"), "ros2-sim", "--domain-id", str(DOMAIN), "--time-compression", "1"],
                tmp / "sim2.log")
    ctl = spawn([str(BIN / "rt-controller"), "run", "--config", str(tmp / "ctl.toml"), "--prefix", prefix,
                 "--json"], tmp / "ctl.log")
    lrn = spawn([str(BIN / "learner"), "serve", "--config", str(tmp / "learner.toml"), "--prefix", prefix,
                 "--out", str(tmp / "out")], tmp / "learner.log")
    try:
        js_r = DataReader(dp, Topic(dp, "rt/joint_states", m.JointState), qos=QOS)
        cmd_r = DataReader(dp, Topic(dp, "rt/forward_position_controller/commands", m.Float64MultiArray), qos=QOS)
        def away(c):
            return max(abs(c.data[j] - START_Q[j]) for j in range(3)) > 0.01

        cmds, states, t0 = [], [], time.monotonic()
        # Until the controller has reset the arm and runs the learner's first table (its
        # commands leave the start pose).
        while time.monotonic() - t0 < 60 and not (len(cmds) >= 200 and any(away(c) for c in cmds)):
            cmds.extend(cmd_r.take(N=100))
            states.extend(js_r.take(N=100))
            time.sleep(0.005)
        check(len(cmds) >= 200 and any(away(c) for c in cmds),
              f"CycloneDDS reads rt-controller's commands: {len(cmds)} in {time.monotonic() - t0:.1f} s, "
              f"{sum(away(c) for c in cmds)} of them away from the start pose")
        if not cmds:
            return
        six = all(len(c.data) == 6 for c in cmds)
        wrist = all(abs(c.data[3] + math.pi / 2) < 1e-9 and abs(c.data[4] - math.pi / 2) < 1e-9 and abs(c.data[5]) < 1e-9
                    for c in cmds)
        check(six and wrist, "six positions per command, the wrist at its locked angles (-pi/2, pi/2, 0)")
        limits = [(-2 * math.pi, 2 * math.pi), (-math.pi, 0.0), (-math.pi, math.pi)]
        check(all(lo <= c.data[j] <= hi for c in cmds for j, (lo, hi) in enumerate(limits)),
              "every commanded active joint within the UR5's limits")
        q = by_name(states[-1]) if states else {}
        last = cmds[-1].data
        near = q and all(abs(q[UR_JOINTS[j]] - last[j]) < 0.5 for j in range(3))
        check(bool(near), f"the last command {[round(v, 3) for v in last[:3]]} is near the arm "
                          f"{[round(q.get(n, float('nan')), 3) for n in UR_JOINTS[:3]]}")
    finally:
        for p in (lrn, ctl, sim):
            p.terminate()
        for p in (lrn, ctl, sim):
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()
        if failures:
            for log in ("ctl.log", "learner.log", "sim2.log"):
                print(f"--- {log}\n" + (tmp / log).read_text()[-3000:])


def main():
    for b in ("hil-sim", "rt-controller", "learner"):
        if not (BIN / b).exists():
            sys.exit(f"{BIN / b} not found: cargo build --release --workspace --all-targets first")
    dp = DomainParticipant(DOMAIN)
    with tempfile.TemporaryDirectory(prefix="ros2-check-") as d:
        tmp = Path(d)
        part1(dp, tmp)
        part2(dp, tmp)
    print(f"{len(failures)} failed" if failures else "all checks passed")
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
