"""Conversions between drivewm's 4x4 transforms / integer nanoseconds and the message fields
of Foxglove and ROS 2 (translation + quaternion x, y, z, w; time as sec + nsec).

A pose that is not finite (fleet logs have gaps) travels as NaN translation and quaternion and
comes back as an all-NaN 4x4, so a gap stays a gap instead of turning into a wrong pose.
"""

from __future__ import annotations

import numpy as np

from drivewm.geometry import R_to_quat_xyzw, make_T, quat_xyzw_to_R


def split_T(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """4x4 transform -> (translation (3,), quat_xyzw (4,)); NaN for both if T is not finite."""
    T = np.asarray(T, dtype=np.float64)
    if not np.all(np.isfinite(T)):
        return np.full(3, np.nan), np.full(4, np.nan)
    return T[:3, 3].copy(), R_to_quat_xyzw(T[:3, :3])


def join_T(translation: np.ndarray, quat_xyzw: np.ndarray) -> np.ndarray:
    """(translation (3,), quat_xyzw (4,)) -> 4x4 transform; all NaN if either is not finite or
    the quaternion is zero (an unset ROS/Foxglove quaternion)."""
    t = np.asarray(translation, dtype=np.float64)
    q = np.asarray(quat_xyzw, dtype=np.float64)
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(q))) or not np.any(q):
        return np.full((4, 4), np.nan)
    return make_T(quat_xyzw_to_R(q), t)


def quat_xyzw_from_yaw(yaw_rad: float) -> np.ndarray:
    """Rotation about +z as a quaternion (x, y, z, w)."""
    return np.array([0.0, 0.0, np.sin(yaw_rad / 2), np.cos(yaw_rad / 2)])


def yaw_from_quat_xyzw(quat_xyzw: np.ndarray) -> float:
    """Heading about +z of a quaternion (x, y, z, w) (exact inverse of quat_xyzw_from_yaw up to
    rounding; for a general rotation, the yaw of its x axis)."""
    R = quat_xyzw_to_R(quat_xyzw)
    return float(np.arctan2(R[1, 0], R[0, 0]))


def ns_to_sec_nsec(timestamp_ns: int) -> tuple[int, int]:
    """Integer nanoseconds -> (sec, nsec) with 0 <= nsec < 1e9."""
    sec, nsec = divmod(int(timestamp_ns), 1_000_000_000)
    return sec, nsec


def sec_nsec_to_ns(sec: int, nsec: int) -> int:
    """(sec, nsec) -> integer nanoseconds."""
    return int(sec) * 1_000_000_000 + int(nsec)
