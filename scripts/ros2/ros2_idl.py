"""The ROS 2 message types the controller and hil-sim speak, declared as IDL for CycloneDDS's
Python binding (PyPI `cyclonedds`): the same DDS type names and field order as ROS 2's
rosidl-generated IDL (`sensor_msgs/msg/JointState.idl` and so on), final extensibility, so that
they encode as plain CDR (XCDR1), what ROS 2 Humble and Jazzy put on the wire.

An independent implementation of the types in `shared/ros2` (the Rust side): the vectors that
`shared/ros2`'s tests check against come from here (`cdr_vectors.py`), and `ros2_check.py` uses
them to talk to hil-sim and rt-controller over DDS.
"""

from dataclasses import dataclass

import cyclonedds.idl.annotations as annotate
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import float64, int8, int32, sequence, uint8, uint32, uint64


@dataclass
@annotate.final
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32


@dataclass
@annotate.final
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
@annotate.final
class JointState(IdlStruct, typename="sensor_msgs::msg::dds_::JointState_"):
    header: Header
    name: sequence[str]
    position: sequence[float64]
    velocity: sequence[float64]
    effort: sequence[float64]


@dataclass
@annotate.final
class MultiArrayDimension(IdlStruct, typename="std_msgs::msg::dds_::MultiArrayDimension_"):
    label: str
    size: uint32
    stride: uint32


@dataclass
@annotate.final
class MultiArrayLayout(IdlStruct, typename="std_msgs::msg::dds_::MultiArrayLayout_"):
    dim: sequence[MultiArrayDimension]
    data_offset: uint32


@dataclass
@annotate.final
class Float64MultiArray(IdlStruct, typename="std_msgs::msg::dds_::Float64MultiArray_"):
    layout: MultiArrayLayout
    data: sequence[float64]


@dataclass
@annotate.final
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: float64
    y: float64
    z: float64


@dataclass
@annotate.final
class PointStamped(IdlStruct, typename="geometry_msgs::msg::dds_::PointStamped_"):
    header: Header
    point: Point


@dataclass
@annotate.final
class RobotMode(IdlStruct, typename="ur_dashboard_msgs::msg::dds_::RobotMode_"):
    mode: int8


@dataclass
@annotate.final
class SafetyMode(IdlStruct, typename="ur_dashboard_msgs::msg::dds_::SafetyMode_"):
    mode: uint8


@dataclass
@annotate.final
class UInt64(IdlStruct, typename="std_msgs::msg::dds_::UInt64_"):
    data: uint64
