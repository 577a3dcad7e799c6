"""Plans: what the ego does in each future, by name (a manoeuvre) or from a waypoint file.

A waypoint file is the trajectory format ``drivewm generate --trajectory`` takes
(drivewm.multiview.trajectories.load_waypoints: (N, 3) metres in the ego frame at the branch point,
x forward, y left), spaced ``waypoint_dt_s`` apart from one step after the branch; a ``.json`` file
may also give ``"times_s"``: each waypoint's time after the branch point (finite, increasing, > 0).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from drivewm.errors import DrivewmError
from drivewm.multiview.trajectories import load_waypoints, poses_from_waypoints
from drivewm.paths import sanitize_name
from drivewm.sim.ego_plan import EgoPlan

BRAKE_MPS2 = -4.0  # firm braking, well within a car's ~8 m/s^2
ACCELERATE_MPS2 = 2.0
#: Manoeuvre name -> the EgoPlan fields it sets.
MANOEUVRES = {
    "keep": {},
    "left": {"lane_change": 1},
    "right": {"lane_change": -1},
    "brake": {"accel_mps2": BRAKE_MPS2},
    "accelerate": {"accel_mps2": ACCELERATE_MPS2},
    "turn": {"turn": "any"},
    "turn-left": {"turn": "left"},
    "turn-right": {"turn": "right"},
}


def parse_plans(specs: list[str], future_times_s: np.ndarray, waypoint_dt_s: float) -> list[EgoPlan]:
    """One EgoPlan per spec (a manoeuvre name or a waypoint file); ``future_times_s`` (N,): the future
    ticks' times after the branch point, where waypoint plans are sampled."""
    plans = [_plan(spec, future_times_s, waypoint_dt_s) for spec in specs]
    names = [p.name for p in plans]
    if len(set(names)) != len(names):
        raise DrivewmError(f"plans: each future needs its own name, got {names}")
    return plans


def check_plan_names(specs: list[str]) -> None:
    """Refuse an unknown plan before anything runs (names that are neither manoeuvres nor files)."""
    for spec in specs:
        if spec not in MANOEUVRES and not Path(spec).is_file():
            raise DrivewmError(f"plan {spec!r}: not one of {list(MANOEUVRES)} and not a waypoint file")


def _plan(spec: str, future_times_s: np.ndarray, waypoint_dt_s: float) -> EgoPlan:
    if spec in MANOEUVRES:
        return EgoPlan(spec, **MANOEUVRES[spec])
    if not Path(spec).is_file():
        raise DrivewmError(f"plan {spec!r}: not one of {list(MANOEUVRES)} and not a waypoint file")
    waypoints, times_s = load_waypoint_plan(spec, waypoint_dt_s)
    return EgoPlan(
        sanitize_name(Path(spec).stem, "waypoints"),
        T_branch_from_ego=waypoint_poses(waypoints, times_s, future_times_s),
    )


def load_waypoint_plan(path: str | Path, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(waypoints (N, 3) m, their times (N,) s after the branch point) of a waypoint file."""
    waypoints = load_waypoints(path)
    times = (np.arange(len(waypoints)) + 1) * dt_s
    if Path(path).suffix == ".json":
        raw = json.loads(Path(path).read_text())
        if isinstance(raw, dict) and "times_s" in raw:
            times = _times(raw["times_s"], len(waypoints), str(path))
    return waypoints, times


def _times(value, count: int, where: str) -> np.ndarray:
    try:
        times = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise DrivewmError(f"{where}: times_s must be a list of numbers (s), got {value!r}") from None
    if times.shape != (count,):
        raise DrivewmError(f"{where}: times_s needs one time per waypoint ({count}), got shape {times.shape}")
    if not np.all(np.isfinite(times)):
        raise DrivewmError(
            f"{where}: times_s must be finite, got NaN or inf at index {int(np.argmin(np.isfinite(times)))}"
        )
    if times[0] <= 0 or np.any(np.diff(times) <= 0):
        raise DrivewmError(f"{where}: times_s must increase from above 0, got {times.tolist()}")
    return times


def waypoint_poses(waypoints: np.ndarray, times_s: np.ndarray, future_times_s: np.ndarray) -> np.ndarray:
    """(N, 4, 4) poses at ``future_times_s`` (the branch point at t = 0 is the origin), positions
    interpolated linearly (held at the last waypoint after its time), heading along the motion."""
    t = np.concatenate([[0.0], times_s])
    w = np.concatenate([np.zeros((1, 3)), waypoints])
    at = np.stack([np.interp(future_times_s, t, w[:, k]) for k in range(3)], axis=1)
    dt = float(future_times_s[0]) if len(future_times_s) else 1.0
    return poses_from_waypoints(at, len(future_times_s) + 1, dt, 1.0 / dt)[1:]
