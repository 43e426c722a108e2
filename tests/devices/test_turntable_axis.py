"""The turntable axis of a cell file (``[devices.turntable_axis]``, written by a calibration): read, checked, and
used to place a real cell's frames (``T_table_base``: a rotation about the measured axis)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from devices.cell import rz
from devices.cellfile import T_table_base, parse_cell


def _cell(axis: str) -> dict:
    import tomllib

    return tomllib.loads(f"[devices]\n[devices.turntable_axis]\n{axis}\n")


def test_the_axis_is_read_as_a_unit_vector_and_defaults_to_the_vertical() -> None:
    cell = parse_cell(_cell("direction = [0.003, -0.002, 2.0]"))
    assert np.allclose(cell.turntable_axis, np.array([0.003, -0.002, 2.0]) / np.linalg.norm([0.003, -0.002, 2.0]))
    assert parse_cell({"devices": {}}).turntable_axis == (0.0, 0.0, 1.0)


@pytest.mark.parametrize(
    ("axis", "message"),
    [
        ("direction = [0.2, 0.0, 1.0]", "tilted 11.31 deg from the vertical"),
        ("direction = [0.0, 0.0, 0.0]", "must not be zero"),
        ("direction = [0.0, 1.0]", "must be 3 finite numbers"),
        ("point = [0.0, 0.0]", "only direction"),
    ],
)
def test_a_bad_axis_is_refused_naming_the_field(axis: str, message: str) -> None:
    with pytest.raises(ValueError, match=r"devices\.turntable_axis") as info:
        parse_cell(_cell(axis))
    assert message in str(info.value)


def test_frames_turn_about_the_measured_axis() -> None:
    theta = math.radians(70.0)
    assert np.allclose(T_table_base(theta).matrix, rz(-theta).matrix)  # vertical: the cell model's Rz(-theta)
    tilt = np.array([math.sin(math.radians(0.3)), 0.0, math.cos(math.radians(0.3))])
    T = T_table_base(theta, tilt)
    assert np.allclose(T.rotation @ tilt, tilt)  # points on the axis stay
    angle = Rotation.from_matrix(T.rotation).magnitude()
    assert math.isclose(angle, theta, rel_tol=1e-9)
    # against the vertical model, a point 15 cm off the axis at 10 cm height moves by about tilt x reach
    p = np.array([0.15, 0.0, 0.10])
    moved = float(np.linalg.norm(T.rotation @ p - rz(-theta).rotation @ p))
    assert 0.0002 < moved < 0.002
