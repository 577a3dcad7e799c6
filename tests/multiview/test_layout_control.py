"""The layout steers the multi-view model: a new layout path starts at zero effect, a dropped layout is
no layout, the ControlNet branch starts as a copy of the blocks it shadows, and the latent cache
carries layout latents checked like the clip's."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from drivewm.clips.format import ClipMeta
from drivewm.clips.latents import LatentCache, write_latent_clip, write_latent_index
from drivewm.errors import DrivewmError
from drivewm.geometry import load_rig
from drivewm.multiview.config import MultiViewConfig
from drivewm.multiview.init import from_text2world
from drivewm.multiview.model import MultiView
from drivewm.multiview.posttrain import continue_from
from drivewm.multiview.trajectories import resolve_trajectory

MODES = ["tokens", "controlnet"]


def _cond(model: MultiView, rig, seed: int = 0):
    v = len(rig.cameras)
    traj = resolve_trajectory("left", model.cfg.multiview.trajectory_waypoints, 0.1)[None]
    cond = model.conditioning(rig, [["a snowy highway"] * v], traj)
    g = torch.Generator().manual_seed(seed)
    x = torch.randn(v, *model.latent.latent_shape, generator=g)
    sigma = torch.exp(torch.randn(v, generator=g))
    layout = torch.randn(v, *model.latent.latent_shape, generator=g)
    return cond, x, sigma, layout


def _perturb(module: torch.nn.Module) -> None:
    with torch.no_grad():
        for p in module.parameters():
            p.add_(0.1 * torch.randn_like(p))


@pytest.mark.parametrize("mode", MODES)
def test_a_new_layout_path_starts_as_the_model_without_it(parent, mode, tmp_path):
    base = from_text2world(parent, cond_frames=1)
    _perturb(base.net)  # as after training: every zero-initialised layer has moved
    base.save_pretrained(tmp_path / "base")
    model = continue_from(base, dataclasses.replace(base.cfg.multiview, layout=mode), tmp_path / "base")
    rig = load_rig("nuscenes6")
    cond, x, sigma, layout = _cond(model, rig)
    with torch.no_grad():
        ref = base.net(x, sigma, cond)
        out = model.net(x, sigma, dataclasses.replace(cond, layout=layout))
    assert ref.abs().mean() > 0.1
    torch.testing.assert_close(out, ref, rtol=1e-5, atol=1e-5)
    if mode == "controlnet":  # the branch's blocks are the main blocks' copies
        control = model.net.dit.control.blocks[0].state_dict()
        for name, value in model.net.dit.blocks[0].state_dict().items():
            torch.testing.assert_close(control[name], value)


@pytest.mark.parametrize("mode", MODES)
def test_a_trained_layout_reaches_the_output_and_a_dropped_one_is_none(parent, mode):
    model = from_text2world(parent, MultiViewConfig(layout=mode), cond_frames=1)
    _perturb(model.net)
    rig = load_rig("front3")
    cond, x, sigma, layout = _cond(model, rig)
    with torch.no_grad():
        none = model.net(x, sigma, cond)
        given = model.net(x, sigma, dataclasses.replace(cond, layout=layout))
        other = model.net(x, sigma, dataclasses.replace(cond, layout=-layout))
        dropped = model.net(x, sigma, dataclasses.replace(cond, layout=layout, layout_keep=torch.zeros(3, dtype=bool)))
        one_dropped = model.net(
            x, sigma, dataclasses.replace(cond, layout=layout, layout_keep=torch.tensor([1, 0, 1]) > 0)
        )
    assert (given - none).abs().mean() > 1e-3 and (given - other).abs().mean() > 1e-3
    torch.testing.assert_close(dropped, none)  # a dropped layout is the model's "no layout"
    assert 1e-4 < (one_dropped - given).abs().mean() < (none - given).abs().mean()


def test_a_model_without_layout_refuses_one_and_a_bad_config_is_named(parent):
    plain = from_text2world(parent, cond_frames=1)
    rig = load_rig("front1")
    with pytest.raises(DrivewmError, match="not trained with a layout"):
        plain.sample_latents(rig, [["x"]], None, [0], steps=1, layout_latents=torch.zeros(1, 1, 4, 3, 4, 6))
    with pytest.raises(DrivewmError, match="layout must be none, tokens or controlnet"):
        MultiViewConfig(layout="boxes").validate()
    cfg = dataclasses.replace(plain.cfg, multiview=MultiViewConfig(layout="controlnet"))
    with pytest.raises(DrivewmError, match="control_depth 0"):
        MultiView(cfg, plain.latent)


def test_sampling_with_a_layout_follows_it(parent):
    model = from_text2world(parent, MultiViewConfig(layout="tokens"), cond_frames=1)
    _perturb(model.net)
    rig = load_rig("front1")
    layout = torch.randn(1, 1, *model.latent.latent_shape, generator=torch.Generator().manual_seed(3))
    kw = dict(steps=3, guidance=1.0)
    a = model.sample_latents(rig, [["snow"]], None, [7], layout_latents=layout, **kw)
    b = model.sample_latents(rig, [["snow"]], None, [7], layout_latents=layout, **kw)
    c = model.sample_latents(rig, [["snow"]], None, [7], **kw)
    torch.testing.assert_close(a, b)  # seeded
    assert (a - c).abs().mean() > 1e-3


def _meta(key: str, frames: int = 9) -> ClipMeta:
    rig = load_rig("front1").to_dict()
    return ClipMeta(key, "synthetic", 0, 10.0, [int(j * 1e8) for j in range(frames)], rig, caption="x")


def test_the_latent_cache_carries_layout_latents_checked_like_the_clips(tmp_path):
    z = torch.randn(1, 4, 3, 4, 6)
    poses = np.tile(np.eye(4), (9, 1, 1))
    rows = [
        write_latent_clip(tmp_path, _meta("with"), z, poses, layout_latents=2 * z),
        write_latent_clip(tmp_path, _meta("without"), z, poses),
    ]
    write_latent_index(tmp_path, {"path": None, "latent_mean": [0.0] * 4, "latent_std": [1.0] * 4}, rows)
    cache = LatentCache(tmp_path)
    torch.testing.assert_close(cache[0].layout_latents, 2 * z)
    assert cache[1].layout_latents is None
    with pytest.raises(DrivewmError, match="layout_latents must be the clip's"):
        write_latent_clip(tmp_path, _meta("bad"), z, poses, layout_latents=z[:, :2])
    with pytest.raises(DrivewmError, match="NaN or infinite layout_latents"):
        write_latent_clip(tmp_path, _meta("nan"), z, poses, layout_latents=z * float("nan"))
