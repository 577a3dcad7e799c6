"""Simulated MCAP logs are geometrically consistent with their own calibration and poses.

Read back through drivewm.logs.reader.read_log (JPEG images, calibration and /tf from the file):
- SIFT matches between adjacent cameras at the same tick satisfy the epipolar constraint of F
  computed from the log's K and T_ego_from_cam (median Sampson error < 0.5 px);
- consecutive frames of one camera give, through cv2.findEssentialMat + recoverPose, the
  relative pose of the logged ego motion within 1 degree.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from sim_matching import agent_mask, in_view_of, match, sift

from drivewm.geometry import fundamental_from_T, invert_T, rotation_angle_deg, sampson_distance_sq
from drivewm.logs.reader import read_log

PAIRS = [
    ("CAM_FRONT", "CAM_FRONT_LEFT"),
    ("CAM_FRONT_RIGHT", "CAM_FRONT"),
    ("CAM_BACK", "CAM_BACK_LEFT"),
    ("CAM_BACK_RIGHT", "CAM_BACK"),
]


@pytest.fixture(scope="module")
def day_logs(sim_log_dir):
    return {name: read_log(sim_log_dir / f"{name}.mcap") for name in ("highway_clear", "roundabout_clear")}


@pytest.mark.parametrize("log_name", ["highway_clear", "roundabout_clear"])
@pytest.mark.parametrize("cam_a,cam_b", PAIRS)
def test_adjacent_cameras_obey_calibrated_epipolar_geometry(day_logs, log_name: str, cam_a: str, cam_b: str) -> None:
    log = day_logs[log_name]
    ca, cb = log.rig.camera(cam_a), log.rig.camera(cam_b)
    F = fundamental_from_T(ca.K, cb.K, invert_T(cb.T_ego_from_cam) @ ca.T_ego_from_cam)
    errors = []
    for k in range(0, len(log.images[cam_a]), 10):  # six ticks over the drive, matches pooled
        xa, xb = match(sift(log.images[cam_a][k].decode()), sift(log.images[cam_b][k].decode()), ratio=0.75)
        shared = in_view_of(ca, cb, xa) & in_view_of(cb, ca, xb)
        errors.append(np.sqrt(sampson_distance_sq(F, xa[shared], xb[shared])))
    errors = np.concatenate(errors)
    assert len(errors) >= 40, f"only {len(errors)} matches in the shared view of {cam_a} and {cam_b}"
    assert np.median(errors) < 0.5, f"median Sampson error {np.median(errors):.3f} px"


@pytest.mark.parametrize("log_name", ["highway_clear", "roundabout_clear"])
def test_consecutive_frames_give_the_logged_ego_motion(day_logs, log_name: str) -> None:
    log = day_logs[log_name]
    cam = log.rig.camera("CAM_FRONT")
    frames, agents = log.images["CAM_FRONT"], dict(log.agents)
    pose_at = dict(zip(log.pose_timestamps_ns.tolist(), log.T_world_from_ego))
    rot_errors, dir_errors = [], []
    for k in range(0, len(frames) - 1, 8):
        feats, T_world_from_cam = [], []
        for frame in (frames[k], frames[k + 1]):
            T_world_from_ego = pose_at[frame.timestamp_ns]
            feats.append(sift(frame.decode(), agent_mask(cam, T_world_from_ego, agents.get(frame.timestamp_ns, []))))
            T_world_from_cam.append(T_world_from_ego @ cam.T_ego_from_cam)
        xa, xb = match(*feats)
        E, inliers = cv2.findEssentialMat(xa, xb, cam.K, cv2.USAC_ACCURATE, 0.9999, 0.5)
        _, R, t, _ = cv2.recoverPose(E, xa, xb, cam.K, mask=inliers)
        T_b_from_a = invert_T(T_world_from_cam[1]) @ T_world_from_cam[0]
        rot_errors.append(rotation_angle_deg(R @ T_b_from_a[:3, :3].T))
        t_true = T_b_from_a[:3, 3] / np.linalg.norm(T_b_from_a[:3, 3])
        dir_errors.append(np.degrees(np.arccos(np.clip(float(t.ravel() @ t_true), -1.0, 1.0))))
    assert max(rot_errors) < 1.0, f"rotation errors (deg) {np.round(rot_errors, 3)}"
    assert max(dir_errors) < 3.0, f"translation direction errors (deg) {np.round(dir_errors, 2)}"
