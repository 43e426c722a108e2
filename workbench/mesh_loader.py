"""Mesh files are read in a child process under a memory and a time limit, so a parser bomb dies there.

trimesh holds the GIL while it parses and flattens a glTF scene before any limit of ours can run, and some
files (an instancing GLB, a PLY whose header claims billions of elements) make it allocate gigabytes from a
few hundred kilobytes. So every mesh file, uploaded or in the models directory, is pre-scanned, loaded,
admitted and checked against the limits in a child (a fork of the worker pool's forkserver, never of the
threaded server) with ``RLIMIT_AS`` set to ``memory`` bytes above its start and killed after ``timeout``
seconds. Only the placed vertices and faces come back. Refusals:

- TooLarge (413): over a mesh limit (the pre-scan or the loaded counts), out of memory, over the time limit;
- Invalid (422): not a usable mesh (workbench/catalog.py adds the model's name);
- Conflict: the create was cancelled (``DELETE /api/creations/ID``): the child is killed at once.
"""

from __future__ import annotations

import contextlib
import resource
import threading
import time
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from workbench.engine import mp_context
from workbench.errors import Conflict, Invalid, TooLarge
from workbench.limits import MeshLimits

POLL = 0.05
"""Seconds between looks at the cancellation while the child works."""


def _vm_bytes() -> int:
    """This process's virtual memory size (what RLIMIT_AS counts), bytes."""
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[0]) * resource.getpagesize()


def _child(conn: Connection, path: str, limits: MeshLimits, up: Any, size: float, what: str, memory: int) -> None:
    """Runs in the child: pre-scan, load, place, admit, check; sends ("ok", vertices, faces) or (kind, message)."""
    from devices.mesh import load_mesh

    with contextlib.suppress(OSError, ValueError):
        limit = _vm_bytes() + memory
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    try:
        limits.check_file(Path(path), what)  # before trimesh spends memory on it
        mesh = load_mesh(path, up=up, size=size)
        limits.check_mesh(mesh.vertices, mesh.faces, what)
        message: tuple[Any, ...] = ("ok", np.asarray(mesh.vertices), np.asarray(mesh.faces))
    except TooLarge as exc:
        message = ("too_large", exc.detail)
    except MemoryError:
        message = ("too_large", f"{what}: reading it needs more than {memory / 1e6:.0f} MB (server.mesh_load_memory)")
    except ValueError as exc:
        message = ("invalid", str(exc))
    except Exception as exc:  # a parser's own error: the file is not a usable mesh
        message = ("invalid", f"{what}: cannot read ({type(exc).__name__}: {exc})"[:300])
    try:
        conn.send(message)
    except MemoryError:
        conn.send(("too_large", f"{what}: reading it needs more than {memory / 1e6:.0f} MB (server.mesh_load_memory)"))
    conn.close()


def load_in_child(
    path: Path,
    limits: MeshLimits,
    *,
    up: Any,
    size: float,
    what: str,
    memory: int,
    timeout: float,
    cancelled: threading.Event | None = None,
) -> trimesh.Trimesh:
    """The placed mesh of the file at ``path``, read in a child process (see the module docstring).

    memory: bytes the child may allocate; timeout: seconds it may take (0: no limit); cancelled: set, the
    child is killed at once and Conflict raised. Messages of Invalid name the file by ``path``."""
    ctx = mp_context()
    receiver, sender = ctx.Pipe(duplex=False)
    child = ctx.Process(
        target=_child, args=(sender, str(path), limits, up, size, what, memory), name="mesh-loader", daemon=True
    )
    child.start()
    sender.close()
    deadline = None if timeout <= 0 else time.monotonic() + timeout
    try:
        while not receiver.poll(POLL):
            if cancelled is not None and cancelled.is_set():
                raise Conflict(f"{what}: the create was cancelled while reading the mesh")
            if deadline is not None and time.monotonic() > deadline:
                raise TooLarge(f"{what}: reading it takes longer than {timeout:g} s (server.mesh_load_timeout)")
            if not child.is_alive() and not receiver.poll(0):
                break
        try:
            message = receiver.recv()
        except EOFError:
            raise TooLarge(
                f"{what}: the mesh reader died (exit {child.exitcode}): out of its {memory / 1e6:.0f} MB "
                "(server.mesh_load_memory)?"
            ) from None
    finally:
        if child.is_alive():
            child.kill()
        child.join(5.0)
        receiver.close()
    kind = message[0]
    if kind == "ok":
        return trimesh.Trimesh(message[1], message[2], process=False)
    if kind == "too_large":
        raise TooLarge(message[1])
    raise Invalid(message[1])
