"""workbench.evaluation.accuracy on objects with known answers."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from workbench.evaluation import GroundTruth, accuracy, coverage, coverage_and_accuracy, fscore


@pytest.fixture(scope="module")
def cube() -> tuple[trimesh.Trimesh, GroundTruth]:
    mesh = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    samples, _ = trimesh.sample.sample_surface_even(mesh, 20_000, seed=0)
    return mesh, GroundTruth.of(mesh, np.asarray(samples))


def test_a_perfect_dense_cloud_scores_one(cube: tuple[trimesh.Trimesh, GroundTruth]) -> None:
    mesh, truth = cube
    cloud, _ = trimesh.sample.sample_surface_even(mesh, 40_000, seed=1)
    acc = accuracy(truth, cloud)
    assert acc.precision_2mm == pytest.approx(1.0) and acc.precision_5mm == pytest.approx(1.0)
    assert acc.recall_5mm > 0.999 and acc.fscore_5mm > 0.999
    assert acc.mean_mm < 1e-3 and acc.chamfer_mm < 1.0


def test_an_offset_cloud_has_known_distances(cube: tuple[trimesh.Trimesh, GroundTruth]) -> None:
    """Points 3 mm off the top face: precision 0 at 2 mm, 1 at 5 mm; mean distance 3 mm; recall = the top's share."""
    _, truth = cube
    xs, ys = np.meshgrid(np.linspace(-0.045, 0.045, 60), np.linspace(-0.045, 0.045, 60))
    cloud = np.column_stack([xs.ravel(), ys.ravel(), np.full(xs.size, 0.05 + 0.003)])
    acc = accuracy(truth, cloud)
    assert acc.precision_2mm == 0.0 and acc.precision_5mm == 1.0
    assert acc.mean_mm == pytest.approx(3.0, abs=1e-3) and acc.p90_mm == pytest.approx(3.0, abs=1e-3)
    assert acc.recall_5mm == pytest.approx(1 / 6, abs=0.02)  # the top face of six (and its rim)
    assert acc.fscore_5mm == pytest.approx(fscore(1.0, acc.recall_5mm))


def test_outliers_lower_precision_not_recall(cube: tuple[trimesh.Trimesh, GroundTruth]) -> None:
    mesh, truth = cube
    cloud, _ = trimesh.sample.sample_surface_even(mesh, 20_000, seed=2)
    noisy = np.concatenate([cloud, np.random.default_rng(0).uniform(0.2, 0.3, (5_000, 3))])
    a, b = accuracy(truth, cloud), accuracy(truth, noisy)
    assert b.recall_5mm == a.recall_5mm
    assert b.precision_5mm == pytest.approx(len(cloud) / len(noisy), abs=1e-3)


def test_empty_cloud_and_bad_input(cube: tuple[trimesh.Trimesh, GroundTruth]) -> None:
    _, truth = cube
    empty = accuracy(truth, np.zeros((0, 3)))
    assert empty.fscore_5mm == 0.0 and empty.to_json()["chamfer_mm"] is None
    with pytest.raises(ValueError, match="cloud: expected shape"):
        accuracy(truth, np.zeros((4, 2)))


def test_the_recall_query_in_spatial_order_gives_each_sample_its_own_distance(
    cube: tuple[trimesh.Trimesh, GroundTruth],
) -> None:
    """The samples are queried cell by cell (``spatial_order``) and each distance is put back at its sample: the
    distances equal brute force's sample for sample, and recall and chamfer are made of them."""
    from workbench.evaluation.accuracy import QUERY_CELL, spatial_order

    _, truth = cube
    order = truth.query_order
    assert sorted(order.tolist()) == list(range(len(truth.samples)))  # a permutation of the samples
    cells = np.floor(truth.samples[order] / QUERY_CELL).astype(np.int64)
    keys = [tuple(c) for c in cells]
    assert keys == sorted(keys) and len(set(keys)) > 100  # visited cell by cell, many cells
    assert np.array_equal(spatial_order(truth.samples), order)
    cloud = np.random.default_rng(3).uniform(-0.06, 0.06, (400, 3))  # all over the cube, some far from samples
    nearest = np.concatenate(
        [
            np.sqrt(((chunk[:, None, :] - cloud[None]) ** 2).sum(axis=2)).min(axis=1)
            for chunk in np.array_split(truth.samples, 10)
        ]
    )  # (M,) brute force, in the samples' order
    got = truth.samples_distance(cloud)
    np.testing.assert_allclose(got, nearest, rtol=1e-12, atol=0)
    assert got.max() > 5 * got.min() > 0  # distances differ from sample to sample: a misplaced one would show
    acc = accuracy(truth, cloud)
    assert acc.recall_5mm == float(np.mean(got <= 0.005))
    assert acc.chamfer_mm == pytest.approx((truth.distance(cloud).mean() + got.mean()) / 2 * 1000, rel=1e-12)


def test_coverage_taken_from_the_recall_is_the_coverage_to_the_bit(cube: tuple[trimesh.Trimesh, GroundTruth]) -> None:
    """A view asks coverage and accuracy of one cloud: with the truth's own samples the coverage is the recall at
    5 mm, equal to what coverage() measures on its own, for partial, noisy and offset clouds; other samples are
    measured by coverage(); each is None without its input."""
    mesh, truth = cube
    rng = np.random.default_rng(4)
    for k in range(8):
        cloud, _ = trimesh.sample.sample_surface_even(mesh, 30_000, seed=k)
        cloud = np.asarray(cloud)[np.asarray(cloud)[:, k % 3] > rng.uniform(-0.05, 0.05)]  # a partial view
        cloud = cloud + rng.normal(0.0, 0.001 * k, cloud.shape) + rng.uniform(-0.004, 0.004, 3)
        cov, acc = coverage_and_accuracy(truth.samples.copy(), truth, cloud)
        assert acc == accuracy(truth, cloud)
        assert cov == coverage(truth.samples, cloud) == acc.recall_5mm
        assert 0.0 < cov < 1.0
    other = truth.samples[:5000] + 0.003  # not the truth's samples: measured on its own
    cov, acc = coverage_and_accuracy(other, truth, cloud)
    assert acc is not None and cov == coverage(other, cloud) and cov != acc.recall_5mm
    assert coverage_and_accuracy(None, truth, cloud)[0] is None
    assert coverage_and_accuracy(other, None, cloud) == (coverage(other, cloud), None)
