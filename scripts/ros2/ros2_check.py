"""An independent DDS implementation against hil-sim and rt-controller: CycloneDDS (PyPI
`cyclonedds`, C underneath) with the ROS 2 types declared as IDL in `ros2_idl.py`, on the
loopback only (no multicast; peers found by unicast on 127.0.0.1), as a ROS 2 node would see
the topics.

1. `hil-sim ros2-sim`: reads `/joint_states` (six named joints, their rate, the start pose),
   the robot and safety modes, then moves the arm by publishing
   `/forward_position_controller/commands` (shoulder pan +0.2 rad) and sees it arrive there.
2. `hil-sim ros2-sim` + `rt-controller run` (the `ros2` arm) + `learner serve`: reads the
   controller's commands on `/forward_position_controller/commands` beside ros2-sim, and checks
   them against the joint states (six values, the wrist's as configured, within the limits),
   and the live view's goal and end-effector points beside them.
3. `hil-sim serve` (the iceoryx2 arm, real time x10) + `rt-controller run` with `[live_view]` and
   its joint states + `learner serve`: reads the live view (`/rt_controller/goal`,
   `/end_effector`, `/episode`, `/table_version`, `/joint_states`) and checks it: the task's
   goal in frame `base`, every end-effector point at the forward kinematics (UR5 DH, computed
   here) of the joint state of the same stamp, episodes and table versions in order and
   advancing.

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
DOMAIN = 140  # a ROS domain of its own: the Rust tests use 120-130 and 201-202, rclpy_check.py 141-143

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
GOAL = [-0.45, -0.25, 0.25]  # the task's default goal (shared TaskConfig), m
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


def stop(procs, tmp, logs):
    """Terminates `procs` (kills what does not end within 10 s); prints `logs` if a check failed."""
    for p in procs:
        p.terminate()
    for p in procs:
        try:
            p.wait(10)
        except subprocess.TimeoutExpired:
            p.kill()
    if failures:
        for log in logs:
            print(f"--- {log}\n" + (tmp / log).read_text()[-3000:])


def controller_and_learner(tmp, prefix, tag):
    """rt-controller with `ctl{tag}.toml` and learner serve with `learner.toml` on `prefix`."""
    ctl = spawn([str(BIN / "rt-controller"), "run", "--config", str(tmp / f"ctl{tag}.toml"), "--prefix", prefix,
                 "--json"], tmp / f"ctl{tag}.log")
    lrn = spawn([str(BIN / "learner"), "serve", "--config", str(tmp / "learner.toml"), "--prefix", prefix,
                 "--out", str(tmp / f"out{tag}")], tmp / f"learner{tag}.log")
    return ctl, lrn


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
        f"[live_view]\nenabled = true\ndomain_id = {DOMAIN}\n"
    )
    (tmp / "learner.toml").write_text("samples = 2\nseed = 1\niterations = 2\n[task]\nhorizon = 20\n")
    sim = spawn([str(BIN / "hil-sim"), "ros2-sim", "--domain-id", str(DOMAIN), "--time-compression", "1"],
                tmp / "sim2.log")
    ctl, lrn = controller_and_learner(tmp, prefix, "")
    try:
        js_r = DataReader(dp, Topic(dp, "rt/joint_states", m.JointState), qos=QOS)
        cmd_r = DataReader(dp, Topic(dp, "rt/forward_position_controller/commands", m.Float64MultiArray), qos=QOS)
        goal_r = DataReader(dp, Topic(dp, "rt/rt_controller/goal", m.PointStamped), qos=QOS)
        ee_r = DataReader(dp, Topic(dp, "rt/rt_controller/end_effector", m.PointStamped), qos=QOS)

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
        goals, ees, t1 = [], [], time.monotonic()
        while time.monotonic() - t1 < 20 and not (goals and len(ees) >= 5):
            goals.extend(goal_r.take(N=100))
            ees.extend(ee_r.take(N=100))
            time.sleep(0.01)
        check(bool(goals) and bool(ees) and all([g.point.x, g.point.y, g.point.z] == GOAL for g in goals),
              f"the live view beside the ros2 arm: {len(goals)} goals (the task's), {len(ees)} end-effector points")
        limits = [(-2 * math.pi, 2 * math.pi), (-math.pi, 0.0), (-math.pi, math.pi)]
        check(all(lo <= c.data[j] <= hi for c in cmds for j, (lo, hi) in enumerate(limits)),
              "every commanded active joint within the UR5's limits")
        q = by_name(states[-1]) if states else {}
        last = cmds[-1].data
        near = q and all(abs(q[UR_JOINTS[j]] - last[j]) < 0.5 for j in range(3))
        check(bool(near), f"the last command {[round(v, 3) for v in last[:3]]} is near the arm "
                          f"{[round(q.get(n, float('nan')), 3) for n in UR_JOINTS[:3]]}")
    finally:
        stop((lrn, ctl, sim), tmp, ("ctl.log", "learner.log", "sim2.log"))


UR5_DH = dict(d=[0.089159, 0, 0, 0.10915, 0.09465, 0.0823], a=[0, -0.425, -0.39225, 0, 0, 0],
              alpha=[math.pi / 2, 0, 0, math.pi / 2, -math.pi / 2, 0])  # Universal Robots' UR5


def flange(q):
    """The UR5's flange point (m, base frame) at joint angles q (rad): the product of UR's
    standard DH transforms, written here independently of the Rust kinematics."""
    t = [[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, 0], [0, 0, 0, 1.0]]
    for th, d, a, al in zip(q, UR5_DH["d"], UR5_DH["a"], UR5_DH["alpha"]):
        ct, st, ca, sa = math.cos(th), math.sin(th), math.cos(al), math.sin(al)
        m_ = [[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st], [0, sa, ca, d], [0, 0, 0, 1]]
        t = [[sum(t[i][k] * m_[k][j] for k in range(4)) for j in range(4)] for i in range(4)]
    return [t[0][3], t[1][3], t[2][3]]


def part3(dp, tmp):
    prefix = f"ros2-check-lv-{os.getpid()}"
    ns = "/rt_controller"
    (tmp / "sim3.toml").write_text(
        "[task]\nhorizon = 20\n[serve]\nmode = \"real_time\"\ntime_compression = 10.0\nstate_period_s = 0.01\n"
    )
    (tmp / "ctl3.toml").write_text(
        "seed = 1\nmode = \"real_time\"\ntime_compression = 10.0\n[task]\nhorizon = 20\n"
        f"[live_view]\nenabled = true\ndomain_id = {DOMAIN}\nrate_hz = 100.0\njoint_states = true\n"
    )
    reader = lambda name, t: DataReader(dp, Topic(dp, f"rt{ns}/{name}" if name else "rt/joint_states", t), qos=QOS)
    goal_r, ee_r = reader("goal", m.PointStamped), reader("end_effector", m.PointStamped)
    ep_r, tv_r = reader("episode", m.UInt64), reader("table_version", m.UInt64)
    js_r = reader(None, m.JointState)
    sim = spawn([str(BIN / "hil-sim"), "serve", "--config", str(tmp / "sim3.toml"), "--prefix", prefix],
                tmp / "sim3.log")
    ctl, lrn = controller_and_learner(tmp, prefix, "3")
    try:
        goals, ees, eps, tvs, jss, t0 = [], [], [], [], [], time.monotonic()
        # Until the learner's second table is shown and two more episodes after it, and 20
        # end-effector points.
        v2_at = None
        while time.monotonic() - t0 < 90:
            goals.extend(goal_r.take(N=100))
            ees.extend(ee_r.take(N=100))
            eps.extend(x.data for x in ep_r.take(N=100))
            tvs.extend(x.data for x in tv_r.take(N=100))
            jss.extend(js_r.take(N=100))
            if v2_at is None and any(v >= 2 for v in tvs):
                v2_at = eps[-1] if eps else 0
            if v2_at is not None and eps and eps[-1] >= v2_at + 2 and len(ees) >= 20:
                break
            time.sleep(0.005)
        check(bool(goals) and bool(ees) and bool(eps) and bool(tvs) and bool(jss),
              f"CycloneDDS reads the live view of rt-controller (iceoryx2 arm): {len(goals)} goals, "
              f"{len(ees)} end-effector points, {len(eps)} episodes, {len(tvs)} table versions, "
              f"{len(jss)} joint states in {time.monotonic() - t0:.1f} s")
        if not (goals and ees and jss):
            return
        check(all(g.header.frame_id == "base" and [g.point.x, g.point.y, g.point.z] == GOAL for g in goals),
              f"every goal is the task's {GOAL} in frame base")
        by_stamp = {(j.header.stamp.sec, j.header.stamp.nanosec): j for j in jss}
        paired = [(e, by_stamp.get((e.header.stamp.sec, e.header.stamp.nanosec))) for e in ees]
        paired = [(e, j) for e, j in paired if j is not None]
        errs = [max(abs(a - b) for a, b in zip([e.point.x, e.point.y, e.point.z], flange(j.position)))
                for e, j in paired]
        check(len(paired) >= len(ees) // 2 and max(errs, default=1) < 1e-5 and all(e.header.frame_id == "base" for e in ees),
              f"{len(paired)} of {len(ees)} end-effector points paired with the joint state of their stamp: "
              f"at its UR5 forward kinematics within {max(errs, default=float('nan')):.1e} m")
        spread = max(max(abs(p.point.x - ees[0].point.x), abs(p.point.z - ees[0].point.z)) for p in ees)
        check(spread > 0.01, f"the end effector moves ({spread:.3f} m)")
        check(all(a <= b for a, b in zip(eps, eps[1:])) and eps[-1] > eps[0]
              and all(a <= b for a, b in zip(tvs, tvs[1:])) and tvs[-1] >= 2,
              f"episodes {eps[0]} -> {eps[-1]} and table versions {tvs[0]} -> {tvs[-1]}, never backwards")
        check(all(j.name == UR_JOINTS and len(j.position) == 6
                  and abs(j.position[3] + math.pi / 2) < 1e-12 and abs(j.position[4] - math.pi / 2) < 1e-12
                  for j in jss),
              "joint states: six UR joints in order, the wrist at its locked angles")
    finally:
        stop((lrn, ctl, sim), tmp, ("ctl3.log", "learner3.log", "sim3.log"))


def main():
    for b in ("hil-sim", "rt-controller", "learner"):
        if not (BIN / b).exists():
            sys.exit(f"{BIN / b} not found: cargo build --release --workspace --all-targets first")
    dp = DomainParticipant(DOMAIN)
    with tempfile.TemporaryDirectory(prefix="ros2-check-") as d:
        tmp = Path(d)
        part1(dp, tmp)
        part2(dp, tmp)
        part3(dp, tmp)
    print(f"{len(failures)} failed" if failures else "all checks passed")
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
