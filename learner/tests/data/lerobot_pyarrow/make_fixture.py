"""Writes this folder's LeRobot v3.0 fixture with pyarrow alone (not with `learner dataset
export`): the states of the first two demonstrations of a `learner expert` demos.npz, as float32
lists, snappy-compressed (pyarrow's default), no `ur5_task` in meta/info.json, no actions.

    python make_fixture.py DEMOS.npz    # needs numpy and pyarrow
"""
import json
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

here = Path(__file__).parent
d = np.load(sys.argv[1])
states = d["states"][:2].astype(np.float32)  # (2, T, 12)
names = [str(n) for n in d["state_names"]]
n_ep, horizon, dx = states.shape
fps = int(round(1.0 / float(d["dt"])))
frames = n_ep * horizon
table = pa.table({
    "observation.state": pa.array(list(states.reshape(frames, dx)), type=pa.list_(pa.float32(), dx)),
    "timestamp": pa.array(np.tile(np.arange(horizon) / fps, n_ep).astype(np.float32)),
    "frame_index": pa.array(np.tile(np.arange(horizon), n_ep).astype(np.int64)),
    "episode_index": pa.array(np.repeat(np.arange(n_ep), horizon).astype(np.int64)),
    "index": pa.array(np.arange(frames, dtype=np.int64)),
    "task_index": pa.array(np.zeros(frames, dtype=np.int64)),
})
(here / "data/chunk-000").mkdir(parents=True, exist_ok=True)
pq.write_table(table, here / "data/chunk-000/file-000.parquet")
(here / "meta/episodes/chunk-000").mkdir(parents=True, exist_ok=True)
pq.write_table(pa.table({
    "episode_index": pa.array(np.arange(n_ep, dtype=np.int64)),
    "tasks": pa.array([["reach"]] * n_ep),
    "length": pa.array([horizon] * n_ep, type=pa.int64()),
    "data/chunk_index": pa.array([0] * n_ep, type=pa.int64()),
    "data/file_index": pa.array([0] * n_ep, type=pa.int64()),
    "dataset_from_index": pa.array([e * horizon for e in range(n_ep)], type=pa.int64()),
    "dataset_to_index": pa.array([(e + 1) * horizon for e in range(n_ep)], type=pa.int64()),
}), here / "meta/episodes/chunk-000/file-000.parquet")
pq.write_table(pa.table({"task_index": pa.array([0], type=pa.int64()), "task": ["reach"]}),
               here / "meta/tasks.parquet")
scalar = lambda t: {"dtype": t, "shape": [1], "names": None}
info = {
    "codebase_version": "v3.0", "robot_type": "ur5", "total_episodes": n_ep,
    "total_frames": frames, "total_tasks": 1, "chunks_size": 1000, "fps": fps,
    "splits": {"train": f"0:{n_ep}"},
    "data_path": "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet",
    "video_path": None,
    "features": {
        "observation.state": {"dtype": "float32", "shape": [dx], "names": names},
        "timestamp": scalar("float32"), "frame_index": scalar("int64"),
        "episode_index": scalar("int64"), "index": scalar("int64"), "task_index": scalar("int64"),
    },
}
(here / "meta/info.json").write_text(json.dumps(info, indent=2))
