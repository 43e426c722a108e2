"""The replay devices: recording folders (PLY + pose JSON per view) and the cell that plays frames back."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from devices.builtins import make_builtin
from devices.config import CellConfig
from devices.ply import write_ply
from devices.protocols import CaptureError
from devices.replay import ReplayCamera, ReplayCell, load_recording
from devices.sim import make_sim_cell
from planner import DepthFrame, Intrinsics, Pose

K = Intrinsics(160, 120, 152.5, 152.5, 79.5, 59.5)
VIEWS = [Pose.look_at([0.45 * np.cos(a), 0.45 * np.sin(a), 0.3], [0, 0, 0.08]) for a in (0.0, 2.0, 4.0)]


@pytest.fixture(scope="module")
def frames() -> list[DepthFrame]:
    from devices.config import CameraConfig

    cell = make_sim_cell(
        make_builtin("l-block", 0.2),
        CameraConfig(width=160, height=120, fx=152.5, fy=152.5, cx=79.5, cy=59.5),
        CellConfig(kinematics="reach_sphere"),  # the sphere puts the camera exactly at the recorded views
    )
    out = []
    for pose in VIEWS:
        cell.move_to(pose)
        out.append(cell.capture())
    return out


def write_recording(folder: Path, frames: list[DepthFrame], *, camera_frame: bool = False) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "intrinsics.json").write_text(
        json.dumps(dict(width=160, height=120, fx=152.5, fy=152.5, cx=79.5, cy=59.5))
    )
    for i, f in enumerate(frames):
        points = f.points_camera if camera_frame else f.points_world
        write_ply(folder / f"view_{i:02d}.ply", points)
        meta = {"T_world_camera": f.T_world_camera.to_dict(), "points_frame": "camera" if camera_frame else "world"}
        (folder / f"view_{i:02d}.json").write_text(json.dumps(meta))
    return folder


def test_a_recording_becomes_the_same_depth_images(tmp_path: Path, frames) -> None:
    for camera_frame in (False, True):
        loaded = load_recording(write_recording(tmp_path / f"rec{camera_frame}", frames, camera_frame=camera_frame))
        assert len(loaded) == 3
        for a, b in zip(frames, loaded, strict=True):
            assert b.intrinsics == K
            assert np.allclose(a.T_world_camera.matrix, b.T_world_camera.matrix)
            assert np.array_equal(a.valid, b.valid)
            assert np.allclose(a.depth, b.depth, atol=1e-5)


def bad_recording(tmp_path: Path, frames, case: str) -> Path:
    folder = write_recording(tmp_path / case, frames[:2])
    if case == "nan":
        pts = frames[1].points_world.copy()
        pts[5] = np.nan
        write_ply(folder / "view_01.ply", pts)
    elif case == "inf":
        pts = frames[1].points_world.copy()
        pts[7, 2] = np.inf
        write_ply(folder / "view_01.ply", pts)
    elif case == "empty":  # every point behind the camera
        pose = frames[1].T_world_camera
        write_ply(folder / "view_01.ply", pose.apply(np.array([[0.0, 0.0, -0.5], [0.01, 0.0, -0.4]])))
    elif case == "no-points":
        write_ply(folder / "view_01.ply", np.zeros((0, 3)))
    elif case == "missing-ply":
        (folder / "view_01.ply").unlink()
    elif case == "bad-pose":
        (folder / "view_01.json").write_text(json.dumps({"T_world_camera": {"position": [0, 0], "wxyz": [1, 0, 0, 0]}}))
    elif case == "bad-json":
        (folder / "view_01.json").write_text("{not json")
    elif case == "no-intrinsics":
        (folder / "intrinsics.json").unlink()
    elif case == "nothing":
        for p in folder.iterdir():
            p.unlink()
    return folder


@pytest.mark.parametrize(
    ("case", "message"),
    [
        ("nan", "non-finite"),
        ("inf", "non-finite"),
        ("empty", "empty view"),
        ("no-points", "empty view"),
        ("missing-ply", "no view_01.ply"),
        ("bad-pose", "T_world_camera"),
        ("bad-json", "not readable JSON"),
        ("no-intrinsics", "no intrinsics"),
        ("nothing", "no views"),
    ],
)
def test_bad_recordings_are_refused_with_the_file_named(tmp_path: Path, frames, case: str, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        load_recording(bad_recording(tmp_path, frames, case))


def test_symlinks_out_of_the_recording_are_ignored(tmp_path: Path, frames) -> None:
    outside = write_recording(tmp_path / "outside", frames[:1])
    folder = write_recording(tmp_path / "rec", frames[:1])
    os.symlink(outside / "view_00.json", folder / "view_99.json")
    os.symlink(outside / "view_00.ply", folder / "view_99.ply")
    assert len(load_recording(folder)) == 1


def test_sequence_and_nearest_playback(frames) -> None:
    cam = ReplayCamera(frames)
    assert [cam.capture() for _ in range(3)] == frames
    with pytest.raises(CaptureError, match="all 3 recorded frames"):
        cam.capture()
    state = {"position": 1}
    cam.restore_device_state(state)
    assert cam.capture() is frames[1] and cam.device_state() == {"position": 2}

    cell = ReplayCell(frames, mode="nearest")
    near_2 = Pose.look_at(VIEWS[2].translation + 0.02, [0, 0, 0.08])
    cell.move_to(near_2)
    assert cell.capture() is frames[2]
    seq = ReplayCell(frames)
    assert np.allclose(seq.initial_pose().translation, VIEWS[0].translation)
    seq.move_to(VIEWS[2])  # a sequence plays frame 1 whatever was asked; the recorded pose is kept
    first = seq.capture()
    assert first is frames[0] and np.allclose(first.T_world_camera.translation, VIEWS[0].translation)
    assert seq.is_reachable(VIEWS[0]) == make_sim_cell(
        None, cell_config=CellConfig(kinematics="reach_sphere")
    ).is_reachable(VIEWS[0])


def test_a_replay_cell_takes_a_move_planned_for_the_next_view(frames) -> None:
    """The tour's ring asks its first move with the views after it (``Cell.move_to(then=...)``): a replay cell
    accepts the request and moves as without it (the views were taken already)."""
    a, b = ReplayCell(frames, mode="nearest"), ReplayCell(frames, mode="nearest")
    near_2 = Pose.look_at(VIEWS[2].translation + 0.02, [0, 0, 0.08])
    ma, mb = a.move_to(near_2, then=[VIEWS[0], VIEWS[1]]), b.move_to(near_2)
    assert ma.angle == mb.angle and np.allclose(ma.T_base_camera.matrix, mb.T_base_camera.matrix)
    assert a.capture() is b.capture() is frames[2]


def test_replay_camera_refuses_mixed_intrinsics(frames) -> None:
    other = DepthFrame(np.zeros((10, 10), np.float32), Pose.identity(), Intrinsics(10, 10, 10, 10, 4.5, 4.5))
    with pytest.raises(ValueError, match="intrinsics differ"):
        ReplayCamera([frames[0], other])
    with pytest.raises(ValueError, match="no frames"):
        ReplayCamera([])
