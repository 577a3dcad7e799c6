"""The multi-view model extends its Text2World parent: zero step = parent per view, any rig, and the
trajectory / camera / Video2World conditioning reach the output."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import numpy as np
import pytest
import torch

from drivewm.diffusion.denoiser import Conditioning
from drivewm.errors import DrivewmError
from drivewm.geometry import load_rig
from drivewm.multiview.config import MultiViewConfig
from drivewm.multiview.cross_view import view_neighbors
from drivewm.multiview.init import from_text2world
from drivewm.multiview.trajectories import resolve_trajectory

CAPTIONS = [
    "a snowy highway",
    "a clear roundabout at noon",
    "night in a city grid",
    "fog on a bridge",
    "rain, lorry ahead",
    "empty road",
]


def _inputs(model, rig, b=2, seed=0):
    v = len(rig.cameras)
    caps = [[CAPTIONS[(i + j) % len(CAPTIONS)] for j in range(v)] for i in range(b)]
    traj = np.stack([resolve_trajectory(name, 16, 0.1) for name in ["left", "stop"][:b]])
    cond = model.conditioning(rig, caps, traj)
    g = torch.Generator().manual_seed(seed)
    x = torch.randn(b * v, *model.latent.latent_shape, generator=g)
    sigma = torch.exp(torch.randn(b * v, generator=g))
    return caps, traj, cond, x, sigma


@pytest.mark.parametrize("cross_view", ["joint", "neighbors"])
def test_zero_step_equals_parent_per_view(parent, cross_view):
    mv = from_text2world(parent, MultiViewConfig(cross_view=cross_view, neighbors=1), cond_frames=1)
    rig = load_rig("nuscenes6")
    caps, _, cond, x, sigma = _inputs(mv, rig)
    with torch.no_grad():
        out = mv.net(x, sigma, cond)  # (B V, c, t, h, w)
        emb, mask = parent.text_encoder.encode([c for row in caps for c in row])
        ref = parent.denoiser(x, sigma, Conditioning(emb, mask, cond.fps))  # each view on its own
    assert out.abs().mean() > 0.1  # a non-trivial output
    torch.testing.assert_close(out, ref, rtol=1e-6, atol=1e-6)


def test_same_checkpoint_runs_three_and_six_camera_rigs(parent, tmp_path):
    from drivewm.multiview.model import MultiView

    from_text2world(parent).save_pretrained(tmp_path / "mv")
    mv = MultiView.from_pretrained(tmp_path / "mv")
    for rig_name, v in [("front3", 3), ("nuscenes6", 6)]:
        rig = load_rig(rig_name)
        z = mv.sample_latents(
            rig, [CAPTIONS[:v]], resolve_trajectory("straight", 16, 0.1)[None], seeds=[0], steps=3, guidance=2.0
        )
        assert z.shape == (1, v, *mv.latent.latent_shape) and torch.isfinite(z).all()


def _perturb(module: torch.nn.Module, seed: int) -> None:
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for p in module.parameters():
            p.add_(0.2 * torch.randn(p.shape, generator=g))


def test_trajectory_and_camera_conditioning_change_the_output(parent):
    mv = from_text2world(parent)
    rig = load_rig("front3")
    _, _, cond, x, sigma = _inputs(mv, rig)
    _perturb(mv.net.trajectory_encoder, 1)
    _perturb(mv.net.camera_encoder, 2)
    with torch.no_grad():
        base = mv.net(x, sigma, cond)
        swapped = mv.net(x, sigma, dataclasses.replace(cond, trajectory=cond.trajectory.flip(0)))  # left <-> stop
        moved_rig = load_rig("nuscenes6").subset(["CAM_BACK_LEFT", "CAM_BACK", "CAM_BACK_RIGHT"])
        other_rays = mv.conditioning(moved_rig, [["x"] * 3] * 2, None).rays
        other_cams = mv.net(x, sigma, dataclasses.replace(cond, rays=other_rays))
    assert (swapped - base).abs().mean() > 1e-3 * base.abs().mean()
    assert (other_cams - base).abs().mean() > 1e-3 * base.abs().mean()


def test_dropped_trajectory_is_no_trajectory_and_guidance_interpolates(parent):
    """A dropped trajectory (training dropout, guidance's free branch) is exactly the model given
    none: static rays, no waypoint embedding. Trajectory guidance w is D_free + w (D_traj - D_free)."""
    from drivewm.diffusion.samplers import GuidedDenoiser

    mv = from_text2world(parent)
    rig = load_rig("front3")
    caps, _, cond, x, sigma = _inputs(mv, rig)
    _perturb(mv.net.trajectory_encoder, 1)
    _perturb(mv.net.camera_encoder, 2)
    none = mv.conditioning(rig, caps, None)
    with torch.no_grad():
        with_traj, free = mv.net(x, sigma, cond), mv.net(x, sigma, cond.without_trajectory())
        torch.testing.assert_close(free, mv.net(x, sigma, none))
        assert (with_traj - free).abs().mean() > 1e-3 * free.abs().mean()
        keep = torch.tensor([True, True, True, False, False, False])  # clip 0 keeps it, clip 1 drops it
        mixed = mv.net(x, sigma, cond.drop_trajectory(keep))
        torch.testing.assert_close(mixed[:3], with_traj[:3])
        torch.testing.assert_close(mixed[3:], free[3:])
        guided = GuidedDenoiser(mv.net, 3.0, drop=lambda c: c.without_trajectory())(x, sigma, cond)
        torch.testing.assert_close(guided, free + 3.0 * (with_traj - free))


def test_cross_view_attention_mixes_views_after_training_like_perturbation(parent):
    mv = from_text2world(parent, MultiViewConfig(cross_view="neighbors", neighbors=2))
    _perturb(mv.net.dit.blocks[-1].layers["cross_view_attn"].layer.out, 3)  # one hop of mixing only
    rig = load_rig("nuscenes6")
    _, _, cond, x, sigma = _inputs(mv, rig, b=1)
    nbrs = view_neighbors(rig, "neighbors", 2)
    far = next(j for j in range(6) if j not in nbrs[0].tolist())  # a view that view 0 does not read
    with torch.no_grad():
        base = mv.net(x, sigma, cond)
        x2 = x.clone()
        x2[far] += 1.0
        out = mv.net(x2, sigma, cond)
    assert torch.allclose(out[0], base[0], atol=1e-6)  # views outside the neighbourhood do not leak
    reader = next(j for j in range(6) if j != far and far in nbrs[j].tolist())
    assert not torch.allclose(out[reader], base[reader], atol=1e-4)  # a view that reads it does see it


def test_view_neighbors_follow_rig_geometry():
    nbrs = view_neighbors(load_rig("nuscenes6"), "neighbors", 2).tolist()
    names = load_rig("nuscenes6").names
    by_name = {names[i]: {names[j] for j in row} for i, row in enumerate(nbrs)}
    assert by_name["CAM_FRONT"] == {"CAM_FRONT", "CAM_FRONT_LEFT", "CAM_FRONT_RIGHT"}
    assert by_name["CAM_BACK"] == {"CAM_BACK", "CAM_BACK_LEFT", "CAM_BACK_RIGHT"}
    assert view_neighbors(load_rig("front3"), "joint", 1).shape == (3, 3)


def test_video2world_keeps_the_conditioning_frames(parent):
    mv = from_text2world(parent, cond_frames=1)
    rig = load_rig("front3")
    cond_latents = torch.randn(1, 3, *mv.latent.latent_shape) * 0.9 + 0.1
    z = mv.sample_latents(
        rig,
        [CAPTIONS[:3]],
        resolve_trajectory("right", 16, 0.1)[None],
        [5],
        steps=3,
        guidance=1.0,
        cond_latents=cond_latents,
    )
    torch.testing.assert_close(z[:, :, :, :1], cond_latents[:, :, :, :1], rtol=1e-5, atol=1e-5)
    assert (z[:, :, :, 1:] - cond_latents[:, :, :, 1:]).abs().mean() > 0.1


def test_plucker_rays_are_the_camera_rays_and_move_with_the_ego():
    import dataclasses as dc

    from drivewm.geometry import T_from_xyz_yaw, transform_points
    from drivewm.views.rays import moving_token_rays, plucker_rays

    rig = load_rig("front3")
    rays = plucker_rays(rig, (6, 10)).double()  # (V, 60, 6)
    cam = rig.cameras[0]
    # A point at depth 7 m along the ray of a patch centre lies on the Plucker line: m = p x d.
    d, m = rays[0, 13, :3].numpy(), rays[0, 13, 3:].numpy()
    p = transform_points(
        cam.T_ego_from_cam, 7.0 * np.linalg.solve(cam.K, [(3 + 0.5) * 32 - 0.5, (1 + 0.5) * 32 - 0.5, 1.0])
    )
    np.testing.assert_allclose(np.cross(p, d), m, atol=1e-9)
    # Moving the ego by T equals the rig mounted at T @ T_ego_from_cam.
    T = T_from_xyz_yaw(4.0, -1.5, 0.0, 0.3)
    moved = moving_token_rays(rays, torch.from_numpy(np.stack([np.eye(4), T])))  # (V, 2*60, 6)
    rig_at_T = dc.replace(rig, cameras=[dc.replace(c, T_ego_from_cam=T @ c.T_ego_from_cam) for c in rig.cameras])
    torch.testing.assert_close(moved[:, 60:], plucker_rays(rig_at_T, (6, 10)).double(), atol=1e-6, rtol=1e-6)
    torch.testing.assert_close(moved[:, :60], rays)
    # The trajectory probe's turned rig (drivewm.multiview.trajectory_probe.turn_rays) is the rig
    # turned in place: the ego rotated about its origin, and a quarter turn left sends +x to +y.
    from drivewm.multiview.trajectory_probe import turn_rays

    turned = moving_token_rays(rays, torch.from_numpy(T_from_xyz_yaw(0.0, 0.0, 0.0, 0.3)[None]))
    torch.testing.assert_close(turn_rays(rays, 0.3), turned, atol=1e-9, rtol=1e-9)
    ahead = torch.tensor([1.0, 0.0, 0.0, 0.0, 0.0, 1.0], dtype=torch.float64)  # along +x from (0, -1, 0)
    # turned: along +y from (1, 0, 0), whose moment (1, 0, 0) x (0, 1, 0) is still +z
    torch.testing.assert_close(turn_rays(ahead, np.pi / 2), torch.tensor([0.0, 1.0, 0, 0, 0, 1.0]).double())


def test_importing_multiview_registers_no_sublayer():
    """The cross-view sub-layer is registered where the multi-view network is built, not by an import."""
    code = (
        "from drivewm.diffusion.blocks import SUBLAYERS; import drivewm.multiview.model, drivewm.multiview.init; "
        "print(sorted(SUBLAYERS))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "['cross_attn', 'joint_attn', 'mlp', 'self_attn']"


@pytest.mark.parametrize(
    "name, content, message",
    [
        ("far.json", "[[1e200, 0, 0], [2e200, 0, 0]]", "within 10000 m of the first frame, got 2e+200 m"),
        ("nan.json", "[[1, 0, 0], [NaN, 0, 0]]", "waypoints must be finite, got NaN or inf in row 1"),
        ("text.npy", np.array([["a", "b", "c"]]), "<U1 values are not numbers of metres"),
        ("complex.npy", np.ones((2, 3)) * 1j, "complex128 values are not numbers of metres"),
        ("flags.json", "[[true, false, true]]", "bool values are not numbers of metres"),
    ],
)
def test_waypoint_files_out_of_reason_are_refused_by_name(tmp_path, name, content, message):
    """A waypoint file the network cannot use is a one-line error, not a traceback (strings) or a black
    video written with exit 0 (1e200 m overflows float32 in the trajectory encoder)."""
    path = tmp_path / name
    if name.endswith(".npy"):
        np.save(path, content)
    else:
        path.write_text(content)
    with pytest.raises(DrivewmError) as info:
        resolve_trajectory(str(path), 16, 0.1)
    assert str(info.value).startswith(str(path)) and message in str(info.value)
