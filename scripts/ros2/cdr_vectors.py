"""Prints the CDR test vectors of `shared/ros2/src/msg.rs`'s tests, encoded by CycloneDDS
(`ros2_idl.py`): one `name hex` line per message, little-endian (CDR_LE) and, for JointState,
big-endian (CDR_BE) too. Run with a venv that has `cyclonedds`:

    python scripts/ros2/cdr_vectors.py
"""

import math

from cyclonedds.idl._support import Endianness

import ros2_idl as m

VECTORS = {
    "joint_state": m.JointState(
        m.Header(m.Time(12, 345), "base"),
        ["shoulder_pan_joint", "elbow_joint"],
        [1.0, -2.5],
        [0.5, math.pi],
        [],
    ),
    "float64_multi_array": m.Float64MultiArray(
        m.MultiArrayLayout([m.MultiArrayDimension("joints", 6, 6)], 0),
        [0.0, -2.0, 2.4, -1.5707963267948966, 1.5707963267948966, 0.25],
    ),
    "float64_multi_array_empty_layout": m.Float64MultiArray(m.MultiArrayLayout([], 0), [1.5]),
    "point_stamped": m.PointStamped(m.Header(m.Time(-1, 999999999), "world"), m.Point(0.1, -0.2, 0.3)),
    "robot_mode": m.RobotMode(7),
    "robot_mode_no_controller": m.RobotMode(-1),
    "safety_mode": m.SafetyMode(3),
    "uint64": m.UInt64(2**40 + 3),
}

for name, msg in VECTORS.items():
    print(name, msg.serialize(endianness=Endianness.Little).hex())
print("joint_state_be", VECTORS["joint_state"].serialize(endianness=Endianness.Big).hex())
