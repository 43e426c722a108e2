"""coverage: the fraction of ground-truth surface samples that have a scanned point nearby."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.evaluation.coverage import coverage

SAMPLES = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.1, 0.0], [0.0, 0.0, 0.1]])


def test_fraction_within_radius() -> None:
    cloud = np.array([[0.004, 0.0, 0.0], [0.1, 0.0, 0.0049], [0.0, 0.106, 0.0]])
    assert coverage(SAMPLES, cloud, radius=0.005) == 0.5  # samples 0 and 1; sample 2 is 6 mm off
    assert coverage(SAMPLES, cloud, radius=0.007) == 0.75
    assert coverage(SAMPLES, cloud) == 0.5  # default radius 5 mm


def test_complete_and_empty() -> None:
    assert coverage(SAMPLES, SAMPLES) == 1.0
    assert coverage(SAMPLES, np.zeros((0, 3))) == 0.0
    assert coverage(SAMPLES, []) == 0.0


def test_one_point_covers_several_samples() -> None:
    dense = np.column_stack([np.linspace(0.0, 0.01, 11), np.zeros(11), np.zeros(11)])  # 1 mm apart
    assert coverage(dense, [[0.005, 0.0, 0.0]], radius=0.0035) == pytest.approx(7 / 11)


@pytest.mark.parametrize(
    ("samples", "cloud", "radius", "pattern"),
    [
        (np.zeros((0, 3)), SAMPLES, 0.005, "surface_samples: need at least one sample"),
        (SAMPLES, SAMPLES, 0.0, "radius: must be > 0"),
        (SAMPLES, SAMPLES, float("nan"), "radius: must be > 0"),
        (SAMPLES[:, :2], SAMPLES, 0.005, r"surface_samples: expected shape \(N, 3\)"),
        (SAMPLES, np.array([[0.0, np.nan, 0.0]]), 0.005, "cloud: 1 non-finite"),
    ],
)
def test_bad_input(samples: np.ndarray, cloud: np.ndarray, radius: float, pattern: str) -> None:
    with pytest.raises(ValueError, match=pattern):
        coverage(samples, cloud, radius)
