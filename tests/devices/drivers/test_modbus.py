"""The Modbus RTU turntable driver against a fake drive on a pseudo terminal (real minimalmodbus, real RTU frames)."""

from __future__ import annotations

import math
import threading
import time

import pytest

from devices.drivers.modbus import ModbusTurntable, ModbusTurntableConfig
from devices.protocols import DeviceError, Turntable
from devices.timeout import DeviceTimeoutError
from tests.devices.drivers.fake_modbus import FakeModbusDrive


@pytest.fixture
def drive():
    with FakeModbusDrive() as fake:
        yield fake


def table(fake: FakeModbusDrive, **overrides) -> ModbusTurntable:
    settings = {"port": fake.port, "baudrate": 115200, "poll_s": 0.01, **overrides}
    return ModbusTurntable(ModbusTurntableConfig(**settings))


def test_rotate_to_writes_the_target_and_waits_for_the_drive(drive):
    with table(drive) as t:
        assert isinstance(t, Turntable)
        assert t.angle == 0.0
        t.rotate_to(math.radians(90.0))
        assert drive.target == 9000 and drive.position == 9000 and drive.commands == [1]
        assert t.angle == pytest.approx(math.radians(90.0))
        assert "Modbus drive 1 on /dev/pts/" in t.describe() and "idle" in t.describe()


def test_negative_targets_the_short_way_and_inversion(drive):
    drive.position = 17000  # 170 deg
    with table(drive, invert=True, steps_per_degree=100.0) as t:
        assert t.angle == pytest.approx(math.radians(-170.0))
        t.rotate_to(math.radians(170.0))  # 20 deg the short way: from -170 to -190
        assert drive.target == 19000
        assert t.angle == pytest.approx(math.radians(170.0))
    with table(drive, continuous=False) as t:
        t.rotate_to(math.radians(-150.0))
        assert drive.target == -15000 and drive.position == -15000  # 32-bit signed on the wire


def test_an_alarm_during_the_move_names_the_code_and_blocks_further_moves(drive):
    drive.alarm_after_s = 0.05
    with table(drive) as t:
        with pytest.raises(
            DeviceError, match=r"turntable: drive alarm 21 during the move to 90.00 deg at \d+\.\d\d deg"
        ):
            t.rotate_to(math.radians(90.0))
        assert 0 < drive.position < 9000
        with pytest.raises(DeviceError, match=r"drive alarm 21; clear it on the drive, not moving"):
            t.rotate_to(0.0)
        assert drive.commands == [1]


def test_a_silent_drive_is_a_timeout_and_a_wrong_register_a_device_error(drive):
    with table(drive) as t:
        drive.silent = True
        with pytest.raises(
            DeviceTimeoutError, match=r"no answer from Modbus slave 1 on /dev/pts/\d+ to reading status"
        ):
            t.rotate_to(1.0)
    drive.silent = False
    with pytest.raises(DeviceError, match=r"Modbus error on reading status register 40"):
        table(drive, status_register=40)
    with pytest.raises(DeviceTimeoutError, match=r"no answer from Modbus slave 9"):
        table(drive, slave_address=9)  # nobody answers to that address


def test_a_slow_move_times_out_and_is_stopped():
    with FakeModbusDrive(rate=500.0) as fake, table(fake, move_timeout_s=0.2) as t:
        with pytest.raises(DeviceTimeoutError, match=r"the move to 90.00 deg did not finish within 0.2 s"):
            t.rotate_to(math.radians(90.0))
        assert fake.commands == [1, 2]
        stopped = fake.position
        time.sleep(0.05)
        assert fake.position == stopped < 9000


def test_stop_from_another_thread(drive):
    drive.rate = 4500.0  # 2 s for 90 deg, stopped after 0.2 s
    with table(drive) as t:
        timer = threading.Timer(0.2, t.stop)
        timer.start()
        with pytest.raises(DeviceError, match=r"turntable: stopped on request at \d+\.\d\d deg"):
            t.rotate_to(math.radians(90.0))
        timer.join()
        assert 2 in drive.commands and 0 < drive.position < 9000


def test_homing_on_connect(drive):
    drive.position = 4200
    with table(drive, home_on_connect=True) as t:
        assert drive.commands == [3]
        assert t.angle == 0.0


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"port": ""}, r"devices.turntable.port: required"),
        ({"slave_address": 0}, r"devices.turntable.slave_address: must be an integer in 1..247"),
        ({"parity": "X"}, r"devices.turntable.parity: 'N', 'E' or 'O'"),
        ({"alarm_bit": 16}, r"devices.turntable.alarm_bit: must be a bit number 0..15"),
        ({"status_register": -1}, r"devices.turntable.status_register: must be an integer in 0..65535"),
    ],
)
def test_bad_config_names_the_field(overrides, message):
    with pytest.raises(ValueError, match=message):
        ModbusTurntableConfig(**{"port": "/dev/ttyUSB0", **overrides})
