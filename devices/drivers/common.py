"""What every hardware driver shares: lazy vendor imports and the arm-fault error.

A driver module imports its vendor package (``pyrealsense2``, ``rtde_control``, ``serial``, ...) only
when a device is opened, through :func:`import_vendor`, so ``import devices.drivers.ur`` works on a
machine without ``ur-rtde`` and a missing package is one clear error naming the extra to install.
"""

from __future__ import annotations

import importlib
from types import ModuleType

import numpy as np
from numpy.typing import ArrayLike, NDArray

from devices.protocols import DeviceError


class MissingVendorPackageError(DeviceError):
    """A driver's vendor package is not installed (the message names the pip extra that installs it)."""


class ArmFaultError(DeviceError):
    """The arm stopped on a fault: the controller's reason and the last joint state it reported.

    reason: the controller's words (``protective stop``, ``emergency stop``, ``lost connection``, ...).
    joint_positions: (n,) float64 the last joint configuration read from the controller, radians
    (None when none was ever read).
    """

    def __init__(self, reason: str, joint_positions: ArrayLike | None, detail: str = "") -> None:
        self.reason = reason
        self.joint_positions: NDArray[np.float64] | None = (
            None if joint_positions is None else np.asarray(joint_positions, dtype=np.float64).copy()
        )
        where = (
            "no joint state read"
            if self.joint_positions is None
            else "last joints [" + ", ".join(f"{q:.4f}" for q in self.joint_positions) + "] rad"
        )
        super().__init__(f"arm: {reason}{f' ({detail})' if detail else ''}; {where}")


def import_vendor(module: str, extra: str, what: str) -> ModuleType:
    """``import module``, or MissingVendorPackageError telling how to install it.

    module: the vendor's import name (``pyrealsense2``). extra: the project's pip extra that installs it
    (``realsense``). what: the device, for the message (``RealSense camera``).
    """
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise MissingVendorPackageError(
            f"{what}: the Python package {module!r} is not installed ({exc}); "
            f"install it with: pip install -e '.[{extra}]' (or '.[hardware]' for every driver)"
        ) from None
