"""The objects a session can scan: built-ins, files in the models directory, and uploads.

A request names a model; it never names a path. Names are looked up in the
catalogue (built-in names, file names directly inside ``models_dir``, and
``uploads/<file>`` directly inside ``data_dir/uploads``), so no request can reach
a file outside those two directories.
"""

from __future__ import annotations

import hashlib
import os
import re
import tempfile
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import trimesh

from workbench.errors import Invalid, NotFound, TooLarge
from workbench.settings import WorkbenchSettings

ModelKind = Literal["builtin", "file", "upload"]
UPLOAD_PREFIX = "uploads/"


@dataclass(frozen=True)
class ModelInfo:
    """One entry of the catalogue. ``path`` is None for built-ins."""

    name: str
    kind: ModelKind
    description: str
    path: Path | None = None

    def to_json(self) -> dict[str, Any]:
        return {"name": self.name, "kind": self.kind, "description": self.description}


def _suffixes() -> tuple[str, ...]:
    from devices.mesh import SUPPORTED_SUFFIXES

    return tuple(SUPPORTED_SUFFIXES)


def _files(directory: Path) -> list[Path]:
    """Mesh files directly in ``directory``; a symlink counts only when it resolves inside ``directory``."""
    if not directory.is_dir():
        return []
    suffixes = _suffixes()
    root = directory.resolve()
    return sorted(
        p
        for p in directory.iterdir()
        if p.is_file()
        and not p.name.startswith(".")
        and p.suffix.lower() in suffixes
        and p.resolve().is_relative_to(root)
    )


def upload_dir(settings: WorkbenchSettings) -> Path:
    return settings.data_dir / "uploads"


def list_models(settings: WorkbenchSettings) -> list[ModelInfo]:
    """Built-ins first, then the models directory, then uploads."""
    from devices.builtins import BUILTIN_OBJECTS

    models = [ModelInfo(name, "builtin", text) for name, text in BUILTIN_OBJECTS.items()]
    default = settings.devices.model  # `nbv serve --model some/file.obj`: the operator's choice, offered too
    if default not in BUILTIN_OBJECTS and Path(default).is_file() and Path(default).suffix.lower() in _suffixes():
        models.append(ModelInfo(default, "file", f"{Path(default).name} (the server's default model)", Path(default)))
    models += [ModelInfo(p.name, "file", f"{p.name} in {settings.models_dir}", p) for p in _files(settings.models_dir)]
    models += [
        ModelInfo(UPLOAD_PREFIX + p.name, "upload", f"uploaded {p.name}", p) for p in _files(upload_dir(settings))
    ]
    return models


def find_model(settings: WorkbenchSettings, name: str) -> ModelInfo:
    """The catalogue entry called ``name``; NotFound lists what exists."""
    models = list_models(settings)
    for info in models:
        if info.name == name:
            return info
    known = ", ".join(m.name for m in models)
    raise NotFound(f"model {name!r}: unknown (known: {known})")


def load_model(
    settings: WorkbenchSettings, name: str, stage: Callable[[str], None] = lambda name: None
) -> trimesh.Trimesh:
    """The placed mesh (on the plate, scaled to ``devices.size``) of model ``name``.

    NotFound for an unknown name, Invalid for a file that is not a usable mesh. stage: told each stage as it
    starts (checking the file, reading the mesh, checking the mesh); it may raise to cancel.
    """
    from devices.builtins import make_builtin

    info = find_model(settings, name)
    size = settings.devices.size
    if info.kind == "builtin":
        try:
            return make_builtin(info.name, size)
        except ValueError as exc:
            raise Invalid(f"model {name!r}: {exc}") from None
    assert info.path is not None
    stage("checking the file")
    stage("reading the mesh")
    creation = getattr(stage, "__self__", None)  # a create's stage: its Cancel kills the reader at once
    mesh = read_mesh(settings, info.path, f"model {name!r}", getattr(creation, "cancelled", None))
    stage("checking the mesh")
    return mesh


def read_mesh(
    settings: WorkbenchSettings, path: Path, what: str, cancelled: threading.Event | None = None
) -> trimesh.Trimesh:
    """The placed mesh of a file, pre-scanned, read, admitted and checked in a child process under the settings'
    memory and time limits (workbench/sources/mesh_loader.py). TooLarge, Invalid (naming ``what``), Conflict."""
    from workbench.sources.mesh_loader import load_in_child

    try:
        return load_in_child(
            path,
            settings.mesh_limits,
            up=settings.devices.up,
            size=settings.devices.size,
            what=what,
            memory=settings.mesh_load_memory,
            timeout=settings.mesh_load_timeout,
            cancelled=cancelled,
        )
    except Invalid as exc:
        detail = exc.detail if exc.detail.startswith(what) else f"{what}: {exc.detail}"
        raise Invalid(detail.replace(str(path), "file")) from None


_SAFE = re.compile(r"[^A-Za-z0-9_.-]+")


def save_upload(settings: WorkbenchSettings, filename: str, data: bytes) -> ModelInfo:
    """Store an uploaded mesh under ``data_dir/uploads`` after checking it loads.

    The stored name is the sanitised stem plus a content hash, so two uploads
    never overwrite each other and the name carries no path. TooLarge over
    ``max_upload_bytes`` or beyond ``settings.mesh_limits`` (triangles, vertices,
    polygon degree, triangles per vertex: workbench/sources/limits.py); Invalid for an
    unsupported or unusable file (nothing is kept then).
    """
    if len(data) > settings.max_upload_bytes:
        raise TooLarge(f"upload: {len(data)} bytes is over the limit of {settings.max_upload_bytes} bytes")
    if not data:
        raise Invalid("upload: empty file")
    suffix = Path(filename).suffix.lower()
    if suffix not in _suffixes():
        raise Invalid(f"upload: unsupported file type {suffix or '(none)'!r} (supported: {', '.join(_suffixes())})")
    stem = _SAFE.sub("_", Path(filename).stem)[:40].strip("._") or "mesh"
    digest = hashlib.sha256(data).hexdigest()[:10]
    directory = upload_dir(settings)
    directory.mkdir(parents=True, exist_ok=True)
    final = directory / f"{stem}-{digest}{suffix}"
    info = ModelInfo(UPLOAD_PREFIX + final.name, "upload", f"uploaded {filename}", final)
    if final.is_file():  # the same bytes under the same name were admitted already (the name is content-addressed)
        return info
    # a temporary file of this upload's own: identical uploads at the same moment never share one
    fd, name = tempfile.mkstemp(prefix=f".{stem}-{digest}.", suffix=f".part{suffix}", dir=directory)
    tmp = Path(name)
    try:
        with os.fdopen(fd, "wb") as out:
            out.write(data)
        read_mesh(settings, tmp, f"upload {filename!r}")  # a bomb dies in the reader's process, not here
        tmp.replace(final)  # atomic: a concurrent identical upload replaces it with the same bytes
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return info
