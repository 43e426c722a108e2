"""A device deadline does not count the time a call waited for its turn (a simulated camera's render queued behind
other sessions' jobs on a busy server), but still cuts off a call that hangs once it runs."""

from __future__ import annotations

import time

import pytest

from devices.timeout import DeviceTimeoutError, call_with_timeout


def test_the_wait_for_a_turn_does_not_count_against_the_deadline() -> None:
    start = time.monotonic()

    def queued_then_quick() -> str:
        time.sleep(0.5)  # 0.4 s in a queue, then 0.1 s of the device's own time
        return "frame"

    waited = lambda: min(time.monotonic() - start, 0.4)  # noqa: E731
    assert call_with_timeout(queued_then_quick, 0.3, "camera capture", waited=waited) == "frame"
    with pytest.raises(DeviceTimeoutError, match=r"no answer within 0\.3 s"):  # the same call, the wait counted
        call_with_timeout(queued_then_quick, 0.3, "camera capture")


def test_a_call_that_hangs_after_its_turn_still_times_out() -> None:
    start = time.monotonic()
    waited = lambda: min(time.monotonic() - start, 0.2)  # noqa: E731
    t = time.monotonic()
    with pytest.raises(DeviceTimeoutError):
        call_with_timeout(lambda: time.sleep(3.0), 0.3, "camera capture", waited=waited)
    assert 0.45 <= time.monotonic() - t < 1.5  # the 0.3 s deadline plus the 0.2 s wait
