"""Lazy vendor imports and the arm-fault error."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from devices.drivers.common import ArmFaultError, MissingVendorPackageError, import_vendor
from devices.protocols import DeviceError


def test_a_missing_vendor_package_names_the_extra_to_install():
    with pytest.raises(MissingVendorPackageError, match=r"UR arm: the Python package 'no_such_rtde' is not installed"):
        import_vendor("no_such_rtde", "ur", "UR arm")
    with pytest.raises(DeviceError, match=r"pip install -e '\.\[ur\]' \(or '\.\[hardware\]' for every driver\)"):
        import_vendor("no_such_rtde", "ur", "UR arm")


def test_importing_the_drivers_imports_no_vendor_package():
    code = (
        "import sys, devices.drivers.realsense, devices.drivers.ur, devices.drivers.grbl, devices.drivers.modbus, "
        "devices.drivers.rsrecord, devices.rig, "
        "devices.cellfile; "
        "print(sorted(m for m in ('pyrealsense2', 'rtde_control', 'rtde_receive', 'serial', 'minimalmodbus') "
        "if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    assert out.stdout.strip() == "[]"


def test_arm_fault_error_keeps_the_reason_and_the_last_joints():
    err = ArmFaultError("protective stop", [0.1, -1.2], "during the motion")
    assert err.reason == "protective stop"
    assert err.joint_positions is not None and np.allclose(err.joint_positions, [0.1, -1.2])
    assert str(err) == "arm: protective stop (during the motion); last joints [0.1000, -1.2000] rad"
    assert str(ArmFaultError("lost connection", None)) == "arm: lost connection; no joint state read"
