"""Depth frames on disk: one ``.npz`` per frame, written durably (temp file, fsync, rename, fsync dir).

The file holds (format version ``FRAME_FORMAT``)::

    format            ()      int64    FRAME_FORMAT
    depth             (H, W)  float32  planar z-depth, metres, 0 = no return
    T_world_camera    (4, 4)  float64  camera pose in the planner's world (turntable) frame
    intrinsics        (6,)    float64  width, height, fx, fy, cx, cy (pixels)

``load_frame`` never unpickles (``allow_pickle=False``) and validates every field:
a non-finite depth, a bad pose or a shape that does not match the intrinsics is a
``ValueError`` naming the file and the field.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import os
from pathlib import Path

import numpy as np

from planner.types import DepthFrame, Intrinsics, Pose

FRAME_FORMAT = 1


def frame_bytes(frame: DepthFrame) -> bytes:
    """The ``.npz`` bytes of ``frame`` (uncompressed: depth images compress poorly and this is on the hot path)."""
    k = frame.intrinsics
    buf = io.BytesIO()
    np.savez(
        buf,
        format=np.int64(FRAME_FORMAT),
        depth=np.asarray(frame.depth, dtype=np.float32),
        T_world_camera=frame.T_world_camera.matrix,
        intrinsics=np.array([k.width, k.height, k.fx, k.fy, k.cx, k.cy], dtype=np.float64),
    )
    return buf.getvalue()


def write_durably(path: Path, data: bytes, *, fsync: bool = True) -> None:
    """Write ``data`` to ``path`` atomically: a reader (or a restart after kill -9) sees all of it or nothing."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.part")
    try:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            if fsync:
                os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:  # a full disk: no half-written temp file stays behind to fail every retry
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    if fsync:
        fsync_dir(path.parent)


def fsync_dir(directory: Path) -> None:
    """Make a rename or a new file in ``directory`` durable (no-op where directories cannot be opened)."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def save_frame(path: str | Path, frame: DepthFrame, *, fsync: bool = True) -> str:
    """Write ``frame`` to ``path`` durably; returns the sha256 (hex) of the bytes written."""
    data = frame_bytes(frame)
    write_durably(Path(path), data, fsync=fsync)
    return hashlib.sha256(data).hexdigest()


def load_frame(path: str | Path, sha256: str | None = None) -> DepthFrame:
    """Read a frame written by :func:`save_frame`. ValueError for a missing, corrupt or invalid file."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ValueError(f"{path.name}: cannot read frame ({exc.strerror})") from None
    if sha256 is not None and hashlib.sha256(data).hexdigest() != sha256:
        raise ValueError(f"{path.name}: checksum mismatch (the frame file was changed or damaged)")
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as npz:
            arrays = {key: npz[key] for key in ("format", "depth", "T_world_camera", "intrinsics") if key in npz}
    except Exception as exc:  # zipfile / numpy format errors of a damaged file
        raise ValueError(f"{path.name}: not a frame file ({type(exc).__name__}: {exc})") from None
    missing = {"format", "depth", "T_world_camera", "intrinsics"} - set(arrays)
    if missing:
        raise ValueError(f"{path.name}: missing field(s) {sorted(missing)}")
    if int(arrays["format"]) != FRAME_FORMAT:
        raise ValueError(f"{path.name}: frame format {int(arrays['format'])} (this version reads {FRAME_FORMAT})")
    try:
        k = np.asarray(arrays["intrinsics"], dtype=np.float64).reshape(6)
        intrinsics = Intrinsics(int(k[0]), int(k[1]), float(k[2]), float(k[3]), float(k[4]), float(k[5]))
        pose = Pose.from_matrix(arrays["T_world_camera"])
        return DepthFrame(np.asarray(arrays["depth"], dtype=np.float32), pose, intrinsics)
    except ValueError as exc:
        raise ValueError(f"{path.name}: {exc}") from None
