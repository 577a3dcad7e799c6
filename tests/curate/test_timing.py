"""StepClock: nested steps charge every CPU second to exactly one step, and a step left by an
exception is closed (the per-log stage raises DrivewmError from inside its steps)."""

import time

import pytest

from drivewm.curate.timing import StepClock


def _spin(seconds: float) -> None:
    end = time.process_time() + seconds
    while time.process_time() < end:
        pass


def test_nested_steps_split_the_cpu_and_exceptions_close_the_step():
    start = time.process_time()
    clock = StepClock()
    with clock.step("index"):
        _spin(0.03)
        with clock.step("decode"):
            _spin(0.05)
    with pytest.raises(ValueError):
        with clock.step("encode"):
            _spin(0.02)
            raise ValueError("bad frame")
    _spin(0.01)  # outside every step: "other"
    totals = clock.totals()
    assert not clock._stack
    assert totals["decode"] == pytest.approx(0.05, abs=0.005)
    assert totals["index"] == pytest.approx(0.03, abs=0.005)  # its inner step's CPU is not counted twice
    assert totals["encode"] == pytest.approx(0.02, abs=0.005)
    assert sum(totals.values()) == pytest.approx(time.process_time() - start, abs=0.004)
