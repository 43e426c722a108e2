"""Mesh files are read in a child process (workbench/mesh_loader.py): bombs die there or in the pre-scan,
a Cancel kills the reader at once, and degenerate meshes are refused naming the problem (thin objects and
sheets stay accepted)."""

from __future__ import annotations

import multiprocessing
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import trimesh

from tests.mesh_bombs import instancing_glb, ply_header_bomb
from workbench.errors import Conflict, Invalid, TooLarge
from workbench.limits import MeshLimits
from workbench.mesh_loader import load_in_child

GiB = 1 << 30


def load(
    path: Path, memory: int = GiB, timeout: float = 60.0, cancelled: threading.Event | None = None
) -> trimesh.Trimesh:
    return load_in_child(
        path, MeshLimits(), up="z", size=0.2, what="model 'x'", memory=memory, timeout=timeout, cancelled=cancelled
    )


def no_reader_left() -> bool:
    return not [p for p in multiprocessing.active_children() if p.name == "mesh-loader"]


def test_an_honest_mesh_comes_back_placed(tmp_path: Path) -> None:
    trimesh.creation.icosphere(subdivisions=3, radius=0.05).export(tmp_path / "ball.obj")
    mesh = load(tmp_path / "ball.obj")
    assert len(mesh.faces) == 1280 and mesh.bounds[0][2] == pytest.approx(0.0)
    assert float(np.max(mesh.extents)) == pytest.approx(0.2)
    assert no_reader_left()


@pytest.mark.parametrize("nodes", [400, 5000])
def test_an_instancing_glb_is_refused_by_its_json_before_any_load(tmp_path: Path, nodes: int) -> None:
    path = tmp_path / "bomb.glb"
    path.write_bytes(instancing_glb(nodes))
    with pytest.raises(TooLarge, match=rf"{nodes * 20_000} triangles \({nodes} mesh instances"):
        load(path)
    small = tmp_path / "few.glb"
    small.write_bytes(instancing_glb(3, 2_000))  # the same structure, within the limits: loaded, instances and all
    assert len(load(small).faces) == 6_000


def test_a_ply_header_that_its_body_cannot_hold_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "bomb.ply"
    path.write_bytes(ply_header_bomb())
    with pytest.raises(Invalid, match="truncated PLY: its header declares"):
        load(path)


def test_a_reader_over_its_memory_or_time_limit_dies_with_413(tmp_path: Path) -> None:
    trimesh.creation.icosphere(subdivisions=6, radius=0.05).export(tmp_path / "ball.obj")  # 82k triangles
    with pytest.raises(TooLarge, match="mesh_load_memory"):
        load(tmp_path / "ball.obj", memory=20 * 1024 * 1024)
    with pytest.raises(TooLarge, match=r"takes longer than 0\.001 s"):
        load(tmp_path / "ball.obj", timeout=0.001)
    assert no_reader_left()


def test_cancel_kills_the_reader_at_once(tmp_path: Path) -> None:
    trimesh.creation.icosphere(subdivisions=7, radius=0.05).export(tmp_path / "big.obj")  # 327k triangles
    cancelled = threading.Event()
    threading.Timer(0.2, cancelled.set).start()
    t0 = time.monotonic()
    with pytest.raises(Conflict, match="cancelled"):
        load(tmp_path / "big.obj", cancelled=cancelled)
    assert time.monotonic() - t0 < 1.0  # reading it takes seconds; the Cancel did not wait for that
    assert no_reader_left()


def _write(path: Path, vertices: np.ndarray, faces: np.ndarray) -> Path:
    lines = [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in vertices] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


BOX = trimesh.creation.box(extents=(0.01, 0.01, 0.01))


@pytest.mark.parametrize(
    ("name", "vertices", "faces", "message"),
    [
        (
            "line",
            np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0.0]]),
            np.array([[0, 1, 2], [1, 2, 3]]),
            "zero total",
        ),
        ("huge", np.array([[-1e308, 0, 0], [1e308, 0, 0], [0, 1e308, 0.0]]), np.array([[0, 1, 2]]), "extent overflows"),
        (
            "outlier",
            np.vstack([BOX.vertices, [[1e30, 0, 0]]]),
            np.vstack([BOX.faces, [[0, 1, 8]]]),
            "far outlier vertex",
        ),
    ],
)
def test_degenerate_meshes_are_refused_naming_the_problem(
    tmp_path: Path, name: str, vertices: np.ndarray, faces: np.ndarray, message: str
) -> None:
    with pytest.raises(Invalid, match=message):
        load(_write(tmp_path / f"{name}.obj", vertices, faces))


def test_a_thin_object_and_a_standing_sheet_are_accepted(tmp_path: Path) -> None:
    thin = trimesh.creation.box(extents=(0.1, 0.1, 0.0002))
    assert len(load(_write(tmp_path / "thin.obj", thin.vertices, thin.faces)).faces) == 12
    sheet = np.array([[0, 0, 0], [0.1, 0, 0], [0.1, 0, 0.1], [0, 0, 0.1]])  # a vertical square, zero thickness
    mesh = load(_write(tmp_path / "sheet.obj", sheet, np.array([[0, 1, 2], [0, 2, 3]])))
    assert mesh.area == pytest.approx(0.04)


def test_a_ply_of_triangle_strips_says_so(tmp_path: Path) -> None:
    path = tmp_path / "strips.ply"
    path.write_text(
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
        "element tristrips 1\nproperty list int int vertex_indices\nend_header\n"
        "0 0 0\n1 0 0\n0 1 0\n1 1 0\n4 0 1 2 3\n"
    )
    with pytest.raises(Invalid, match="triangle strips"):
        load(path)
