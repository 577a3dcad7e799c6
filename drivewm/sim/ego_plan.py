"""What the ego does after a branch point of a drive (drivewm.sim.fork_highway, drivewm.sim.fork_sumo).

A plan is either a manoeuvre (a lane change, a held acceleration, a turn at the next junction),
which the simulator's own controllers carry out, or poses the ego is placed at, tick by tick
(waypoint plans: the ego follows them exactly, the other road users react to it).
Poses are in the ego frame at the branch point (x forward, y left, z up; origin on the ground
under the rear axle).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from drivewm.geometry import T_from_xyz_yaw

#: Lateral distance of one lane change (m) and how long it takes (s), for kinematic manoeuvres.
LANE_WIDTH_M = 3.5
LANE_CHANGE_S = 4.0
#: The ego's box (m): length, width, and its centre ahead of the rear axle (the simulators' 5 m car).
EGO_LENGTH_M = 5.0
EGO_WIDTH_M = 2.0
EGO_CENTER_AHEAD_OF_REAR_AXLE_M = 1.5


@dataclasses.dataclass
class EgoPlan:
    """One future's ego behaviour after the branch point."""

    name: str
    """Shown in reports and used as the future's folder name."""
    lane_change: int = 0
    """+1: one lane to the left, -1: one lane to the right, 0: keep the lane."""
    accel_mps2: float = 0.0
    """Longitudinal acceleration held from the branch point (speed stays within [0, max_speed_mps])."""
    max_speed_mps: float = 33.0
    """Speed an accelerating ego holds once reached."""
    turn: str = ""
    """"left", "right" or "any" (left where there is one): take that turn at the next junction (SUMO); "" for none."""
    T_branch_from_ego: np.ndarray | None = None
    """(N, 4, 4) ego poses at the future's ticks 1..N in the branch point's ego frame (waypoint plans);
    None for manoeuvres."""

    @property
    def is_kinematic(self) -> bool:
        """Whether the ego is placed at given poses rather than driven by a controller."""
        return self.T_branch_from_ego is not None


def no_lane_reason(lane_change: int) -> str:
    """Why a lane change is infeasible where the ego's road has no lane on that side."""
    return f"no lane to the {'left' if lane_change > 0 else 'right'} of the ego at the branch point"


def speed_profile(v0_mps: float, accel_mps2: float, max_speed_mps: float, times_s: np.ndarray) -> np.ndarray:
    """Speed (m/s) at ``times_s`` under a constant acceleration, clamped to [0, max(v0, max_speed)]."""
    return np.clip(v0_mps + accel_mps2 * np.asarray(times_s), 0.0, max(v0_mps, max_speed_mps))


def manoeuvre_poses(plan: EgoPlan, v0_mps: float, times_s: np.ndarray) -> np.ndarray:
    """(N, 4, 4) poses of a manoeuvre driven open-loop from the branch point (straight ahead in the branch
    ego frame, a lane change as a smoothstep of :data:`LANE_WIDTH_M` over :data:`LANE_CHANGE_S`), at
    ``times_s`` after the branch: the ego of a replayed (non-reactive) log."""
    fine_t = np.linspace(0.0, float(np.max(times_s)), max(2, int(math.ceil(np.max(times_s) * 100)) + 1))
    v = speed_profile(v0_mps, plan.accel_mps2, plan.max_speed_mps, fine_t)
    x = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(fine_t))])
    u = np.clip(fine_t / LANE_CHANGE_S, 0.0, 1.0)
    y = plan.lane_change * LANE_WIDTH_M * u * u * (3 - 2 * u)  # smoothstep
    xs, ys = np.interp(times_s, fine_t, x), np.interp(times_s, fine_t, y)
    yaw = np.arctan2(np.gradient(y, fine_t), np.maximum(np.gradient(x, fine_t), 1e-6))
    yaws = np.interp(times_s, fine_t, yaw)
    return np.stack([T_from_xyz_yaw(a, b, 0.0, c) for a, b, c in zip(xs, ys, yaws)])


@dataclasses.dataclass
class PlacedVehicle:
    """A road user put on the ego's lane when a future starts (a built case: a stopped car ahead, a
    follower behind), the same in every future."""

    gap_m: float
    """Distance along the lane from the ego's centre to the vehicle's centre: > 0 ahead, < 0 behind."""
    speed_mps: float | None = None
    """Its speed when placed; None: the ego's. A vehicle placed at 0 stays where it is; any other is
    driven by the simulator's car-following model (IDM, SUMO's Krauss)."""
