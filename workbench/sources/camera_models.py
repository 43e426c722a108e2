"""The simulated camera's error models a session may ask for: the depth sensor and the calibration error.

A create request's ``camera`` is ``{"sensor": NAME, "calibration": NAME}`` (either optional); the names are those
of ``devices.sensors.SENSORS`` and ``devices.calibration_error.CALIBRATIONS`` (docs/experiments/sensors.md, "Sensor models").
They go into the session's ``devices.camera``; a hardware session refuses them (a real camera has its own noise).
"""

from __future__ import annotations

from typing import Any

from devices.calibration_error import CALIBRATIONS
from devices.sensors.presets import SENSORS
from workbench.errors import Invalid

CAMERA_FIELDS = ("sensor", "calibration")


def camera_models() -> dict[str, list[str]]:
    """``{"sensors": [...], "calibrations": [...]}``: the names a request may give (the first is the default)."""
    return {"sensors": list(SENSORS), "calibrations": list(CALIBRATIONS)}


def check_camera_models(camera: dict[str, Any] | None) -> dict[str, str] | None:
    """The request's ``camera`` checked: only ``sensor`` and ``calibration``, each a known name (Invalid listing
    the names otherwise); None when nothing was asked."""
    if camera is None:
        return None
    if not isinstance(camera, dict):
        raise Invalid(f"camera: expected an object with 'sensor' and/or 'calibration', got {type(camera).__name__}")
    extra = sorted(set(camera) - set(CAMERA_FIELDS))
    if extra:
        raise Invalid(f"camera: unknown field(s) {', '.join(extra)} (known: {', '.join(CAMERA_FIELDS)})")
    known = {"sensor": SENSORS, "calibration": CALIBRATIONS}
    out: dict[str, str] = {}
    for name in CAMERA_FIELDS:
        value = camera.get(name)
        if value is None:
            continue
        if not isinstance(value, str) or value not in known[name]:
            raise Invalid(f"camera.{name}: unknown {name} {value!r}; known: {', '.join(known[name])}")
        out[name] = value
    return out or None
