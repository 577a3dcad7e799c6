"""Noise warped along the trajectory (drivewm.multiview.warped_noise): standard normal everywhere,
correlated by exactly a along the warp, moving the way the image content of a turn moves, and used
by the model only where it was trained with it and a trajectory is given."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from drivewm.geometry import T_from_xyz_yaw, load_rig
from drivewm.multiview.warp import warp_grid
from drivewm.multiview.warped_noise import warp_noise

HW = (12, 20)


def _left_turn(rig, yaw: float = 0.2):
    """Warp grids of a rig that turns left on the spot by ``yaw`` rad per frame, everything at infinity."""
    poses = np.stack([T_from_xyz_yaw(0.0, 0.0, 0.0, k * yaw) for k in range(3)])
    return warp_grid(rig, HW, poses, max_ground_m=0.0)


def test_zero_correlation_is_the_identity_and_a_bad_one_is_refused():
    rig = load_rig("front3")
    grid, valid = _left_turn(rig)
    noise = torch.randn(3, 4, 3, *HW)
    assert warp_noise(noise, grid, valid, 3, 0.0) is noise
    for a in (1.0, -0.1, 1.5):
        with pytest.raises(ValueError, match="warped noise"):
            warp_noise(noise, grid, valid, 3, a)


def test_values_stay_standard_normal_and_correlate_by_a_along_the_warp():
    rig = load_rig("front3")
    grid, valid = _left_turn(rig)
    a = 0.8
    noise = torch.randn(3 * 400, 4, 3, *HW, generator=torch.Generator().manual_seed(0))  # 400 clips of 3 views
    out = warp_noise(noise, grid.repeat(400, 1, 1, 1, 1), valid.repeat(400, 1, 1, 1), 3, a)
    assert abs(float(out.mean())) < 0.01 and abs(float(out.std()) - 1) < 0.01
    torch.testing.assert_close(out[:, :, 0], noise[:, :, 0])  # the first frame is the seed's own
    # the source of a valid pixel is the first frame's nearest latent pixel, in whichever view holds it
    x = (grid[..., 0] + 1) / 2 * 3 * HW[1] - 0.5
    y = (grid[..., 1] + 1) / 2 * HW[0] - 0.5
    view, col, row = (x // HW[1]).round().long(), (x % HW[1]).round().long(), y.round().long()
    v, t, i, j = torch.nonzero(valid[:, 1:], as_tuple=True)
    t = t + 1
    clips = torch.arange(400).repeat_interleave(len(v))
    at = (v, t, i, j)
    src = noise[clips * 3 + view[at].repeat(400), :, 0, row[at].repeat(400), col[at].repeat(400)]
    dst = out[clips * 3 + v.repeat(400), :, t.repeat(400), i.repeat(400), j.repeat(400)]
    corr = float(torch.corrcoef(torch.stack([src.flatten(), dst.flatten()]))[0, 1])
    assert abs(corr - a) < 0.01, corr
    invalid = ~valid[:, 1:]
    if invalid.any():  # no source: the frame's own noise, untouched
        later = [x[:3, :, 1:].permute(0, 2, 3, 4, 1)[invalid] for x in (out, noise)]
        torch.testing.assert_close(*later)


def test_the_noise_of_a_left_turn_moves_right_by_the_turn():
    """Turning left, what the front camera saw moves right in its image, by about fx * yaw: so does
    the noise (the column shift with the highest correlation between frames 0 and 1)."""
    rig = load_rig("nuscenes6")
    yaw = 0.2
    grid, valid = _left_turn(rig, yaw)
    out = warp_noise(torch.randn(6, 16, 3, *HW), grid, valid, 6, 0.95)
    front = out[rig.names.index("CAM_FRONT")]
    cam = rig.camera("CAM_FRONT")
    expected = cam.K[0, 0] * HW[1] / cam.width * np.tan(yaw)  # latent columns, at the image centre
    w = HW[1]

    def corr(s: int) -> float:
        a, b = front[:, 0, :, w // 4 : 3 * w // 4], front[:, 1, :, w // 4 + s : 3 * w // 4 + s]
        return float(torch.corrcoef(torch.stack([a.flatten(), b.flatten()]))[0, 1])

    best = max(range(-4, 5), key=corr)
    assert best > 0 and abs(best - expected) <= 1, (best, expected)
    assert corr(best) > 0.8 and abs(corr(-best)) < 0.1
