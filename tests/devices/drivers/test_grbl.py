"""The GRBL turntable driver against a fake firmware on a pseudo terminal, including an alarm and timeouts."""

from __future__ import annotations

import math
import threading
import time

import numpy as np
import pytest

from devices.drivers.grbl import GrblConfig, GrblTurntable
from devices.protocols import DeviceError, Turntable
from devices.timeout import DeviceTimeoutError
from tests.devices.drivers.fake_grbl import FakeGrbl


@pytest.fixture
def grbl():
    with FakeGrbl() as fake:
        yield fake


def table(fake: FakeGrbl, **overrides) -> GrblTurntable:
    return GrblTurntable(GrblConfig(port=fake.port, command_timeout_s=0.5, poll_s=0.01, **overrides))


def test_connects_resets_and_reads_the_angle(grbl):
    with table(grbl) as t:
        assert isinstance(t, Turntable)
        assert t.version == "Grbl 1.1h"
        assert t.angle == 0.0
        assert "Grbl 1.1h on /dev/pts/" in t.describe() and "Idle" in t.describe()


def test_rotate_to_moves_the_axis_and_waits_until_idle(grbl):
    with table(grbl) as t:
        t.rotate_to(math.pi / 2)
        assert grbl.lines[-1] == "G90 G0 X90.0000"
        assert grbl.state == "Idle" and grbl.position == 90.0  # it returned once the plate had arrived
        assert t.angle == pytest.approx(math.pi / 2)


def test_a_continuous_plate_takes_the_short_way_and_a_limited_one_stays_within_180(grbl):
    grbl.position = 170.0
    with table(grbl) as t:
        t.rotate_to(math.radians(-170.0))
        assert grbl.lines[-1] == "G90 G0 X190.0000"  # 20 deg forward, not 340 back
        assert t.angle == pytest.approx(math.radians(-170.0))
    with table(grbl, continuous=False) as t:
        t.rotate_to(math.radians(-170.0))
        assert grbl.lines[-1] == "G90 G0 X-170.0000"
        assert t.angle == pytest.approx(math.radians(-170.0))


def test_units_per_degree_invert_and_zero_offset(grbl):
    with table(grbl, units_per_degree=2.0, invert=True, zero_offset_deg=10.0) as t:
        assert t.angle == pytest.approx(math.radians(10.0))
        t.rotate_to(math.radians(40.0))
        assert grbl.lines[-1] == "G90 G0 X-60.0000"
        assert t.angle == pytest.approx(math.radians(40.0))


def test_an_alarm_during_the_move_is_a_device_error_and_later_moves_are_refused(grbl):
    grbl.alarm_after_s = 0.1
    with table(grbl) as t:
        with pytest.raises(DeviceError, match=r"GRBL alarm during the move \(ALARM:1 hard limit triggered\) at"):
            t.rotate_to(math.pi / 2)
        assert 10.0 < grbl.position < 80.0
        with pytest.raises(DeviceError, match=r"GRBL is in alarm \(ALARM:1 hard limit triggered\); not moving"):
            t.rotate_to(0.0)
        assert grbl.lines[-1] == "G90 G0 X90.0000"  # nothing more was sent


def test_a_firmware_that_stops_answering_is_a_timeout(grbl):
    with table(grbl) as t:
        grbl.silent = True
        with pytest.raises(DeviceTimeoutError, match=r"no answer from GRBL on /dev/pts/\d+ to a status request"):
            t.rotate_to(1.0)


def test_a_move_that_does_not_finish_in_time_is_halted_and_a_timeout():
    with FakeGrbl(rate=20.0) as fake, table(fake, move_timeout_s=0.3) as t:
        with pytest.raises(DeviceTimeoutError, match=r"the move to 90.00 deg did not finish within 0.3 s"):
            t.rotate_to(math.pi / 2)
        time.sleep(0.1)
        assert fake.state == "Idle"  # feed hold, then reset: no alarm, position kept
        assert 3.0 < fake.position < 85.0  # halted on the way (at 20 deg/s: 6 deg after 0.3 s)
        assert t.angle == pytest.approx(math.radians(fake.position), abs=1e-4)


def test_stop_from_another_thread_holds_the_plate_where_it_is():
    with FakeGrbl(rate=45.0) as fake, table(fake) as t:  # 2 s for 90 deg, stopped after 0.2 s
        timer = threading.Timer(0.2, t.stop)
        timer.start()
        with pytest.raises(DeviceError, match=r"turntable: stopped on request at \d+\.\d\d deg"):
            t.rotate_to(math.pi / 2)
        timer.join()
        assert fake.state == "Idle" and 5.0 < fake.position < 80.0
        t.rotate_to(0.0)  # the table works after a stop
        assert fake.position == 0.0


def test_a_firmware_in_alarm_after_reset_is_refused_unless_homed():
    with FakeGrbl(start_in_alarm=True) as fake:
        with pytest.raises(DeviceError, match=r"GRBL is in alarm after reset .*home_on_connect = true"):
            table(fake)
        fake.position = 33.0
        with table(fake, home_on_connect=True) as t:
            assert "$H" in fake.lines
            assert t.angle == 0.0


def test_no_banner_is_a_timeout_and_a_missing_port_a_device_error(grbl, tmp_path):
    grbl.silent = True
    with pytest.raises(DeviceTimeoutError, match=r"to a soft reset \(no Grbl banner\)"):
        table(grbl, startup_s=0.3)
    with pytest.raises(DeviceError, match=r"turntable: cannot open '.*ttyNOPE'"):
        GrblTurntable(GrblConfig(port=str(tmp_path / "ttyNOPE")))


def test_bad_angles_are_value_errors_and_move_nothing(grbl):
    with table(grbl) as t:
        for bad in (float("nan"), "1.0", True):
            with pytest.raises(ValueError, match=r"angle: must be a finite number \(radians\)"):
                t.rotate_to(bad)  # type: ignore[arg-type]
        assert not any(line.startswith("G90") for line in grbl.lines)


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"port": ""}, r"devices.turntable.port: required"),
        ({"axis": "B"}, r"devices.turntable.axis: one of X, Y, Z, A, got 'B'"),
        ({"units_per_degree": 0.0}, r"devices.turntable.units_per_degree: must be > 0"),
        ({"invert": 1}, r"devices.turntable.invert: expected true/false"),
        ({"move_timeout_s": -1.0}, r"devices.turntable.move_timeout_s: must be > 0"),
    ],
)
def test_bad_config_names_the_field(overrides, message):
    with pytest.raises(ValueError, match=message):
        GrblConfig(**{"port": "/dev/ttyUSB0", **overrides})


def test_a_turn_records_the_plate_angle_of_its_own_status_reports(grbl):
    """Move capture's plate history: every status report of the turn, stamped on arrival, the Idle ones holding."""
    with table(grbl) as t:
        before = time.time()
        series = t.record_plate()
        t.rotate_to(math.pi / 2)  # at the fake's 360 deg/s: 0.25 s, polled every 10 ms
        after = time.time()
        t.stop_recording(series)
        count = len(series)
        assert t.angle == pytest.approx(math.pi / 2)
        assert len(series) == count  # not recorded any more
    stamps, values = series.snapshot()
    assert count >= 10 and before <= stamps[0] and stamps[-1] <= after
    assert values[0, 0] == 0.0 and values[-1, 0] == pytest.approx(math.pi / 2)
    assert np.all(np.diff(values[:, 0]) >= 0)  # the plate only turned one way
    middle = (stamps[0] + stamps[-1]) / 2
    value, why = series.at(middle, max_gap_s=0.1)
    assert why == "" and value is not None and 0.0 < value[0] < math.pi / 2
    # the last report was Idle: it holds after the turn
    value, why = series.at(after + 5.0, max_gap_s=0.1)
    assert why == "" and value is not None and value[0] == pytest.approx(math.pi / 2)
