"""Staggered camera exposures: camera i of the rig exposes at ``tick + i * stagger``.

Real surround rigs do not fire all cameras together: nuScenes triggers each camera as the lidar
sweeps past it, so the six exposures of one sweep spread over about 40 ms (Caesar et al.,
"nuScenes", CVPR 2020, sec. 2). At 30 m/s the ego moves over a metre in that time, which is what
a cross-view consistency score must compensate for. The simulator logs a scene state per tick;
an exposure between two ticks sees the world interpolated between them: the ego pose (position
linear, rotation by quaternion slerp) and every other road user present at both ticks (centre
linear, heading along the shorter arc). A road user present at only one of the two ticks is shown
as at the nearer tick (it enters or leaves the scene there). The traffic simulators step at the
tick rate or finer (highway-env at most 1/15 s, SUMO at one tick), so linear motion between ticks
is the simulator's own resolution.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from drivewm.errors import DrivewmError
from drivewm.geometry import R_to_quat_xyzw, make_T, quat_xyzw_to_R
from drivewm.logs.types import AgentBox
from drivewm.sim.scene import SceneTick


def exposure_offsets_ns(num_cameras: int, stagger_ms: float, period_ns: float) -> list[int]:
    """Offsets (ns) of each camera's exposure after the tick, rig order: ``i * stagger``.

    Raises DrivewmError when the last camera would expose at or after the next tick (the
    exposures of one tick must stay between it and the next)."""
    offsets = [int(round(i * stagger_ms * 1e6)) for i in range(num_cameras)]
    if stagger_ms < 0 or (offsets and offsets[-1] >= period_ns):
        raise DrivewmError(
            f"sim config: exposure_stagger_ms {stagger_ms} must be >= 0 and put the last of {num_cameras} cameras "
            f"before the next tick ({num_cameras - 1} x stagger < {period_ns / 1e6:g} ms)"
        )
    return offsets


def state_at(ticks: list[SceneTick], k: int, timestamp_ns: int) -> SceneTick:
    """The world at ``timestamp_ns`` in [ticks[k], ticks[k + 1]] (exactly ticks[k] at its own time)."""
    a = ticks[k]
    if timestamp_ns == a.timestamp_ns:
        return a
    if k + 1 >= len(ticks):
        raise DrivewmError(f"exposure at {timestamp_ns} ns is after the last simulated tick")
    b = ticks[k + 1]
    w = (timestamp_ns - a.timestamp_ns) / (b.timestamp_ns - a.timestamp_ns)
    T = interpolate_pose(a.T_world_from_ego, b.T_world_from_ego, w)
    later = {box.track_id: box for box in b.agents}
    agents = [_interpolate_box(box, later.get(box.track_id), w) for box in a.agents]
    if w > 0.5:  # road users that enter at tick k + 1 are nearer to it
        known = {box.track_id for box in a.agents}
        agents += [box for box in b.agents if box.track_id not in known]
        agents = [box for box in agents if box.track_id in later]
    speed = (1 - w) * a.ego_speed_mps + w * b.ego_speed_mps
    return SceneTick(int(timestamp_ns), T, agents, speed)


def interpolate_pose(T_a: np.ndarray, T_b: np.ndarray, w: float) -> np.ndarray:
    """Rigid pose a fraction ``w`` in [0, 1] from ``T_a`` to ``T_b``: translation linear, rotation slerp."""
    t = (1 - w) * T_a[:3, 3] + w * T_b[:3, 3]
    return make_T(quat_xyzw_to_R(slerp(R_to_quat_xyzw(T_a[:3, :3]), R_to_quat_xyzw(T_b[:3, :3]), w)), t)


def slerp(q_a: np.ndarray, q_b: np.ndarray, w: float) -> np.ndarray:
    """Spherical linear interpolation of unit quaternions (x, y, z, w) along the shorter arc
    (Shoemake, "Animating rotation with quaternion curves", SIGGRAPH 1985)."""
    dot = float(q_a @ q_b)
    if dot < 0:
        q_b, dot = -q_b, -dot
    if dot > 0.9995:  # nearly equal: the linear blend is exact to float precision
        q = (1 - w) * q_a + w * q_b
        return q / np.linalg.norm(q)
    theta = np.arccos(dot)
    return (np.sin((1 - w) * theta) * q_a + np.sin(w * theta) * q_b) / np.sin(theta)


def _interpolate_box(a: AgentBox, b: AgentBox | None, w: float) -> AgentBox:
    if b is None:
        return a
    turn = (b.yaw_rad - a.yaw_rad + np.pi) % (2 * np.pi) - np.pi  # the shorter arc
    center = (1 - w) * np.asarray(a.center_xyz) + w * np.asarray(b.center_xyz)
    return dataclasses.replace(a, center_xyz=center, yaw_rad=float(a.yaw_rad + w * turn))
