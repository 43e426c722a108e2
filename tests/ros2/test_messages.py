"""Our ROS 2 message types against ``rosbags``, an independent ROS 2 serialiser: for every type the ``ros2`` cell
uses, with every field set, our CDR bytes are byte for byte the ones rosbags writes (Humble's and Jazzy's
definitions), and we read rosbags' bytes back to the same message."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore

from devices.drivers.ros2.camera import depth_of, intrinsics_of
from devices.drivers.ros2.messages import (
    MESSAGES,
    ROS_TYPE_NAMES,
    CameraInfo,
    Duration,
    Float64,
    Header,
    Image,
    JointState,
    JointTrajectory,
    JointTrajectoryPoint,
    PointCloud2,
    PointField,
    RegionOfInterest,
    Time,
    seconds_of,
    stamp_of,
)
from devices.protocols import CaptureError, DeviceError

RNG = np.random.default_rng(3)


def header(frame: str = "camera_depth_optical_frame") -> Header:
    return Header(stamp=Time(sec=1_733_400_000, nanosec=123_456_789), frame_id=frame)


def samples() -> dict[type, Any]:
    """One message of each type, every field away from its default."""
    depth = RNG.integers(0, 4000, size=(6, 5), dtype=np.uint16)
    return {
        Time: Time(sec=-3, nanosec=999_999_999),
        Duration: Duration(sec=2, nanosec=500_000_000),
        Header: header("odd frame name ü"),
        Float64: Float64(data=-1.25),
        Image: Image(
            header=header(), height=6, width=5, encoding="16UC1", is_bigendian=0, step=10, data=depth.tobytes()
        ),
        RegionOfInterest: RegionOfInterest(x_offset=1, y_offset=2, height=3, width=4, do_rectify=True),
        CameraInfo: CameraInfo(
            header=header(),
            height=480,
            width=640,
            distortion_model="plumb_bob",
            d=[0.1, -0.2, 0.001, 0.002, 0.03],
            k=[610.0, 0.0, 319.5, 0.0, 611.0, 239.5, 0.0, 0.0, 1.0],
            r=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            p=[610.0, 0.0, 319.5, 0.0, 0.0, 611.0, 239.5, 0.0, 0.0, 0.0, 1.0, 0.0],
            binning_x=1,
            binning_y=2,
            roi=RegionOfInterest(x_offset=1, y_offset=2, height=3, width=4, do_rectify=True),
        ),
        JointState: JointState(
            header=header("base"),
            name=["shoulder_pan_joint", "elbow_joint", "turntable_joint"],
            position=[0.1, -1.5, 3.0],
            velocity=[0.0, 0.2, -0.1],
            effort=[],
        ),
        PointField: PointField(name="z", offset=8, datatype=7, count=1),
        PointCloud2: PointCloud2(
            header=header(),
            height=1,
            width=3,
            fields=[PointField(name=n, offset=4 * i, datatype=7, count=1) for i, n in enumerate("xyz")],
            is_bigendian=False,
            point_step=12,
            row_step=36,
            data=RNG.random((3, 3)).astype("<f4").tobytes(),
            is_dense=True,
        ),
        JointTrajectoryPoint: JointTrajectoryPoint(
            positions=[0.5, 1.0],
            velocities=[0.1, 0.0],
            accelerations=[0.0, 0.3],
            effort=[1.5],
            time_from_start=Duration(1, 2),
        ),
        JointTrajectory: JointTrajectory(
            header=Header(),
            joint_names=["a", "b"],
            points=[
                JointTrajectoryPoint(positions=[0.0, 0.0], velocities=[0.0, 0.0], time_from_start=Duration(0, 0)),
                JointTrajectoryPoint(
                    positions=[0.5, -1.0], velocities=[0.0, 0.0], time_from_start=Duration(1, 250_000_000)
                ),
            ],
        ),
    }


def to_rosbags(typestore: Any, message: Any) -> Any:
    """The rosbags message of one of ours (same fields, numpy arrays where rosbags keeps them)."""
    cls = typestore.types[ROS_TYPE_NAMES[type(message).__name__]]
    values: dict[str, Any] = {}
    for f in dataclasses.fields(message):
        v = getattr(message, f.name)
        if dataclasses.is_dataclass(v):
            v = to_rosbags(typestore, v)
        elif isinstance(v, bytes):
            v = np.frombuffer(v, dtype=np.uint8)
        elif isinstance(v, list) and v and dataclasses.is_dataclass(v[0]):
            v = [to_rosbags(typestore, x) for x in v]
        elif isinstance(v, list) and all(isinstance(x, float) for x in v):
            v = np.array(v, dtype=np.float64)
        values[f.name] = v
    return cls(**values)


def test_every_message_type_is_tested() -> None:
    assert set(samples()) == set(MESSAGES)


@pytest.mark.parametrize("store", [Stores.ROS2_HUMBLE, Stores.ROS2_JAZZY], ids=["humble", "jazzy"])
@pytest.mark.parametrize("kind", MESSAGES, ids=[m.__name__ for m in MESSAGES])
def test_our_cdr_bytes_are_rosbags_bytes(store: Stores, kind: type) -> None:
    typestore = get_typestore(store)
    ours = samples()[kind]
    name = ROS_TYPE_NAMES[kind.__name__]
    theirs = bytes(typestore.serialize_cdr(to_rosbags(typestore, ours), name))
    assert ours.serialize() == theirs
    assert kind.deserialize(theirs) == ours
    assert kind.__idl_typename__ == name.replace("/msg/", "::msg::dds_::").replace("/", "::") + "_"  # type: ignore[attr-defined]


def test_an_image_from_a_numpy_array_is_the_same_message() -> None:
    depth = RNG.integers(0, 4000, size=(4, 3), dtype=np.uint16)
    a = Image(header=header(), height=4, width=3, encoding="16UC1", step=6, data=depth)
    b = Image(header=header(), height=4, width=3, encoding="16UC1", step=6, data=depth.tobytes())
    assert a.serialize() == b.serialize()


def test_depth_encodings_and_refusals() -> None:
    mm = np.array([[0, 1000], [1500, 65535]], dtype="<u2")
    image = Image(header=header(), height=2, width=2, encoding="16UC1", step=4, data=mm.tobytes())
    assert np.allclose(depth_of(image), [[0.0, 1.0], [1.5, 65.535]], rtol=1e-6, atol=0)
    big = Image(
        header=header(), height=2, width=2, encoding="16UC1", is_bigendian=1, step=4, data=mm.astype(">u2").tobytes()
    )
    assert np.array_equal(depth_of(big), depth_of(image))
    m = np.array([[np.nan, 0.5], [np.inf, 2.0]], dtype="<f4")
    # a padded row (step 12 > 2 * 4) is read without its padding
    padded = np.zeros((2, 12), np.uint8)
    padded[:, :8] = m.view(np.uint8)
    image = Image(header=header(), height=2, width=2, encoding="32FC1", step=12, data=padded.tobytes())
    assert np.array_equal(depth_of(image), np.array([[0.0, 0.5], [0.0, 2.0]], dtype=np.float32))
    with pytest.raises(CaptureError, match="'rgb8' is not a depth encoding"):
        depth_of(Image(header=header(), height=2, width=2, encoding="rgb8", step=6, data=bytes(12)))
    with pytest.raises(CaptureError, match="incomplete 16UC1 image"):
        depth_of(Image(header=header(), height=2, width=2, encoding="16UC1", step=4, data=bytes(6)))


def test_intrinsics_from_camera_info() -> None:
    info = samples()[CameraInfo]
    with pytest.raises(DeviceError, match="has distortion"):
        intrinsics_of(info)
    info.d = [0.0] * 5
    k = intrinsics_of(info)
    assert (k.width, k.height, k.fx, k.fy, k.cx, k.cy) == (640, 480, 610.0, 611.0, 319.5, 239.5)
    info.k = [0.0] * 9
    with pytest.raises(DeviceError, match="no calibration"):
        intrinsics_of(info)


def test_stamps() -> None:
    assert seconds_of(stamp_of(12.25)) == 12.25
    assert stamp_of(3.9999999999) == Time(sec=3, nanosec=999_999_999) or stamp_of(3.9999999999) == Time(
        sec=4, nanosec=0
    )
