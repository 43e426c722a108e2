"""A session registry on the simulated cell, without HTTP: the workbench is tested as a library."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from workbench.registry.registry import SessionRegistry
from workbench.settings import WorkbenchSettings


@pytest.fixture
def settings(tmp_path: Path) -> WorkbenchSettings:
    return WorkbenchSettings(models_dir=tmp_path / "models", data_dir=tmp_path / "data")


@pytest.fixture
def registry(settings: WorkbenchSettings) -> Iterator[SessionRegistry]:
    registry = SessionRegistry(settings)
    yield registry
    registry.close()
