"""Calibration and motion error of a simulated cell: where the camera really is when the kinematics say it is
somewhere else.

A lab calibrates its hand-eye transform (``T_flange_camera``) and its turntable axis, and its arm repeats a pose
only to a fraction of a millimetre. A :class:`CalibrationModel` (``none``, ``typical``, ``poor``) gives the size of
each error; :class:`CellErrors` draws one cell's errors from a seed:

- a bias fixed for the session: a hand-eye error ``E`` (``T_flange_camera_true = T_flange_camera @ E``) and the
  turntable's true axis (offset in x, y and tilted; the true plate turn is about it);
- per-move noise: the arm's repeatability (a small camera-frame displacement) and the turntable's angle error,
  drawn from the seed and the configuration reached, so the same move lands the same way (a resumed session too).

The reported pose is the nominal kinematics, ``Rz(-theta) @ T_base_camera``; the camera renders from
:meth:`CellErrors.true_T_table_camera`. Sources of the figures: docs/experiments/sensors.md ("Calibration and motion error").
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from planner.types import Pose
from planner.validate import finite, require


@dataclass(frozen=True)
class CalibrationModel:
    """Standard deviations of a cell's errors (per axis / per rotation-vector component). Metres and degrees."""

    name: str
    hand_eye_translation: float = 0.0
    """Bias: error of the calibrated ``T_flange_camera`` position, metres."""
    hand_eye_rotation_deg: float = 0.0
    """Bias: error of its orientation, degrees."""
    axis_offset: float = 0.0
    """Bias: the turntable's true axis is this far (x and y each) from the nominal one, metres."""
    axis_tilt_deg: float = 0.0
    """Bias: the true axis is tilted from vertical by this (about x and y each), degrees."""
    turntable_angle_deg: float = 0.0
    """Per move: error of the plate angle reached, degrees."""
    arm_translation: float = 0.0
    """Per move: the arm's repeatability, position, metres."""
    arm_rotation_deg: float = 0.0
    """Per move: the arm's repeatability, orientation, degrees."""

    def __post_init__(self) -> None:
        for field in (
            "hand_eye_translation",
            "hand_eye_rotation_deg",
            "axis_offset",
            "axis_tilt_deg",
            "turntable_angle_deg",
            "arm_translation",
            "arm_rotation_deg",
        ):
            v = getattr(self, field)
            require(finite(v) and v >= 0, f"calibration.{field}: must be >= 0, got {v!r}")

    @property
    def is_exact(self) -> bool:
        return self == CalibrationModel(self.name)


CALIBRATIONS: dict[str, CalibrationModel] = {
    "none": CalibrationModel("none"),
    # After a lab's calibration: hand-eye ~1 mm / 0.2 deg, turntable axis found to 0.5 mm / 0.05 deg, a stepper
    # turntable to 0.02 deg, UR5 repeatability +-0.1 mm (taken as 3 sigma).
    "typical": CalibrationModel(
        "typical",
        hand_eye_translation=0.001,
        hand_eye_rotation_deg=0.2,
        axis_offset=0.0005,
        axis_tilt_deg=0.05,
        turntable_angle_deg=0.02,
        arm_translation=0.0001 / 3,
        arm_rotation_deg=0.003,
    ),
    # A rough calibration (a hand-measured mount, an axis taken from the drawing, a worn arm).
    "poor": CalibrationModel(
        "poor",
        hand_eye_translation=0.004,
        hand_eye_rotation_deg=0.8,
        axis_offset=0.002,
        axis_tilt_deg=0.3,
        turntable_angle_deg=0.1,
        arm_translation=0.0003,
        arm_rotation_deg=0.01,
    ),
}
"""Every named calibration preset."""


def calibration_named(name: str) -> CalibrationModel:
    """The preset called ``name``; ValueError listing the names for an unknown one."""
    try:
        return CALIBRATIONS[name]
    except (KeyError, TypeError):
        raise ValueError(f"calibration: unknown calibration {name!r}; known: {', '.join(CALIBRATIONS)}") from None


def _small(rng: np.random.Generator, translation: float, rotation_deg: float) -> Pose:
    t = rng.normal(0.0, translation, 3) if translation > 0 else np.zeros(3)
    r = rng.normal(0.0, math.radians(rotation_deg), 3) if rotation_deg > 0 else np.zeros(3)
    return Pose(Rotation.from_rotvec(r).as_matrix(), t)


def _rz(theta: float) -> Pose:
    c, s = math.cos(theta), math.sin(theta)
    return Pose(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), np.zeros(3))


class CellErrors:
    """One cell's calibration and motion errors, drawn from ``seed`` (model: the sizes)."""

    def __init__(self, model: CalibrationModel, seed: int = 0) -> None:
        self.model = model
        self._seed = int(seed)
        rng = np.random.default_rng([self._seed, 0])
        self.E_hand_eye: Pose = _small(rng, model.hand_eye_translation, model.hand_eye_rotation_deg)
        """Bias: ``T_flange_camera_true = T_flange_camera_nominal @ E_hand_eye`` (camera frame)."""
        offset = rng.normal(0.0, model.axis_offset, 2) if model.axis_offset > 0 else np.zeros(2)
        tilt = rng.normal(0.0, math.radians(model.axis_tilt_deg), 2) if model.axis_tilt_deg > 0 else np.zeros(2)
        self.T_base_axis: Pose = Pose(
            Rotation.from_rotvec([tilt[0], tilt[1], 0.0]).as_matrix(), np.array([offset[0], offset[1], 0.0])
        )
        """Bias: the true turntable axis frame in the base frame (its z is the axis; nominal: identity)."""

    def T_flange_camera_true(self, T_flange_camera_nominal: Pose) -> Pose:
        """The true hand-eye transform for a nominal one (for a calibration routine to check its result)."""
        return T_flange_camera_nominal @ self.E_hand_eye

    def T_base_table_true(self, angle: float, key: bytes = b"") -> Pose:
        """The true plate pose at nominal ``angle`` (rad): a turn about the true axis, by the angle plus its error."""
        delta = 0.0
        if self.model.turntable_angle_deg > 0:
            delta = float(self._move_rng(b"table" + key).normal(0.0, math.radians(self.model.turntable_angle_deg)))
        return self.T_base_axis @ _rz(angle + delta) @ self.T_base_axis.inverse()

    def true_T_table_camera(self, T_base_camera_nominal: Pose, angle: float, key: bytes) -> Pose:
        """The pose the camera really has, in the (true) table frame, when the kinematics report
        ``T_base_camera_nominal`` at plate ``angle``. key: the configuration reached (e.g. the joints' bytes): the
        per-move noise is a function of the seed and the key."""
        repeat = _small(self._move_rng(b"arm" + key), self.model.arm_translation, self.model.arm_rotation_deg)
        T_base_camera = T_base_camera_nominal @ repeat @ self.E_hand_eye
        return self.T_base_table_true(angle, key + np.float64(angle).tobytes()).inverse() @ T_base_camera

    def _move_rng(self, key: bytes) -> np.random.Generator:
        return np.random.default_rng([self._seed, 1, zlib.crc32(key)])

    def summary(self) -> dict[str, object]:
        """The drawn bias, JSON-ready: hand-eye error (mm, deg), axis offset (mm) and tilt (deg)."""
        rot = Rotation.from_matrix(self.E_hand_eye.rotation).magnitude()
        tilt = Rotation.from_matrix(self.T_base_axis.rotation).magnitude()
        return {
            "calibration": self.model.name,
            "hand_eye_mm": float(np.linalg.norm(self.E_hand_eye.translation) * 1000),
            "hand_eye_deg": math.degrees(rot),
            "axis_offset_mm": float(np.linalg.norm(self.T_base_axis.translation) * 1000),
            "axis_tilt_deg": math.degrees(tilt),
        }


def configuration_key(q: NDArray[np.float64] | None, pose: Pose) -> bytes:
    """The bytes that name a configuration reached: the joints (rounded to 1e-9 rad) or, without joints, the pose."""
    if q is not None:
        return np.round(np.asarray(q, dtype=np.float64), 9).tobytes()
    return np.round(pose.matrix, 9).tobytes()
