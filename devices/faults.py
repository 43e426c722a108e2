"""Fault injection: wrappers that make any camera, arm or turntable fail on a schedule or at random.

``with_faults(cell, FaultInjector(config))`` wraps the cell's devices. Each device
action asks the injector whether to fail; the injector counts actions per device
(so a schedule can say "fail the 3rd capture"), draws from its own seeded RNG for
the probabilities, and serves faults queued with :meth:`FaultInjector.inject`
(the test-only REST route) first. The kinds:

=================  =========  =====================================================
kind               device     what happens
=================  =========  =====================================================
camera_timeout     camera     the capture hangs for ``hang_seconds`` (the caller's
                              capture timeout must fire), then raises CaptureError
capture_failure    camera     CaptureError at once, no image
nan_frame          camera     the image has NaN depths: building its DepthFrame
                              raises ValueError (what a validating driver does)
empty_frame        camera     an image with no return at all (all zeros)
arm_halfway        arm        the arm stops halfway (a joint arm: half-way through its
                              trajectory; a pose arm: pose interpolated between the
                              current and the target pose) and raises DeviceError
turntable_error    turntable  DeviceError before the plate moves
move_refused       arm        UnreachableError (reason ``refused``) before the arm
                              moves: a move the cell refuses at move time
=================  =========  =====================================================

``Cell.move_to`` turns the plate before moving the arm, so ``arm_halfway`` also
covers "the turntable rotated but the arm failed".
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import Any, Literal, get_args

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from devices.cell import Cell
from devices.protocols import Arm, Camera, CaptureError, DeviceError, JointArm, Turntable, UnreachableError
from devices.trajectory import JointTrajectory
from planner.types import DepthFrame, Intrinsics, Pose
from planner.validate import finite, integer

FaultKind = Literal[
    "camera_timeout", "capture_failure", "nan_frame", "empty_frame", "arm_halfway", "turntable_error", "move_refused"
]
FAULT_KINDS: tuple[str, ...] = get_args(FaultKind)
DEVICE_OF: dict[str, str] = {
    "camera_timeout": "camera",
    "capture_failure": "camera",
    "nan_frame": "camera",
    "empty_frame": "camera",
    "arm_halfway": "arm",
    "turntable_error": "turntable",
    "move_refused": "arm",
}


@dataclass(frozen=True)
class ScheduledFault:
    """Fail the ``at``-th action (1-based) of the fault's device with ``kind``."""

    kind: FaultKind
    at: int

    def __post_init__(self) -> None:
        if self.kind not in FAULT_KINDS:
            raise ValueError(f"faults.schedule.kind: one of {', '.join(FAULT_KINDS)}, got {self.kind!r}")
        if not integer(self.at) or self.at < 1:
            raise ValueError(f"faults.schedule.at: an integer >= 1 (the n-th action of the device), got {self.at!r}")


@dataclass(frozen=True)
class FaultConfig:
    """Which faults the simulated devices inject. Probabilities are per action of the fault's device."""

    camera_timeout: float = 0.0
    """Probability that a capture hangs (the workbench's capture timeout ends it)."""
    capture_failure: float = 0.0
    """Probability that a capture fails with no image."""
    nan_frame: float = 0.0
    """Probability that a capture delivers NaN depths."""
    empty_frame: float = 0.0
    """Probability that a capture delivers an image with no return."""
    arm_halfway: float = 0.0
    """Probability that an arm move stops halfway with an error."""
    turntable_error: float = 0.0
    """Probability that a turntable rotation fails before moving."""
    move_refused: float = 0.0
    """Probability that the arm refuses a move before it starts (UnreachableError, reason ``refused``)."""
    schedule: tuple[ScheduledFault, ...] = ()
    """Deterministic faults, e.g. ``[{"kind": "capture_failure", "at": 3}]``: the 3rd capture fails."""
    seed: int = 0
    """Seeds the random draws (independent of the session seed)."""
    hang_seconds: float = 3600.0
    """How long a ``camera_timeout`` hangs the camera (it is released early when the session closes)."""

    def __post_init__(self) -> None:
        for kind in FAULT_KINDS:
            p = getattr(self, kind)
            if not (finite(p) and 0.0 <= p <= 1.0):
                raise ValueError(f"faults.{kind}: a probability in [0, 1], got {p!r}")
        if not integer(self.seed) or not 0 <= self.seed < 2**32:
            raise ValueError(f"faults.seed: an integer in [0, 2^32), got {self.seed!r}")
        h = self.hang_seconds
        if not (finite(h) and 0 < h <= 86400):
            raise ValueError(f"faults.hang_seconds: in (0, 86400], got {h!r}")
        object.__setattr__(self, "schedule", tuple(self.schedule))

    @property
    def enabled(self) -> bool:
        return bool(self.schedule) or any(getattr(self, k) > 0 for k in FAULT_KINDS)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {k: float(getattr(self, k)) for k in FAULT_KINDS}
        out["schedule"] = [{"kind": s.kind, "at": s.at} for s in self.schedule]
        out["seed"] = self.seed
        out["hang_seconds"] = float(self.hang_seconds)
        return out

    @staticmethod
    def from_dict(data: dict[str, Any] | None) -> FaultConfig:
        """From ``{"capture_failure": 0.1, "schedule": [{"kind": ..., "at": 3}], ...}``; ValueError names the field."""
        if data is None:
            return FaultConfig()
        if not isinstance(data, dict):
            raise ValueError(f"faults: expected a table/object, got {type(data).__name__}")
        known = {*FAULT_KINDS, "schedule", "seed", "hang_seconds"}
        unknown = set(data) - known
        if unknown:
            raise ValueError(f"faults: unknown setting(s) {sorted(unknown)} (known: {', '.join(sorted(known))})")
        values = dict(data)
        schedule = values.pop("schedule", ())
        if not isinstance(schedule, list | tuple):
            raise ValueError("faults.schedule: a list of {kind, at}")
        items = []
        for item in schedule:
            if not isinstance(item, dict) or set(item) != {"kind", "at"}:
                raise ValueError(f"faults.schedule: each entry is {{kind, at}}, got {item!r}")
            items.append(ScheduledFault(item["kind"], item["at"]))
        try:
            return FaultConfig(**values, schedule=tuple(items))
        except TypeError as exc:
            raise ValueError(f"faults: {exc}") from None


@dataclass
class FaultInjector:
    """Decides, per device action, whether it fails. Thread-safe; ``fired`` lists what was injected."""

    config: FaultConfig = field(default_factory=FaultConfig)
    counts: dict[str, int] = field(default_factory=lambda: {"camera": 0, "arm": 0, "turntable": 0})
    fired: list[dict[str, Any]] = field(default_factory=list)

    def __post_init__(self) -> None:
        self._lock = threading.Lock()
        self._rng = np.random.default_rng(self.config.seed)
        self._queued: list[str] = []
        self.released = threading.Event()

    def inject(self, kind: str) -> None:
        """Make the next action of ``kind``'s device fail with ``kind``."""
        if kind not in FAULT_KINDS:
            raise ValueError(f"fault kind: one of {', '.join(FAULT_KINDS)}, got {kind!r}")
        with self._lock:
            self._queued.append(kind)

    def draw(self, device: str) -> str | None:
        """Count one action of ``device`` and return the fault it suffers, if any."""
        with self._lock:
            self.counts[device] += 1
            n = self.counts[device]
            kind = next((k for k in self._queued if DEVICE_OF[k] == device), None)
            if kind is not None:
                self._queued.remove(kind)
            else:
                kind = next((s.kind for s in self.config.schedule if s.at == n and DEVICE_OF[s.kind] == device), None)
            if kind is None:
                for k in FAULT_KINDS:
                    p = getattr(self.config, k)
                    if DEVICE_OF[k] == device and p > 0 and self._rng.random() < p:
                        kind = k
                        break
            if kind is not None:
                self.fired.append({"device": device, "action": n, "kind": kind})
            return kind

    def release(self) -> None:
        """End every hanging capture now (the session is closing)."""
        self.released.set()


class _Wrapper:
    """Forwards what it does not define (counters, ``fail_next``) to the wrapped device."""

    inner: Any

    @property
    def fail_next(self) -> Exception | None:
        return getattr(self.inner, "fail_next", None)

    @fail_next.setter
    def fail_next(self, exc: Exception | None) -> None:
        self.inner.fail_next = exc

    def __getattr__(self, name: str) -> Any:  # only called for names not found on the wrapper
        if name == "inner":
            raise AttributeError(name)
        return getattr(self.inner, name)


class FaultyCamera(_Wrapper):
    """A camera that fails when its injector says so; otherwise the wrapped camera's image."""

    def __init__(self, inner: Camera, injector: FaultInjector) -> None:
        self.inner = inner
        self.injector = injector

    @property
    def intrinsics(self) -> Intrinsics:
        return self.inner.intrinsics

    def capture(self) -> DepthFrame:
        kind = self.injector.draw("camera")
        if kind == "camera_timeout":
            self.injector.released.wait(self.injector.config.hang_seconds)
            raise CaptureError("camera: no image (simulated hang)")
        if kind == "capture_failure":
            raise CaptureError("camera: capture failed (simulated fault)")
        frame = self.inner.capture()
        if kind == "nan_frame":
            depth = np.array(frame.depth, dtype=np.float32)
            depth[::7, ::5] = np.nan
            return DepthFrame(depth, frame.T_world_camera, frame.intrinsics)  # raises: depth is not finite
        if kind == "empty_frame":
            return DepthFrame(np.zeros_like(frame.depth), frame.T_world_camera, frame.intrinsics)
        return frame


def interpolate(a: Pose, b: Pose, t: float) -> Pose:
    """The pose ``t`` of the way from ``a`` to ``b`` (translation linear, rotation slerp)."""
    rotations = Rotation.from_matrix(np.stack([a.rotation, b.rotation]))
    R = Slerp([0.0, 1.0], rotations)([t]).as_matrix()[0]
    return Pose(R, (1.0 - t) * a.translation + t * b.translation)


class FaultyArm(_Wrapper):
    """An arm (pose arm or joint arm) that may stop halfway to its target (and then raises DeviceError)."""

    def __init__(self, inner: Arm | JointArm, injector: FaultInjector) -> None:
        self.inner = inner
        self.injector = injector

    @property
    def pose(self) -> Pose:
        return self.inner.pose

    def move_to(self, T_base_camera: Pose) -> None:
        kind = self.injector.draw("arm")
        _refuse(kind)
        if kind == "arm_halfway":
            self.inner.move_to(interpolate(self.inner.pose, T_base_camera, 0.5))
            raise DeviceError("arm: stopped halfway to the target (simulated fault); the camera is between poses")
        self.inner.move_to(T_base_camera)

    def execute(self, trajectory: JointTrajectory) -> None:
        kind = self.injector.draw("arm")
        _refuse(kind)
        if kind == "arm_halfway":
            self.inner.execute(trajectory.truncated(0.5 * trajectory.duration))
            raise DeviceError(
                "arm: stopped halfway through its trajectory (simulated fault); the arm is between configurations"
            )
        self.inner.execute(trajectory)


def _refuse(kind: str | None) -> None:
    if kind == "move_refused":
        raise UnreachableError("arm: the move was refused (simulated fault); the arm did not move", "refused")


class FaultyTurntable(_Wrapper):
    """A turntable whose drive may fault before it moves."""

    def __init__(self, inner: Turntable, injector: FaultInjector) -> None:
        self.inner = inner
        self.injector = injector

    @property
    def angle(self) -> float:
        return self.inner.angle

    def rotate_to(self, angle: float) -> None:
        if self.injector.draw("turntable") == "turntable_error":
            raise DeviceError("turntable: drive fault (simulated); the plate did not move")
        self.inner.rotate_to(angle)


def with_faults(cell: Cell, injector: FaultInjector) -> Cell:
    """Wrap ``cell``'s devices (in place) so ``injector`` decides their faults; returns the cell."""
    cell.camera = FaultyCamera(cell.camera, injector)
    cell.arm = FaultyArm(cell.arm, injector)
    cell.turntable = FaultyTurntable(cell.turntable, injector)
    return cell
