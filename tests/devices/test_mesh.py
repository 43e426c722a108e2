"""load_mesh / place_on_plate / sample_surface: scale, placement, up conversion, and one-line errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from devices.mesh import MeshError, load_mesh, place_on_plate, sample_surface, turned_about_plate_axis

MODELS = Path(__file__).resolve().parents[3] / "shared" / "models"
STANFORD = ["bunny.obj", "armadillo.obj", "dragon.ply", "buddha.obj"]

# A y-up wedge: 4 vertices, its raw bounds are x [1, 3], y [10, 14], z [-2, -1].
WEDGE_V = np.array([[1.0, 10.0, -2.0], [3.0, 10.0, -2.0], [1.0, 14.0, -2.0], [1.0, 10.0, -1.0]])
WEDGE_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def _assert_placed(mesh: trimesh.Trimesh, size: float) -> None:
    lo, hi = mesh.bounds
    assert np.max(hi - lo) == pytest.approx(size, abs=1e-12)
    assert lo[2] == pytest.approx(0.0, abs=1e-12)
    assert lo[0] + hi[0] == pytest.approx(0.0, abs=1e-12)
    assert lo[1] + hi[1] == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("name", STANFORD)
def test_stanford_models_are_scaled_centred_and_z_up(name: str) -> None:
    raw = trimesh.load(MODELS / name, force="mesh", process=False)
    assert isinstance(raw, trimesh.Trimesh)
    mesh = load_mesh(MODELS / name, up="y", size=0.2)
    _assert_placed(mesh, 0.2)
    raw_extent = raw.vertices.max(axis=0) - raw.vertices.min(axis=0)
    scale = 0.2 / raw_extent.max()
    # y-up -> z-up: the new extents are the old (x, z, y) ones, scaled.
    np.testing.assert_allclose(mesh.extents, raw_extent[[0, 2, 1]] * scale, rtol=1e-9)
    assert len(mesh.faces) == len(raw.faces)


def test_bunny_size_and_up_z_keeps_axes() -> None:
    raw = trimesh.load(MODELS / "bunny.obj", force="mesh", process=False)
    assert isinstance(raw, trimesh.Trimesh)
    mesh = load_mesh(str(MODELS / "bunny.obj"), up="z", size=0.3)
    _assert_placed(mesh, 0.3)
    raw_extent = raw.vertices.max(axis=0) - raw.vertices.min(axis=0)
    np.testing.assert_allclose(mesh.extents, raw_extent * 0.3 / raw_extent.max(), rtol=1e-9)


@pytest.mark.parametrize("suffix", [".ply", ".obj", ".stl", ".off", ".glb"])
def test_every_format_maps_vertices_exactly(tmp_path: Path, suffix: str) -> None:
    path = tmp_path / f"wedge{suffix}"
    trimesh.Trimesh(WEDGE_V, WEDGE_F, process=False).export(path)
    mesh = load_mesh(path, up="y", size=0.2)
    # largest raw extent is y (4); scale 0.05. y-up -> z-up: (x, y, z) -> (x, -z, y), then centre x/y, lift.
    s = 0.2 / 4.0
    expected = np.column_stack([(WEDGE_V[:, 0] - 2.0) * s, (-WEDGE_V[:, 2] - 1.5) * s, (WEDGE_V[:, 1] - 10.0) * s])
    got = np.asarray(mesh.vertices)
    for v in expected:  # exporters may reorder or duplicate vertices: every expected one must be present
        assert np.min(np.linalg.norm(got - v, axis=1)) < 1e-6
    assert len(mesh.faces) == 4
    # orientation is preserved: the closed wedge still has positive volume
    assert mesh.volume == pytest.approx(abs(trimesh.Trimesh(expected, WEDGE_F).volume), rel=1e-5)


def test_glb_scene_is_flattened_and_concatenated(tmp_path: Path) -> None:
    a = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    b = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    scene = trimesh.Scene()
    scene.add_geometry(a, node_name="a")
    scene.add_geometry(b, node_name="b", transform=trimesh.transformations.translation_matrix((3.0, 0.0, 0.0)))
    scene.export(tmp_path / "two.glb")
    mesh = load_mesh(tmp_path / "two.glb", up="z", size=0.4)
    assert len(mesh.faces) == 24
    _assert_placed(mesh, 0.4)
    np.testing.assert_allclose(mesh.extents, [0.4, 0.1, 0.1], atol=1e-6)  # 4 x 1 x 1 units, the transform applied


def test_open_mesh_and_unreferenced_vertices(tmp_path: Path) -> None:
    # One triangle (not watertight) plus an unused vertex far away that must not count for the bounds.
    path = tmp_path / "tri.obj"
    path.write_text("v 0 0 0\nv 2 0 0\nv 0 1 0\nv 100 100 100\nf 1 2 3\n")
    mesh = load_mesh(path, up="z", size=0.2)
    assert not mesh.is_watertight
    assert len(mesh.vertices) == 3
    np.testing.assert_allclose(mesh.bounds, [[-0.1, -0.05, 0.0], [0.1, 0.05, 0.0]], atol=1e-12)


def test_place_on_plate_copies() -> None:
    box = trimesh.creation.box(extents=(2.0, 1.0, 4.0))
    before = box.vertices.copy()
    placed = place_on_plate(box, up="z", size=1.0)
    np.testing.assert_array_equal(box.vertices, before)
    np.testing.assert_allclose(placed.bounds, [[-0.25, -0.125, 0.0], [0.25, 0.125, 1.0]])


def test_turned_about_plate_axis_rotates_counter_clockwise_about_z_and_copies() -> None:
    placed = place_on_plate(trimesh.creation.box(extents=(2.0, 1.0, 4.0)), up="z", size=1.0)
    before = placed.vertices.copy()
    turned = turned_about_plate_axis(placed, 90.0)
    np.testing.assert_array_equal(placed.vertices, before)
    # +x goes to +y: the box's long side now lies along y; heights are kept.
    np.testing.assert_allclose(turned.bounds, [[-0.125, -0.25, 0.0], [0.125, 0.25, 1.0]], atol=1e-12)
    np.testing.assert_allclose(turned.vertices[:, 0], -before[:, 1], atol=1e-12)
    np.testing.assert_allclose(turned.vertices[:, 1], before[:, 0], atol=1e-12)
    np.testing.assert_array_equal(turned.faces, placed.faces)
    with pytest.raises(MeshError, match="yaw: must be finite"):
        turned_about_plate_axis(placed, float("nan"))


def _write(path: Path, content: bytes | str) -> Path:
    if isinstance(content, str):
        content = content.encode()
    path.write_bytes(content)
    return path


@pytest.mark.parametrize(
    ("make", "pattern"),
    [
        (lambda d: d / "missing.obj", r"missing\.obj: no such file"),
        (lambda d: d, r": not a file"),
        (lambda d: _write(d / "points.xyz", "1 2 3\n"), r"unsupported file type '\.xyz' \(supported: ply, obj"),
        (lambda d: _write(d / "noext", "x"), r"unsupported file type '\(none\)'"),
        (lambda d: _write(d / "garbage.ply", "hello world"), r"garbage\.ply: cannot read as PLY \("),
        (lambda d: _write(d / "garbage.glb", "hello"), r"garbage\.glb: cannot read as GLB \("),
        (lambda d: _write(d / "empty.obj", ""), r"empty\.obj: empty mesh \(no faces\)"),
        (lambda d: _write(d / "text.obj", "hello world\n"), r"text\.obj: empty mesh \(no faces\)"),
        (lambda d: _write(d / "verts.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n"), r"verts\.obj: .*(no faces|point cloud)"),
        (
            lambda d: _write(d / "nan.obj", "v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n"),
            r"nan\.obj: 1 vertices with non-finite",
        ),
        (lambda d: _write(d / "flat.obj", "v 1 1 1\nv 1 1 1\nv 1 1 1\nf 1 2 3\n"), r"flat\.obj: degenerate mesh"),
    ],
)
def test_errors_are_one_clear_line(tmp_path: Path, make, pattern: str) -> None:
    path = make(tmp_path)
    with pytest.raises(MeshError, match=pattern) as info:
        load_mesh(path)
    assert "\n" not in str(info.value)
    assert isinstance(info.value, ValueError)


def test_point_cloud_ply_is_not_a_mesh(tmp_path: Path) -> None:
    trimesh.PointCloud(np.random.default_rng(0).random((20, 3))).export(tmp_path / "cloud.ply")
    with pytest.raises(MeshError, match=r"cloud\.ply: contains a point cloud \(20 points\), not a triangle mesh"):
        load_mesh(tmp_path / "cloud.ply")


@pytest.mark.parametrize(
    ("kwargs", "pattern"),
    [
        ({"size": 0.0}, r"^size: must be a finite number > 0"),
        ({"size": -1.0}, r"^size: must be a finite number > 0"),
        ({"size": float("nan")}, r"^size: must be a finite number > 0"),
        ({"up": "x"}, r"^up: must be 'y' or 'z', got 'x'"),
    ],
)
def test_bad_options_are_checked_before_reading(kwargs: dict, pattern: str) -> None:
    with pytest.raises(MeshError, match=pattern):
        load_mesh("/nonexistent/file.obj", **kwargs)


def test_sample_surface_is_seeded_uniform_and_on_the_surface() -> None:
    box = place_on_plate(trimesh.creation.box(extents=(2.0, 1.0, 1.0)), up="z", size=0.2)  # 0.2 x 0.1 x 0.1
    a = sample_surface(box, 20000, seed=3)
    assert a.shape == (20000, 3) and a.dtype == np.float64
    np.testing.assert_array_equal(a, sample_surface(box, 20000, seed=3))
    assert not np.array_equal(a, sample_surface(box, 20000, seed=4))
    lo, hi = box.bounds
    on_face = np.minimum(np.abs(a - lo), np.abs(a - hi)).min(axis=1)
    assert on_face.max() < 1e-12
    # area-uniform: the two 0.1 x 0.1 end faces (x = +-0.1) hold 0.02 / 0.10 = 20 % of the area
    ends = np.mean(np.isclose(np.abs(a[:, 0]), 0.1))
    assert ends == pytest.approx(0.2, abs=0.015)


def test_sample_surface_rejects_bad_n() -> None:
    box = trimesh.creation.box()
    with pytest.raises(ValueError, match="n: must be an integer >= 1"):
        sample_surface(box, 0)
