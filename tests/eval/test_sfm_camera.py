"""Structure from motion keeps each camera's calibration: COLMAP camera models that carry the rig's
OpenCV distortion, pixel-centre conventions, and a distorted rig registered end to end."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from drivewm.errors import DrivewmError
from drivewm.eval.config import PoseConfig
from drivewm.eval.sfm import colmap_camera, run_sfm
from drivewm.eval.trajectory import ego_from_sfm
from drivewm.eval.trajectory_errors import ate
from drivewm.geometry import load_rig

FRONT3 = ["CAM_FRONT_LEFT", "CAM_FRONT", "CAM_FRONT_RIGHT"]
#: A wide-angle lens: barrel k1, k2, tangential p1, p2, and k3.
DISTORTION = np.array([-0.28, 0.09, 0.001, -0.0015, -0.012])


@pytest.mark.parametrize(
    "dist,model",
    [
        (np.zeros(0), "PINHOLE"),
        (DISTORTION[:4], "OPENCV"),
        (DISTORTION, "FULL_OPENCV"),
        (np.concatenate([DISTORTION, [0.01, -0.002, 0.0005]]), "FULL_OPENCV"),
    ],
)
def test_colmap_camera_projects_like_opencv(dist, model):
    """COLMAP's projection of the camera, shifted by its half-pixel convention, equals cv2.projectPoints."""
    cam = dataclasses.replace(load_rig("nuscenes6").camera("CAM_FRONT"), distortion=dist)
    colmap = colmap_camera(cam)
    assert colmap.model.name == model
    rng = np.random.default_rng(0)
    pts = rng.uniform([-4, -2, 3], [4, 2, 30], (200, 3))
    ours = colmap.img_from_cam(pts) - 0.5
    theirs, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), cam.K, dist if dist.size else None)
    np.testing.assert_allclose(ours, theirs.reshape(-1, 2), atol=1e-9)
    if dist.size:  # the lens matters: a pinhole model would be off by pixels
        assert (
            np.abs(
                theirs.reshape(-1, 2) - cv2.projectPoints(pts, np.zeros(3), np.zeros(3), cam.K, None)[0].reshape(-1, 2)
            ).max()
            > 2
        )


def test_unsupported_distortion_is_a_clear_error():
    cam = dataclasses.replace(load_rig("nuscenes6").camera("CAM_FRONT"), distortion=np.ones(12) * 1e-3)
    with pytest.raises(DrivewmError, match="CAM_FRONT: 12 distortion coefficients"):
        colmap_camera(cam)


@pytest.mark.slow
@pytest.mark.timeout(3600)
def test_distorted_rig_registers_with_its_lens_model():
    """The corridor seen through barrel-distorted front cameras: with the lens in the COLMAP model the
    clip registers and the trajectory is within 5 cm; treated as pinhole it is worse or breaks."""
    from eval_synth import synth_frames

    rig = load_rig("nuscenes6").subset(FRONT3)
    rig = dataclasses.replace(rig, cameras=[dataclasses.replace(c, distortion=DISTORTION) for c in rig.cameras])
    videos, poses = synth_frames(rig, num_frames=9)
    sfm = run_sfm(videos, rig, PoseConfig())
    assert sfm.all_registered
    err, sim = ate(ego_from_sfm(sfm, rig).T_world_from_ego, poses)
    pinhole = dataclasses.replace(rig, cameras=[dataclasses.replace(c, distortion=np.zeros(0)) for c in rig.cameras])
    sfm_pin = run_sfm(videos, pinhole, PoseConfig())
    ego_pin = ego_from_sfm(sfm_pin, pinhole)
    reg = ego_pin.registered
    err_pin = ate(ego_pin.T_world_from_ego[reg], poses[reg])[0] if reg.sum() >= 3 else float("inf")
    print(f"distorted rig: ATE {err:.4f} m (scale {sim.scale:.3f})")
    print(f"as pinhole: registered {sfm_pin.registered_fraction:.2f}, ATE {err_pin:.4f} m")
    assert err < 0.05 and sim.scale == pytest.approx(1.0, abs=0.05)
    assert not sfm_pin.all_registered or err_pin > 2 * err
