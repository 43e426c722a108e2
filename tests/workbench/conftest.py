"""A session registry on the simulated cell, without HTTP: the workbench is tested as a library."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.helpers import with_small_costs
from workbench.registry.registry import SessionRegistry
from workbench.settings import WorkbenchSettings


@pytest.fixture
def settings(tmp_path: Path) -> WorkbenchSettings:
    """The API tests' small camera and surface scoring (tests/helpers.py ``with_small_costs``): these tests check
    the session's loop, not the pixels (their three files: 20.8 -> 16.8 CPU-s) nor the scores' values; the surface
    and sensor tests build their own settings."""
    return with_small_costs(WorkbenchSettings(models_dir=tmp_path / "models", data_dir=tmp_path / "data"))


@pytest.fixture
def registry(settings: WorkbenchSettings) -> Iterator[SessionRegistry]:
    registry = SessionRegistry(settings)
    yield registry
    registry.close()
