#!/usr/bin/env python3
"""Reference dynamics of every bundled UR URDF with all six joints active, computed by
Pinocchio (an independent rigid-body library) for hil-sim's tests.

Writes hil-sim/tests/data/pinocchio6.json: per model, seeded random states (q rad, qd rad/s,
tau N·m) and at each Pinocchio's flange pose (wrist_3_link in base_link: position m, rotation
matrix row-major), mass matrix M(q) (CRBA, kg·m²), gravity torque g(q) (N·m, the torque that
holds the arm still) and forward dynamics qdd = ABA(q, qd, tau) (rad/s²); and each wrist
joint's largest inertia (max over the poses of the joints after it of M_jj, kg·m²), from
which hil-sim's wrist servo gains are derived (hil_sim::servo::wrist_velocity_gain).

Python stays out of the test run: the tests read the committed file.
Usage (from the repository root):
    python3 -m venv /tmp/simvenv && /tmp/simvenv/bin/pip install pin numpy
    /tmp/simvenv/bin/python scripts/sim-reference/pinocchio_reference.py
"""
import datetime
import json
import pathlib

import numpy as np
import pinocchio as pin

ROOT = pathlib.Path(__file__).resolve().parents[2]
MODELS = ["ur3", "ur5", "ur10", "ur3e", "ur5e", "ur7e", "ur10e", "ur12e", "ur16e",
          "ur15", "ur18", "ur20", "ur30"]
SAMPLES = 10
SEED = 20261206
# Wrist torques: a small fraction of the effort limit, so that one 0.1 ms physics step of the
# light wrist links stays a small change of velocity.
ARM_TAU_FRACTION, WRIST_TAU_FRACTION = 0.25, 0.01
GRID = 72  # wrist inertia: poses of the later wrist joints on a GRID x GRID grid


def rounded(a):
    return [float(x) for x in np.asarray(a).ravel()]


def main():
    rng = np.random.default_rng(SEED)
    out = {
        "provenance": {
            "script": "scripts/sim-reference/pinocchio_reference.py",
            "pinocchio": pin.__version__,
            "numpy": np.__version__,
            "seed": SEED,
            "date": datetime.date.today().isoformat(),
            "urdf": "hil-sim/urdf/<model>.urdf",
            "gravity": "-9.81 m/s^2 along base z",
        },
        "models": {},
    }
    for name in MODELS:
        model = pin.buildModelFromUrdf(str(ROOT / "hil-sim" / "urdf" / f"{name}.urdf"))
        assert model.nq == 6 and model.nv == 6, (name, model.nq)
        model.gravity.linear = np.array([0.0, 0.0, -9.81])
        data = model.createData()
        flange = model.getFrameId("wrist_3_link")
        lo, hi = model.lowerPositionLimit, model.upperPositionLimit
        effort = model.effortLimit
        samples = []
        for _ in range(SAMPLES):
            q = rng.uniform(np.maximum(lo, -3.0), np.minimum(hi, 3.0))
            qd = rng.uniform(-1.5, 1.5, 6)
            frac = np.array([ARM_TAU_FRACTION] * 3 + [WRIST_TAU_FRACTION] * 3)
            tau = rng.uniform(-1.0, 1.0, 6) * frac * effort
            pin.forwardKinematics(model, data, q)
            pin.updateFramePlacements(model, data)
            pose = data.oMf[flange]
            m = pin.crba(model, data, q)
            m = np.triu(m) + np.triu(m, 1).T
            g = pin.computeGeneralizedGravity(model, data, q)
            qdd = pin.aba(model, data, q, qd, tau)
            samples.append({
                "q": rounded(q), "qd": rounded(qd), "tau": rounded(tau),
                "flange_pos": rounded(pose.translation), "flange_rot": rounded(pose.rotation),
                "mass_matrix": rounded(m), "gravity": rounded(g), "qdd": rounded(qdd),
            })
        # M_jj of wrist joint j depends only on the joints after it.
        grid = np.linspace(-np.pi, np.pi, GRID, endpoint=False)
        inertia = [0.0, 0.0, 0.0]
        for a in grid:
            for b in grid:
                q = np.zeros(6)
                q[4], q[5] = a, b
                m = pin.crba(model, data, q)
                for k in range(3):
                    inertia[k] = max(inertia[k], float(m[3 + k, 3 + k]))
        out["models"][name] = {"samples": samples, "wrist_inertia": inertia}
        print(name, "wrist inertia (kg m^2):", ["%.4g" % x for x in inertia])
    path = ROOT / "hil-sim" / "tests" / "data" / "pinocchio6.json"
    path.write_text(json.dumps(out, separators=(",", ":")) + "\n")
    print("wrote", path)


if __name__ == "__main__":
    main()
