"""The ROS 2 message types the ``ros2`` cell speaks, defined once with their ROS 2 names (cyclonedds IDL).

Each class is the DDS form rosidl generates for a ``.msg`` (``sensor_msgs/msg/Image`` is the DDS type
``sensor_msgs::msg::dds_::Image_`` on topic ``rt/<name>``): member names, order and types follow the ``.msg``
files of ``ros2/common_interfaces`` and ``ros2/rcl_interfaces`` exactly, so the CDR bytes are the ones a ROS 2
node sends and receives (``tests/ros2/test_messages.py`` compares them with ``rosbags``' serialiser).

The fast path: a ``uint8[]`` (an image's or a cloud's ``data``) is on the wire a uint32 length and the bytes. The
generic sequence machine of cyclonedds packs it as one Python int per byte (16 ms for a 640x480 16-bit image,
0.4 s for 3.7 MB); :func:`_pack_byte_sequences` swaps, after the class is built, the (de)serialiser of those
members for :class:`ByteBlockMachine`, which copies the block at once. The type declared to DDS (and its XTypes
type information) stays ``sequence<uint8>``; the member's Python value is ``bytes`` (or anything with the buffer
protocol when sending: a numpy array, a memoryview).
"""

# no "from __future__ import annotations": cyclonedds reads the member annotations as types

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from cyclonedds.idl import IdlStruct
from cyclonedds.idl._machinery import KeyEnabled, Machine, StructMachine
from cyclonedds.idl._support import DeserializeKind, KeyScanner, SerializeKind
from cyclonedds.idl.types import array, float64, int32, sequence, uint8, uint32

if TYPE_CHECKING:  # what the members hold, for the type checker; cyclonedds reads the IDL types below
    Floats = list[float]
    Strings = list[str]
    Bytes = Any  # bytes when received; anything with the buffer protocol (a numpy array) when sent
    Floats9 = list[float]
    Floats12 = list[float]
else:
    Floats = sequence[float64]
    Strings = sequence[str]
    Bytes = sequence[uint8]
    Floats9 = array[float64, 9]
    Floats12 = array[float64, 12]

ROS_TYPE_NAMES: dict[str, str] = {}
"""Our class name -> its ROS 2 type name (``Image`` -> ``sensor_msgs/msg/Image``), for rosbags and the check."""


class ByteBlockMachine(Machine):
    """(De)serialises a ``sequence<uint8>`` as one block of bytes: the same wire bytes, no per-byte Python int."""

    def __init__(self) -> None:
        self.alignment = 4

    def serialize(
        self, buffer: Any, value: Any, serialize_kind: Any = SerializeKind.DataSample, key_enabled: Any = None
    ) -> None:
        block = memoryview(value).cast("B")
        buffer.align(4)
        buffer.write("I", 4, len(block))
        buffer.write_bytes(block)

    def deserialize(
        self, buffer: Any, deserialize_kind: Any = DeserializeKind.DataSample, key_enabled: Any = None
    ) -> bytes:
        buffer.align(4)
        n = buffer.read("I", 4)
        return buffer.read_bytes(n)

    def key_scan(self) -> KeyScanner:
        return KeyScanner.infinity()

    def cdr_key_machine_op(self, skip: bool) -> list[Any]:  # never a key member
        raise NotImplementedError("a byte block is never part of a key")

    def default_initialize(self) -> bytes:
        return b""


def _pack_byte_sequences(cls: type[IdlStruct], members: tuple[str, ...]) -> None:
    """Use :class:`ByteBlockMachine` for the ``sequence[uint8]`` ``members`` of ``cls`` (both CDR versions)."""
    idl = cls.__idl__  # type: ignore[attr-defined]
    idl.populate()
    for machine in (idl.v1_machine, idl.v2_machine):
        if not isinstance(machine, StructMachine):
            raise TypeError(f"{cls.__name__}: expected a final struct, its machine is {type(machine).__name__}")
        for name in members:
            machine.members_machines[name] = ByteBlockMachine()
    _ = KeyEnabled  # the machines' key handling is unchanged (no keys in these types)


def _ros(package: str, name: str) -> str:
    """The DDS type name rosidl gives ``package/msg/name``."""
    ROS_TYPE_NAMES[name] = f"{package}/msg/{name}"
    return f"{package}::msg::dds_::{name}_"


@dataclass
class Time(IdlStruct, typename=_ros("builtin_interfaces", "Time")):
    """``builtin_interfaces/msg/Time``: seconds and nanoseconds since the epoch (or the ROS clock's start)."""

    sec: int32 = 0
    nanosec: uint32 = 0


@dataclass
class Duration(IdlStruct, typename=_ros("builtin_interfaces", "Duration")):
    """``builtin_interfaces/msg/Duration``."""

    sec: int32 = 0
    nanosec: uint32 = 0


@dataclass
class Header(IdlStruct, typename=_ros("std_msgs", "Header")):
    """``std_msgs/msg/Header``: when and in which frame."""

    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


@dataclass
class Float64(IdlStruct, typename=_ros("std_msgs", "Float64")):
    """``std_msgs/msg/Float64``: a position command of a one-joint controller."""

    data: float64 = 0.0


@dataclass
class Image(IdlStruct, typename=_ros("sensor_msgs", "Image")):
    """``sensor_msgs/msg/Image``; ``data`` is bytes (see the module docstring)."""

    header: Header = field(default_factory=Header)
    height: uint32 = 0
    width: uint32 = 0
    encoding: str = ""
    is_bigendian: uint8 = 0
    step: uint32 = 0
    data: Bytes = b""


@dataclass
class RegionOfInterest(IdlStruct, typename=_ros("sensor_msgs", "RegionOfInterest")):
    """``sensor_msgs/msg/RegionOfInterest``."""

    x_offset: uint32 = 0
    y_offset: uint32 = 0
    height: uint32 = 0
    width: uint32 = 0
    do_rectify: bool = False


@dataclass
class CameraInfo(IdlStruct, typename=_ros("sensor_msgs", "CameraInfo")):
    """``sensor_msgs/msg/CameraInfo``: ``k`` = [fx, 0, cx, 0, fy, cy, 0, 0, 1] row-major, ``d`` distortion."""

    header: Header = field(default_factory=Header)
    height: uint32 = 0
    width: uint32 = 0
    distortion_model: str = ""
    d: Floats = field(default_factory=list)
    k: Floats9 = field(default_factory=lambda: [0.0] * 9)
    r: Floats9 = field(default_factory=lambda: [0.0] * 9)
    p: Floats12 = field(default_factory=lambda: [0.0] * 12)
    binning_x: uint32 = 0
    binning_y: uint32 = 0
    roi: RegionOfInterest = field(default_factory=RegionOfInterest)


@dataclass
class JointState(IdlStruct, typename=_ros("sensor_msgs", "JointState")):
    """``sensor_msgs/msg/JointState``: positions in radians (metres for prismatic joints)."""

    header: Header = field(default_factory=Header)
    name: Strings = field(default_factory=list)
    position: Floats = field(default_factory=list)
    velocity: Floats = field(default_factory=list)
    effort: Floats = field(default_factory=list)


@dataclass
class PointField(IdlStruct, typename=_ros("sensor_msgs", "PointField")):
    """``sensor_msgs/msg/PointField`` (``datatype`` 7 = FLOAT32)."""

    name: str = ""
    offset: uint32 = 0
    datatype: uint8 = 0
    count: uint32 = 0


if TYPE_CHECKING:
    PointFields = list[PointField]
else:
    PointFields = sequence[PointField]


@dataclass
class PointCloud2(IdlStruct, typename=_ros("sensor_msgs", "PointCloud2")):
    """``sensor_msgs/msg/PointCloud2``; ``data`` is bytes (see the module docstring)."""

    header: Header = field(default_factory=Header)
    height: uint32 = 0
    width: uint32 = 0
    fields: PointFields = field(default_factory=list)
    is_bigendian: bool = False
    point_step: uint32 = 0
    row_step: uint32 = 0
    data: Bytes = b""
    is_dense: bool = False


@dataclass
class JointTrajectoryPoint(IdlStruct, typename=_ros("trajectory_msgs", "JointTrajectoryPoint")):
    """``trajectory_msgs/msg/JointTrajectoryPoint``."""

    positions: Floats = field(default_factory=list)
    velocities: Floats = field(default_factory=list)
    accelerations: Floats = field(default_factory=list)
    effort: Floats = field(default_factory=list)
    time_from_start: Duration = field(default_factory=Duration)


if TYPE_CHECKING:
    TrajectoryPoints = list[JointTrajectoryPoint]
else:
    TrajectoryPoints = sequence[JointTrajectoryPoint]


@dataclass
class JointTrajectory(IdlStruct, typename=_ros("trajectory_msgs", "JointTrajectory")):
    """``trajectory_msgs/msg/JointTrajectory``: what a ros2_control joint trajectory controller executes."""

    header: Header = field(default_factory=Header)
    joint_names: Strings = field(default_factory=list)
    points: TrajectoryPoints = field(default_factory=list)


_pack_byte_sequences(Image, ("data",))
_pack_byte_sequences(PointCloud2, ("data",))

MESSAGES: tuple[type[IdlStruct], ...] = (
    Time,
    Duration,
    Header,
    Float64,
    Image,
    RegionOfInterest,
    CameraInfo,
    JointState,
    PointField,
    PointCloud2,
    JointTrajectoryPoint,
    JointTrajectory,
)
"""Every message type of the cell."""


def stamp_of(seconds: float) -> Time:
    """A ``Time`` from seconds (float)."""
    sec = int(seconds // 1)
    return Time(sec=sec, nanosec=min(round((seconds - sec) * 1e9), 999_999_999))


def seconds_of(stamp: Time | Duration) -> float:
    """Seconds (float) of a ``Time`` or ``Duration``."""
    return stamp.sec + stamp.nanosec * 1e-9
