"""``server.surface_score_points``: how many points a simulated session's surface is sampled with when it is scored,
in the server process and in a worker, live and after a discard (the rebuild scores with the same truth)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from devices.config import CameraConfig, DeviceConfig
from tests.helpers import SMALL
from workbench.evaluation.accuracy import GroundTruth
from workbench.registry.registry import SessionRegistry
from workbench.settings import MAX_SCORE_POINTS, MIN_SCORE_POINTS, WorkbenchSettings
from workbench.surface.mesh import SurfaceMesh
from workbench.surface.scoring import SURFACE_SAMPLES, surface_accuracy

CAMERA = CameraConfig(width=160, height=120, fx=152.5, fy=152.5, cx=79.5, cy=59.5)


@pytest.mark.parametrize("workers", [False, True])
def test_a_sessions_surface_is_scored_with_the_servers_points(tmp_path: Path, workers: bool) -> None:
    settings = WorkbenchSettings(
        models_dir=tmp_path / "models",
        data_dir=tmp_path / "data",
        workers=workers,
        devices=DeviceConfig(camera=CAMERA),
        surface_score_points=3_000,
    )
    registry = SessionRegistry(settings)
    try:
        session = registry.create(model="box", config=SMALL)
        session.capture()
        first = session._surface
        assert first is not None and first.accuracy is not None
        assert first.accuracy.points == 3_000
        assert 0.0 < first.accuracy.fscore_5mm <= 1.0
        entry = session.plan()
        session.approve(entry.plan_id, entry.plan.best_index)
        session.discard_last_view()  # the surface rebuilt from the journal, scored against the same truth
        rebuilt = session._surface
        assert rebuilt is not None and rebuilt.accuracy is not None and rebuilt.views == 1
        assert rebuilt.accuracy.points == 3_000
        assert rebuilt.accuracy.fscore_5mm == pytest.approx(first.accuracy.fscore_5mm, abs=1e-12)
    finally:
        registry.close()


def test_the_default_is_the_scorers(tmp_path: Path) -> None:
    assert WorkbenchSettings().surface_score_points == SURFACE_SAMPLES == 100_000
    box = trimesh.creation.box((0.1, 0.1, 0.1))
    truth = GroundTruth.of(box, box.sample(2_000, seed=0))
    surface = SurfaceMesh(np.asarray(box.vertices), np.asarray(box.faces))
    assert surface_accuracy(surface, truth).points == SURFACE_SAMPLES  # a truth without its own count
    dense = GroundTruth.of(box, truth.samples, surface_points=1_234)
    assert surface_accuracy(surface, dense).points == 1_234
    assert surface_accuracy(surface, dense, n_points=99).points == 99  # an explicit count wins


@pytest.mark.parametrize(
    "value", [0, MIN_SCORE_POINTS - 1, MAX_SCORE_POINTS + 1, True, 5_000.0, "5000", None, float("nan")]
)
def test_bad_counts_are_refused(value: object) -> None:
    with pytest.raises(ValueError, match=r"server\.surface_score_points: an integer in"):
        WorkbenchSettings(surface_score_points=value)  # type: ignore[arg-type]


@pytest.mark.parametrize("value", [0, -5, True, 2.5])
def test_a_truth_refuses_a_bad_count(value: object) -> None:
    box = trimesh.creation.box((0.1, 0.1, 0.1))
    with pytest.raises(ValueError, match="surface_points: a positive integer or None"):
        GroundTruth.of(box, box.sample(100, seed=0), surface_points=value)  # type: ignore[arg-type]
