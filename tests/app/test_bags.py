"""A scan as a ROS 2 bag and back: ``nbv export-bag`` and ``GET .../export.mcap|db3`` write rosbag2 files that
``rosbags``' AnyReader reads (the journal's depth frames bit for bit, camera infos, TF, the cloud, the surface), and a
bag in ``data_dir/recordings`` plays back as a session with the original's coverage per view. Bad bags are refused
with the missing piece named, and create nothing."""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from apphelpers import BASE_URL, SMALL
from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import AppSettings
from devices.rosbag import CAMERA_INFO_TOPIC, DEPTH_TOPIC, BagTopics, load_bag, still_images, typestore
from nbv.cli import main
from planner import DepthFrame, Intrinsics, Pose
from tests.helpers import with_small_costs
from workbench.journal.store import read_journal

rosbags = pytest.importorskip("rosbags")  # the ros2 and test extras install it
pytestmark = pytest.mark.slow  # one 5-view session, two exports, a 5-view playback: about 10 s of CPU
VIEWS = 5


@pytest.fixture(scope="module")
def scan(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Any]]:
    """One 5-view simulated session (the mug, coarse map), a server on its data directory, and the session as
    an MCAP bag written by ``nbv export-bag`` (Humble, rosbag2 version 8) and a .db3 bag downloaded from the REST
    route (Jazzy, version 9)."""
    root = tmp_path_factory.mktemp("bags")
    settings = with_small_costs(AppSettings(viser_port=0, scene=False, data_dir=root / "data"))
    with TestClient(create_app(settings), base_url=BASE_URL) as client:
        sid = client.post("/api/sessions", json={"model": "mug", "config": SMALL, "seed": 4}).json()["id"]
        assert client.post(f"/api/sessions/{sid}/capture").status_code == 200
        for _ in range(VIEWS - 1):
            assert client.post(f"/api/sessions/{sid}/step").status_code == 200
        export = client.get(f"/api/sessions/{sid}/export").json()
        directory = settings.data_dir / "sessions" / sid
        mcap = root / "scan.mcap"
        assert main(["export-bag", str(directory), "--out", str(mcap)]) == 0
        r = client.get(f"/api/sessions/{sid}/export.db3?distro=jazzy")  # the CLI's: Humble's definitions
        assert r.status_code == 200 and r.headers["content-type"] == "application/vnd.sqlite3"
        db3 = root / "scan.db3"
        db3.write_bytes(r.content)
        yield {
            "client": client,
            "settings": settings,
            "id": sid,
            "dir": directory,
            "export": export,
            "bags": (mcap, db3),
        }


def read_bag(path: Path) -> dict[str, list[tuple[int, Any]]]:
    """Every message of the bag by topic: (log time ns, deserialised message)."""
    from rosbags.highlevel import AnyReader

    out: dict[str, list[tuple[int, Any]]] = {}
    with AnyReader([path]) as reader:
        for con, stamp, raw in reader.messages():
            out.setdefault(con.topic, []).append((stamp, reader.deserialize(raw, con.msgtype)))
    return out


@pytest.mark.parametrize("which", [0, 1], ids=["mcap-cli", "db3-rest"])
def test_anyreader_reads_the_journal_s_frames_bit_for_bit(scan: dict[str, Any], which: int) -> None:
    journal = read_journal(scan["dir"])
    frames = [journal.frame(e) for e in journal.of_kind("capture")]
    assert len(frames) == VIEWS
    msgs = read_bag(scan["bags"][which])
    images = [m for _, m in msgs[DEPTH_TOPIC]]
    assert len(images) == VIEWS and {m.encoding for m in images} == {"32FC1"}
    for frame, image in zip(frames, images, strict=True):
        assert image.header.frame_id == "camera_depth_optical_frame"
        assert bytes(image.data) == frame.depth.astype("<f4").tobytes()  # the exact frame
    infos = [m for _, m in msgs[CAMERA_INFO_TOPIC]]
    k = frames[0].intrinsics
    assert len(infos) == VIEWS and (infos[0].width, infos[0].height) == (k.width, k.height)
    assert np.allclose(infos[0].k, [k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1])
    tf = [t for _, m in msgs["/tf"] for t in m.transforms]
    cams = [t for t in tf if (t.header.frame_id, t.child_frame_id) == ("plate", "camera_depth_optical_frame")]
    assert len(cams) == VIEWS and sum(t.child_frame_id == "plate" for t in tf) == VIEWS
    got = cams[2].transform.translation
    assert np.allclose([got.x, got.y, got.z], frames[2].T_world_camera.translation, atol=1e-12)
    (static,) = [m for _, m in msgs["/tf_static"]]
    assert static.transforms[0].child_frame_id == "base_link"
    joints = [m for _, m in msgs["/joint_states"]]
    assert len(joints) == VIEWS and joints[0].name[0] == "shoulder_pan_joint" and joints[0].name[-1] == "plate_joint"
    assert [s for s, _ in msgs[DEPTH_TOPIC]] == sorted(s for s, _ in msgs[DEPTH_TOPIC])  # stamped in view order
    (cloud,) = [m for _, m in msgs["/nbv/cloud"]]
    assert cloud.width == scan["export"]["session"]["points"] and cloud.point_step == 12
    assert cloud.header.frame_id == "plate"
    (marker,) = [m for _, m in msgs["/nbv/surface"]]
    assert marker.type == 11 and len(marker.points) > 300 and len(marker.points) % 3 == 0
    qos = offered_qos(scan["bags"][which])
    assert "TRANSIENT_LOCAL" in qos["/tf_static"] and "TRANSIENT_LOCAL" not in qos["/tf"]


def test_the_cli_s_rebuilt_cloud_is_the_live_session_s(scan: dict[str, Any]) -> None:
    mcap, db3 = (read_bag(p)["/nbv/cloud"][0][1] for p in scan["bags"])
    assert bytes(mcap.data) == bytes(db3.data)  # nbv export-bag replays the journal; the route takes the live cloud


def offered_qos(path: Path) -> dict[str, str]:
    """The offered QoS profiles (as stored) of each topic of a bag, by topic."""
    from rosbags.interfaces import ConnectionExtRosbag2
    from rosbags.rosbag2 import Reader

    with Reader(path) as reader:
        return {
            c.topic: repr(c.ext.offered_qos_profiles)
            for c in reader.connections
            if isinstance(c.ext, ConnectionExtRosbag2)
        }


def test_a_bag_plays_back_with_the_original_s_coverage_per_view(scan: dict[str, Any]) -> None:
    client, settings = scan["client"], scan["settings"]
    recordings = settings.data_dir / "recordings"
    recordings.mkdir(exist_ok=True)
    shutil.copy(scan["bags"][0], recordings / "lab-scan.mcap")
    assert "lab-scan.mcap" in client.get("/api/recordings").json()
    body = {"config": SMALL, "seed": 4, "source": {"kind": "replay", "recording": "lab-scan.mcap"}}
    r = client.post("/api/sessions", json=body)
    assert r.status_code == 201, r.text
    sid = r.json()["id"]
    assert client.post(f"/api/sessions/{sid}/capture").json()["model"] == "replay:lab-scan.mcap"
    for _ in range(VIEWS - 1):
        assert client.post(f"/api/sessions/{sid}/step").status_code == 200
    r = client.post(f"/api/sessions/{sid}/step")
    assert r.status_code == 503 and f"all {VIEWS} recorded frames" in r.json()["detail"]
    played = client.get(f"/api/sessions/{sid}/export").json()["iterations"]
    original = scan["export"]["iterations"]
    assert [it["coverage"] for it in played] == [it["coverage"] for it in original]
    assert original[-1]["coverage"] > 0.5
    assert [it["points"] for it in played] == [it["points"] for it in original]
    timeline = client.get(f"/api/sessions/{sid}/timeline").json()  # the playback's timeline, view by view
    assert timeline["views"] == VIEWS and len(timeline["steps"]) == VIEWS


# ---------------------------------------------------------------------- bad bags


def write_bag(
    path: Path, *, encoding: str = "32FC1", info: bool = True, info_messages: bool = True, folder: bool = False
) -> Path:
    """A one-view bag: a 4x3 depth image, its camera info, /tf plate -> camera (a hand-made lab bag); the single
    ``path`` (.mcap), or with ``folder`` the rosbag2 folder ``path`` without its suffix (metadata.yaml + file)."""
    from rosbags.rosbag2 import Writer
    from rosbags.rosbag2.enums import StoragePlugin

    from workbench.journal.bag import _Messages

    m = _Messages("humble")
    k = Intrinsics(4, 3, 3.0, 3.0, 1.5, 1.0)
    frame = DepthFrame(np.full((3, 4), 0.5, dtype=np.float32), Pose.look_at([0.4, 0.0, 0.3], [0, 0, 0]), k)
    stamp = 1_000_000_000
    bag_dir = path.with_suffix("")
    with Writer(bag_dir, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        c_tf = w.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=m.store)
        c_img = w.add_connection(DEPTH_TOPIC, "sensor_msgs/msg/Image", typestore=m.store)
        tf = m.tf([m.transform(stamp, "plate", "camera_depth_optical_frame", frame.T_world_camera)])
        w.write(c_tf, stamp, m.store.serialize_cdr(tf, tf.__msgtype__))
        image = m.image(stamp, frame)
        if encoding == "16UC1":
            image.encoding, image.step = "16UC1", 8
            image.data = np.full((3, 4), 500, dtype="<u2").view(np.uint8).reshape(-1)
        else:
            image.encoding = encoding
        w.write(c_img, stamp, m.store.serialize_cdr(image, image.__msgtype__))
        if info:
            c_info = w.add_connection(CAMERA_INFO_TOPIC, "sensor_msgs/msg/CameraInfo", typestore=m.store)
            if info_messages:
                w.write(c_info, stamp, m.store.serialize_cdr(m.camera_info(stamp, frame), "sensor_msgs/msg/CameraInfo"))
    if folder:
        return bag_dir
    (bag_dir / f"{bag_dir.name}.mcap").replace(path)
    shutil.rmtree(bag_dir)
    return path


@pytest.mark.parametrize("folder", [False, True], ids=["mcap-file", "rosbag2-folder"])
def test_a_hand_made_bag_in_millimetres_reads_as_metres(tmp_path: Path, folder: bool) -> None:
    scan = load_bag(write_bag(tmp_path / "mm.mcap", encoding="16UC1", folder=folder))
    (frame,) = scan.frames
    assert frame.depth.dtype == np.float32 and np.allclose(frame.depth, 0.5)
    assert np.allclose(frame.T_world_camera.translation, [0.4, 0.0, 0.3])
    assert frame.intrinsics == Intrinsics(4, 3, 3.0, 3.0, 1.5, 1.0)


def test_a_recording_at_the_camera_s_rate_gives_one_view_per_stop_of_the_joints() -> None:
    ms = 1_000_000
    images = [i * 100 * ms for i in range(40)]  # 10 Hz for 4 s
    # joints at 50 Hz: still until 0.9 s, moving to 2.0 s, still to 3.0 s, the plate turning to 3.4 s, still after
    joints = []
    for i in range(200):
        t = i * 20 * ms
        arm = min(max(t - 900 * ms, 0), 1100 * ms) / (1100 * ms)
        plate = min(max(t - 3000 * ms, 0), 400 * ms) / (400 * ms)
        joints.append((t, np.array([arm, 0.5, plate])))
    views = still_images(images, joints)
    assert views == [0, 23, 37]  # the first image, then the first one 0.3 s after each stop (2.3 s, 3.7 s)
    assert still_images(images, []) == list(range(40))  # no joint states: every image is a view
    assert still_images(images[:3], [(500 * ms, np.array([0.0]))]) == []  # before any joint state: unknown


@pytest.mark.parametrize(
    ("kind", "expected"),
    [
        ("no-info-topic", f"no topic {CAMERA_INFO_TOPIC} (sensor_msgs/msg/CameraInfo)"),
        ("no-info", f"no camera info on {CAMERA_INFO_TOPIC}"),
        ("encoding", "encoding 'rgb8': expected 32FC1 (metres) or 16UC1 (millimetres)"),
        ("frame", "/tf does not connect the frame 'table'"),
        ("depth-topic", "no topic /depth (sensor_msgs/msg/Image)"),
    ],
)
def test_a_bad_bag_is_refused_naming_what_is_missing_and_creates_nothing(
    scan: dict[str, Any], tmp_path: Path, kind: str, expected: str
) -> None:
    client, settings = scan["client"], scan["settings"]
    recordings = settings.data_dir / "recordings"
    recordings.mkdir(exist_ok=True)
    name = f"bad-{kind}.mcap"
    write_bag(
        recordings / name,
        encoding="rgb8" if kind == "encoding" else "32FC1",
        info=kind != "no-info-topic",
        info_messages=kind != "no-info",
    )
    topics = {"plate_frame": "table"} if kind == "frame" else {"depth": "/depth"} if kind == "depth-topic" else None
    before = sorted(p.name for p in (settings.data_dir / "sessions").iterdir())
    source: dict[str, Any] = {"kind": "replay", "recording": name}
    if topics:
        source["topics"] = topics
    r = client.post("/api/sessions", json={"config": SMALL, "source": source})
    assert r.status_code == 422 and expected in r.json()["detail"], r.text
    assert sorted(p.name for p in (settings.data_dir / "sessions").iterdir()) == before
    with pytest.raises(ValueError, match="unknown key"):
        BagTopics.from_dict({"image": "/x"})


def test_export_bag_refuses_another_suffix_and_writes_nothing(scan: dict[str, Any], tmp_path: Path, capsys) -> None:
    assert main(["export-bag", str(scan["dir"]), "--out", str(tmp_path / "scan.bag")]) == 2
    assert "a bag is a .mcap (MCAP) or .db3 (SQLite 3) file" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(ValueError, match="'humble' or 'jazzy'"):
        typestore("iron")
    client = scan["client"]
    sid = client.post("/api/sessions", json={"model": "mug", "config": SMALL}).json()["id"]
    r = client.get(f"/api/sessions/{sid}/export.mcap")
    assert r.status_code == 409 and "no view yet" in r.json()["detail"]
    assert client.get(f"/api/sessions/{sid}/export.mcap?distro=iron").status_code == 422


# ---------------------------------------------------------------------- capture during moves


def test_the_frames_kept_during_moves_go_into_the_bag_between_their_views(tmp_path: Path) -> None:
    from workbench.journal.bag import MOVE_CAMERA_INFO_TOPIC, MOVE_DEPTH_TOPIC, MOVE_POSE_TOPIC

    settings = with_small_costs(AppSettings(viser_port=0, scene=False, data_dir=tmp_path / "data"))
    views = 3
    with TestClient(create_app(settings), base_url=BASE_URL) as client:
        body = {"model": "mug", "config": SMALL, "seed": 4, "move_capture": 5.0}
        sid = client.post("/api/sessions", json=body).json()["id"]
        assert client.post(f"/api/sessions/{sid}/capture").status_code == 200
        for _ in range(views - 1):
            assert client.post(f"/api/sessions/{sid}/step").status_code == 200
        r = client.get(f"/api/sessions/{sid}/export.mcap")
        assert r.status_code == 200, r.text
    bag = tmp_path / "moves.mcap"
    bag.write_bytes(r.content)
    journal = read_journal(settings.data_dir / "sessions" / sid)
    captures = journal.of_kind("capture")
    kept = [
        (e, entry, frame)
        for e in captures
        for entry, frame in zip(e.get("move_frames", []), journal.move_frames(e), strict=True)
    ]
    assert len(captures) == views and len(kept) >= 2  # the moves brought frames
    msgs = read_bag(bag)
    view_stamps = [s for s, _ in msgs[DEPTH_TOPIC]]
    assert len(view_stamps) == views  # the views' topic keeps one image per view
    images = msgs[MOVE_DEPTH_TOPIC]
    assert len(images) == len(msgs[MOVE_CAMERA_INFO_TOPIC]) == len(msgs[MOVE_POSE_TOPIC]) == len(kept)
    stamps = [s for s, _ in images]
    assert stamps == sorted(set(stamps))  # strictly increasing
    assert [m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec for _, m in images] == stamps
    by_view = [captures.index(e) for e, _, _ in kept]
    for stamp, v in zip(stamps, by_view, strict=True):  # after the view before the move, before the move's view
        assert (view_stamps[v - 1] if v > 0 else 0) < stamp < view_stamps[v]
    for (_, entry, (frame, registered)), (_, image), (_, pose) in zip(kept, images, msgs[MOVE_POSE_TOPIC], strict=True):
        assert image.encoding == "32FC1" and image.header.frame_id == "camera_depth_optical_frame"
        assert bytes(image.data) == frame.depth.astype("<f4").tobytes()  # the journaled frame, bit for bit
        p = pose.pose.position
        assert pose.header.frame_id == "plate"
        assert np.allclose([p.x, p.y, p.z], Pose.from_dict(entry["pose_used"]).translation, atol=1e-12)
        assert np.allclose([p.x, p.y, p.z], registered.translation, atol=1e-12)
    tf = [(s, t) for s, m in msgs["/tf"] for t in m.transforms if t.child_frame_id == "camera_depth_optical_frame"]
    assert len(tf) == views + len(kept)
    moved = [t for s, t in tf if s in set(stamps)]
    got = moved[0].transform.translation  # the frame's pose as captured, as the views'
    assert np.allclose([got.x, got.y, got.z], kept[0][2][0].T_world_camera.translation, atol=1e-12)
    assert len(load_bag(bag).frames) == views  # the playback reader takes the views only


def test_a_move_frame_is_stamped_its_time_into_the_move_before_its_view_squeezed_into_a_shorter_window() -> None:
    from workbench.journal.bag import move_stamps

    s = 1_000_000_000
    views = [10 * s, 20 * s, 21 * s]
    got = move_stamps(views, [[0.5], [1.0, 2.5], [0.0, 1.0, 4.0]], [2.0, 4.0, 4.0], first=9 * s)
    # the first move starts at the session's start (9 s), 2 s long: its window (1 s) is shorter, t scaled by 1/2;
    # the second move (4 s) fits between its views: it ends at its view, t after its start (16 s);
    # the third's window is 1 s for 4 s of move: scaled by 1/4, the frame at t = 0 kept after the previous view
    assert got == [[9 * s + s // 4], [17 * s, 18 * s + s // 2], [20 * s + 1, 20 * s + s // 4, 21 * s - 1]]
    assert move_stamps(views, [[], [], []], [0.0, 3.0, 3.0], first=None) == [[], [], []]
    assert move_stamps([5 * s], [[1.0]], [3.0], first=None) == [[3 * s]]  # no session start: the move's own 3 s
