"""Built-in objects: placement, closed surfaces, and the features each one exists for."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import open3d as o3d
import pytest
import trimesh

from devices.builtins import BUILTIN_OBJECTS, grid_surface, make_builtin, resolve_model
from devices.mesh import MeshError

MODELS = Path(__file__).resolve().parents[3] / "shared" / "models"


def _first_hit(
    mesh: trimesh.Trimesh, origin: tuple[float, float, float], direction: tuple[float, float, float]
) -> float:
    """Distance along a unit ray to the first hit (inf for a miss)."""
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor.from_numpy(np.ascontiguousarray(mesh.vertices, dtype=np.float32)),
        o3d.core.Tensor.from_numpy(np.ascontiguousarray(mesh.faces, dtype=np.uint32)),
    )
    ray = o3d.core.Tensor.from_numpy(np.array([[*origin, *direction]], dtype=np.float32))
    return float(scene.cast_rays(ray)["t_hit"].numpy()[0])


def test_the_required_objects_exist_with_one_line_descriptions() -> None:
    assert {"l-block", "mug", "two-boxes", "sphere", "box"} <= set(BUILTIN_OBJECTS)
    for description in BUILTIN_OBJECTS.values():
        assert description and "\n" not in description


@pytest.mark.parametrize("name", list(BUILTIN_OBJECTS))
@pytest.mark.parametrize("size", [0.2, 0.05])
def test_builtins_are_placed_like_loaded_meshes(name: str, size: float) -> None:
    mesh = make_builtin(name, size)
    lo, hi = mesh.bounds
    assert np.max(hi - lo) == pytest.approx(size, abs=1e-12)
    assert lo[2] == pytest.approx(0.0, abs=1e-12)
    assert lo[0] + hi[0] == pytest.approx(0.0, abs=1e-12) and lo[1] + hi[1] == pytest.approx(0.0, abs=1e-12)
    assert np.all(np.isfinite(mesh.vertices)) and len(mesh.faces) > 0
    assert mesh.is_winding_consistent


@pytest.mark.parametrize(
    ("name", "volume"),
    [
        # unit-grid volumes scaled by (size / largest extent)^3 = 0.2^3
        ("box", 1.0 * 0.7 * 0.5 * 0.008),
        ("two-boxes", (0.4 * 0.6 * 1.0 + 0.4 * 0.6 * 0.6) * 0.008),
        ("l-block", (1.0 * 0.5 * 0.3 + 0.3 * 0.5 * 0.7 - 0.3 * 0.15 * 0.25) * 0.008),
    ],
)
def test_boxy_builtins_are_closed_with_exact_volume(name: str, volume: float) -> None:
    mesh = make_builtin(name)
    assert mesh.is_watertight
    assert mesh.volume == pytest.approx(volume, rel=1e-9)


def test_sphere_is_closed_and_round() -> None:
    mesh = make_builtin("sphere")
    assert mesh.is_watertight
    r = np.linalg.norm(mesh.vertices - [0.0, 0.0, 0.1], axis=1)
    np.testing.assert_allclose(r, 0.1, atol=1e-12)


def test_l_block_has_a_through_hole() -> None:
    mesh = make_builtin("l-block")
    # The upright is x in [-0.1, -0.04]; the hole is y in [-0.015, 0.015], z in [0.1, 0.15].
    assert _first_hit(mesh, (-0.5, 0.0, 0.125), (1.0, 0.0, 0.0)) == np.inf
    assert _first_hit(mesh, (-0.5, 0.0, 0.17), (1.0, 0.0, 0.0)) == pytest.approx(0.4, abs=1e-6)
    assert _first_hit(mesh, (-0.5, 0.03, 0.125), (1.0, 0.0, 0.0)) == pytest.approx(0.4, abs=1e-6)
    # the slab: from above at x = 0.05 the top of the slab is at z = 0.06
    assert _first_hit(mesh, (0.05, 0.0, 1.0), (0.0, 0.0, -1.0)) == pytest.approx(0.94, abs=1e-6)


def test_two_boxes_have_a_gap() -> None:
    mesh = make_builtin("two-boxes")
    x = np.asarray(mesh.vertices)[:, 0]
    assert not np.any((x > -0.02 + 1e-9) & (x < 0.02 - 1e-9))
    assert _first_hit(mesh, (0.0, 0.0, 1.0), (0.0, 0.0, -1.0)) == np.inf  # straight down the gap
    assert _first_hit(mesh, (-0.06, 0.0, 1.0), (0.0, 0.0, -1.0)) == pytest.approx(0.8, abs=1e-6)  # tall box, 0.2
    assert _first_hit(mesh, (0.06, 0.0, 1.0), (0.0, 0.0, -1.0)) == pytest.approx(0.88, abs=1e-6)  # short box, 0.12


def test_mug_is_open_at_the_top_with_a_handle() -> None:
    mesh = make_builtin("mug")
    s = 0.2 / 0.94  # unit mug: body radius 0.35, height 0.8, floor 0.06, handle reaching x = 0.59
    axis_x = -0.12 * s  # the bounding box centre is x = 0.12 in unit coordinates
    # Looking down the body axis the ray passes the open top and lands on the inner floor.
    assert _first_hit(mesh, (axis_x, 0.0, 1.0), (0.0, 0.0, -1.0)) == pytest.approx(1.0 - 0.06 * s, abs=1e-6)
    assert mesh.bounds[1, 2] == pytest.approx(0.8 * s, abs=1e-9)
    # The handle: a horizontal ray at the handle's mid-height from +x hits it before the body.
    t = _first_hit(mesh, (0.5, 0.0, 0.45 * s), (-1.0, 0.0, 0.0))
    assert 0.5 - t == pytest.approx(0.1, abs=1e-6)  # x = +0.1 is the handle's outer extreme


def test_unknown_builtin_lists_the_names() -> None:
    with pytest.raises(MeshError, match=r"unknown built-in object 'teapot' \(known: l-block, mug, two-boxes"):
        make_builtin("teapot")


def test_resolve_model_accepts_names_and_paths() -> None:
    name, mesh = resolve_model("sphere", size=0.1)
    assert name == "sphere" and mesh.extents.max() == pytest.approx(0.1)
    name, mesh = resolve_model(str(MODELS / "bunny.obj"), up="y", size=0.2)
    assert name == "bunny" and mesh.extents.max() == pytest.approx(0.2)
    with pytest.raises(MeshError, match=r"'teapot' is neither a built-in object \(l-block, .*\) nor a mesh file"):
        resolve_model("teapot")
    with pytest.raises(MeshError, match=r"teapot\.obj: no such file"):
        resolve_model("teapot.obj")


def test_grid_surface_single_cell_and_bad_shape() -> None:
    mesh = grid_surface([0, 1], [0, 2], [0, 3], np.ones((1, 1, 1), dtype=bool))
    assert mesh.is_watertight and len(mesh.faces) == 12
    assert mesh.volume == pytest.approx(6.0)
    with pytest.raises(ValueError, match=r"occupied: expected shape \(1, 1, 1\)"):
        grid_surface([0, 1], [0, 1], [0, 1], np.ones((2, 1, 1), dtype=bool))
