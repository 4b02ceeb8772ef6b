"""Checks a `learner dataset export --format lerobot` of a demos.npz with pyarrow, pandas and the
`lerobot` package (not needed by the tests):

    python check_lerobot.py DATASET_DIR DEMOS.npz   # needs numpy, pyarrow, pandas, lerobot
"""
import sys, numpy as np, pyarrow.parquet as pq
root = sys.argv[1]
t = pq.read_table(f"{root}/data/chunk-000/file-000.parquet")
s = np.array(t.column("observation.state").to_pylist())
d = np.load(sys.argv[2])
print("pyarrow rows", t.num_rows, "states equal to npz:", np.array_equal(s, d["states"].reshape(-1, 12)))
print("episodes", pq.read_table(f"{root}/meta/episodes/chunk-000/file-000.parquet").num_rows)
import pandas as pd
print(pd.read_parquet(f"{root}/meta/tasks.parquet"))
from lerobot.datasets.lerobot_dataset import LeRobotDataset
ds = LeRobotDataset("local/ur5_demos", root=root)
print("lerobot", ds.num_episodes, ds.num_frames, ds.fps, ds.features["observation.state"]["names"][:3])
x = ds[101]
print({k: (tuple(v.shape) if hasattr(v, "shape") else v) for k, v in x.items()})
print("state 101 equal:", np.allclose(x["observation.state"].numpy(), d["states"][1, 1]))
