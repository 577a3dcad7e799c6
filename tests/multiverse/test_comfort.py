"""Comfort scores read a path's own jerk and lateral acceleration, not the noise of differencing it: a
10 Hz path with known derivatives, and one whose acceleration steps as a driver model's commands do."""

from __future__ import annotations

import numpy as np

from drivewm.multiverse.scores import _comfort


def test_comfort_reads_the_jerk_and_lateral_acceleration_of_a_smooth_path() -> None:
    """x(t) = 12 t + (J / w^3) sin(w t): |jerk| peaks at J; y(t) = B sin(w t): lateral acceleration B w^2."""
    t = np.arange(0, 8.0, 0.1)
    w, jerk, b = 2 * np.pi / 4.0, 2.0, 0.5
    path = np.stack([12.0 * t + jerk / w**3 * np.sin(w * t), b * np.sin(w * t)], axis=1)
    scores = _comfort(t, path)
    assert abs(scores["max_abs_jerk_mps3"] - jerk) < 0.25 * jerk
    assert abs(scores["max_abs_lateral_accel_mps2"] - b * w**2) < 0.25 * b * w**2


def test_a_step_in_acceleration_is_not_read_as_a_jolt() -> None:
    """Braking at 3 m/s^2 from t = 2 s, as a 10 Hz driver model commands it: finite differences read a jerk
    of 30 m/s^3 at the step, nuPlan's comfort bound is 8.37; a smoothed derivative reads it as 3 m/s^2 over
    about a second."""
    t = np.arange(0, 6.0, 0.1)
    speed = np.where(t < 2.0, 12.0, 12.0 - 3.0 * (t - 2.0))
    x = np.concatenate([[0.0], np.cumsum(speed[:-1] * 0.1)])
    scores = _comfort(t, np.stack([x, np.zeros_like(x)], axis=1))
    assert 1.0 < scores["max_abs_jerk_mps3"] < 8.37
    assert scores["max_abs_lateral_accel_mps2"] < 1e-6
