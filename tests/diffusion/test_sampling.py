"""One sampling function for Text2World and multi-view models: outputs unchanged from the two copies
it replaced, per-sample seeding, and the guidance terms it composes."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from drivewm.diffusion.denoiser import Conditioning, EDMConfig
from drivewm.diffusion.dit_config import DiTConfig
from drivewm.diffusion.samplers import seeded_noise
from drivewm.diffusion.sampling import guided, sample
from drivewm.diffusion.text2world import LatentInfo, Text2World, Text2WorldConfig
from drivewm.errors import DrivewmError
from drivewm.geometry import load_rig
from drivewm.multiview.config import MultiViewConfig
from drivewm.multiview.init import from_text2world
from drivewm.multiview.trajectories import resolve_trajectory

#: (sum, sum of squares, first six values) of each sample below, recorded with the code before the
#: sampling function was shared (commit c5bca50: Text2World.sample_latents and MultiView.sample_latents
#: each with its own noise/guidance/sampler code), on the model layout of that time (self + cross attn).
RECORDED = {
    "t2w": [106.182036, 8616.919967, [-0.498339, 4.000095, -3.393855, 2.253785, 2.00132, -1.627855]],
    "t2w_v2w_euler": [24.199014, 91.276254, [-0.410067, 0.197816, 0.449454, -0.694202, -0.083498, 0.142575]],
    "mv": [-356.547507, 14750.641839, [-2.400354, -2.238795, 3.956546, -9.536656, 7.503395, -3.090447]],
    "mv_v2w_traj_guided": [
        -320.288818,
        9767.935905,
        [-0.594601, 0.696617, 1.052949, -0.177284, 0.185495, 0.547842],
    ],
}
CAPTIONS = [["front left snow", "front snow", "front right snow"]]


def tiny(seed: int, cond_frames: int = 0) -> Text2World:
    """A random Text2World model in the layout of c5bca50, every weight perturbed (as after training)."""
    torch.manual_seed(seed)
    dit = DiTConfig(
        in_channels=4,
        hidden_dim=48,
        depth=2,
        num_heads=4,
        adaln_lora_dim=8,
        block_layers=["self_attn", "cross_attn", "mlp"],
        mlp_activation="gelu_tanh",
        cond_mask_channel=cond_frames > 0,
    )
    rig = load_rig("front1").to_dict()
    model = Text2World(
        Text2WorldConfig(dit, EDMConfig(parameterization="edm", cond_frames=cond_frames)),  # as recorded
        LatentInfo([4, 3, 4, 6], [0.1] * 4, [0.9] * 4, 10.0, None, rig),
    )
    with torch.no_grad():
        for p in model.dit.parameters():
            p.add_(0.05 * torch.randn_like(p))
    return model


def tiny_multiview():
    # the recorded samples' model: moving rays, no per-frame motion (the shipped model's are the defaults)
    mv = from_text2world(tiny(2), MultiViewConfig(frame_motion=False, moving_camera_rays=True), cond_frames=1)
    with torch.no_grad():
        for p in mv.net.parameters():
            p.add_(0.05 * torch.randn_like(p))
    return mv


def _assert_recorded(z: torch.Tensor, name: str) -> None:
    total, squares, first = RECORDED[name]
    z = z.double()
    # Sums over ~10^3 values of magnitude ~1-10: float32 reordering (fused ops, complex RoPE) moves them ~1e-5.
    assert z.sum().item() == pytest.approx(total, rel=1e-4, abs=1e-3), name
    assert (z**2).sum().item() == pytest.approx(squares, rel=1e-5), name
    torch.testing.assert_close(z.flatten()[:6], torch.tensor(first, dtype=torch.float64), rtol=1e-4, atol=2e-4)


def test_text2world_samples_are_unchanged_for_fixed_seeds():
    model = tiny(0)
    _assert_recorded(model.sample_latents(["clear day on a highway", "heavy snow at night"], [3, 4], 3, 3.0), "t2w")
    model = tiny(1, cond_frames=1)
    cond = 0.5 * torch.randn(2, 4, 3, 4, 6, generator=torch.Generator().manual_seed(7))
    z = model.sample_latents(["fog", "rain"], [5, 6], 3, 2.0, "euler", cond_latents=cond)
    _assert_recorded(z, "t2w_v2w_euler")


def test_multiview_samples_are_unchanged_for_fixed_seeds():
    mv = tiny_multiview()
    rig, waypoints = load_rig("front3"), resolve_trajectory("left", 16, 0.1, 10.0)[None]
    _assert_recorded(mv.sample_latents(rig, CAPTIONS, waypoints, [9], steps=3, guidance=3.0), "mv")
    cond = 0.5 * torch.randn(1, 3, 4, 3, 4, 6, generator=torch.Generator().manual_seed(8))
    z = mv.sample_latents(rig, CAPTIONS, waypoints, [10], 3, 2.0, cond_latents=cond, trajectory_guidance=2.0)
    _assert_recorded(z, "mv_v2w_traj_guided")


def test_a_sample_does_not_depend_on_its_batch():
    model = tiny(0)
    both = model.sample_latents(["fog", "snow"], [11, 12], steps=2, guidance=2.0)
    alone = model.sample_latents(["snow"], [12], steps=2, guidance=2.0)
    torch.testing.assert_close(both[1:], alone, rtol=1e-4, atol=1e-4)  # batched matmuls round differently
    mv, rig = tiny_multiview(), load_rig("front3")
    waypoints = resolve_trajectory("right", 16, 0.1, 10.0)[None]
    pair = mv.sample_latents(rig, CAPTIONS * 2, waypoints.repeat(2, 0), [3, 4], steps=2, guidance=2.0)
    single = mv.sample_latents(rig, CAPTIONS, waypoints, [4], steps=2, guidance=2.0)
    torch.testing.assert_close(pair[1:], single, rtol=1e-3, atol=1e-2)  # values ~4 rms; other seeds: O(1) apart


def test_guidance_terms_compose_caption_then_trajectory():
    """With D = base + caption term + trajectory term, caption guidance w_c and trajectory guidance
    w_t give base + w_c * caption + w_t * trajectory (each branch of the trajectory term caption-guided)."""

    @dataclasses.dataclass
    class Cond(Conditioning):
        has_trajectory: bool = True

        def without_trajectory(self):
            return dataclasses.replace(self, has_trajectory=False)

    class Toy(torch.nn.Module):
        def forward(self, x, sigma, cond):
            return x + cond.text_mask.float().any(1).view(-1, 1) * 1.0 + float(cond.has_trajectory) * 10.0

    cond = Cond(torch.zeros(2, 3, 4), torch.ones(2, 3, dtype=torch.bool), torch.full((2,), 10.0))
    x = torch.zeros(2, 1)
    assert torch.allclose(guided(Toy(), 3.0, 2.0)(x, torch.ones(2), cond), torch.full((2, 1), 3.0 + 20.0))
    assert torch.allclose(guided(Toy(), 3.0)(x, torch.ones(2), cond), torch.full((2, 1), 3.0 + 10.0))


def test_an_sdedit_start_is_the_guide_noised_to_start_sigma_with_each_samples_own_noise():
    """SDEdit (Meng et al. 2022, sec. 3): the first call sees x_g + sigma(t0) z at sigma(t0), z from the
    sample's seed, and the schedule runs down from there in ``steps`` calls."""
    guide = torch.randn(2, 4, 3, 4, 6, generator=torch.Generator().manual_seed(1))
    cond = tiny(0).conditioning(["snow", "fog"])
    calls = []

    def record(x, sigma, cond):
        calls.append((x.clone(), sigma.clone()))
        return torch.zeros_like(x)

    sample(record, cond, (4, 3, 4, 6), [5, 6], steps=3, guidance=1.0, sampler="euler", start=guide, start_sigma=2.0)
    (x_first, sigma_first), (_, sigma_second) = calls[0], calls[1]
    assert len(calls) == 3 and torch.equal(sigma_first, torch.full((2,), 2.0)) and (sigma_second < 2.0).all()
    torch.testing.assert_close(x_first, guide + 2.0 * seeded_noise((2, 4, 3, 4, 6), [5, 6]))
    with pytest.raises(DrivewmError, match="start_sigma"):
        sample(record, cond, (4, 3, 4, 6), [5, 6], steps=3, start=guide)


def test_a_saved_folder_naming_no_parameterization_loads_as_the_edm_it_was_trained_with(tmp_path):
    """Flow became the default after EDM folders were written without the key: such a folder (and the
    multi-view model made from it) still loads, and samples, as EDM; a folder naming flow loads as flow."""
    import json

    model = tiny(0)
    model.save_pretrained(tmp_path / "old")
    path = tmp_path / "old" / "config.json"
    info = json.loads(path.read_text())
    del info["config"]["edm"]["parameterization"]
    path.write_text(json.dumps(info))
    old = Text2World.from_pretrained(tmp_path / "old")
    assert old.cfg.edm.parameterization == "edm" and EDMConfig().parameterization == "flow"
    torch.testing.assert_close(old.sample_latents(["snow"], [3], steps=2), model.sample_latents(["snow"], [3], steps=2))
    flow = tiny(0)
    flow.cfg = dataclasses.replace(flow.cfg, edm=EDMConfig(parameterization="flow"))
    flow.save_pretrained(tmp_path / "flow")
    assert Text2World.from_pretrained(tmp_path / "flow").cfg.edm.parameterization == "flow"


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda i: i["latent"].update(latent_std=[0.0] * 4), "latent: latent_std must be > 0"),
        (lambda i: i["latent"].update(latent_std=[1.0]), "latent: latent_std must be 4 numbers (c), got [1.0]"),
        (lambda i: i["latent"].update(latent_mean=[1.0, 2.0]), "latent: latent_mean must be 4 numbers (c)"),
        (lambda i: i["latent"].update(latent_shape=[4, 3, 4]), "latent_shape must be 4 sizes (c, t, h, w) >= 1"),
        (lambda i: i["latent"].update(latent_shape=[4, -3, 4, 6]), "latent_shape must be 4 sizes (c, t, h, w) >= 1"),
        (lambda i: i["latent"].update(fps=0), "latent: fps must be a frame rate in [1/60, 1000] Hz, got 0.0"),
        (lambda i: i.update(config=5), "'config' must be a mapping of the network's settings, got 5"),
        (lambda i: i.pop("config"), "'config' must be a mapping of the network's settings, got None"),
        (lambda i: i["config"].update(dit=5), "config.json.dit: expected a mapping, got 5"),
        (lambda i: i["latent"].update(latent_shape=[4, 3, 5, 6]), "latent_shape [4, 3, 5, 6] does not fit the network"),
        (lambda i: i["config"]["dit"].update(in_channels=8), "does not fit the network (in_channels 8,"),
    ],
)
def test_a_hand_edited_config_json_is_refused_naming_the_value(tmp_path, edit, message):
    """A config.json whose latent statistics or sections make no sense is a one-line error when the folder
    loads: before, a latent_std of 0 sampled flat videos with exit 0, and the rest ended in tracebacks (a
    latent_shape the DiT cannot patchify or whose channels are not its in_channels: at the first sample)."""
    import json

    tiny(0).save_pretrained(tmp_path / "m")
    path = tmp_path / "m" / "config.json"
    info = json.loads(path.read_text())
    edit(info)
    path.write_text(json.dumps(info))
    with pytest.raises(DrivewmError) as error:
        Text2World.from_pretrained(tmp_path / "m")
    assert str(tmp_path / "m") in str(error.value) and message in str(error.value)


def test_guidance_in_an_interval_guides_only_the_steps_inside_it_with_one_evaluation_elsewhere():
    """Kynkaenniemi et al. 2024: guidance only for sigma in (lo, hi]. A toy denoiser whose caption adds
    1 records every call: inside the interval the step sees base + w, outside base + 1 from one call."""
    cond = tiny(0).conditioning(["snow"])
    calls = []

    def toy(x, sigma, c):
        calls.append((float(sigma[0]), bool(c.text_mask.any())))
        return torch.zeros_like(x) + c.text_mask.float().any(1).view(-1, *[1] * (x.ndim - 1))

    def run(interval):
        calls.clear()
        sample(toy, cond, (1, 1, 2, 2), [3], steps=8, guidance=5.0, sampler="euler", guidance_interval=interval)
        return list(calls)

    everywhere = run(None)
    assert len(everywhere) == 16 and sum(c for _, c in everywhere) == 8  # two calls a step
    inside = run((0.28, 5.42))
    sigmas = [s for s, c in inside if c]
    guided_steps = [s for s in sigmas if 0.28 < s <= 5.42]
    assert len(inside) == 8 + len(guided_steps)  # the uncaptioned call only where guided
    assert 0 < len(guided_steps) < 8
    assert len(run((100.0, 200.0))) == 8  # nothing inside: the conditional model alone

    guided_model = guided(toy, 5.0, interval=(1.0, 2.0))
    x = torch.zeros(1, 1, 1, 2, 2)
    assert guided_model(x, torch.full((1,), 1.5), cond).flatten()[0].item() == pytest.approx(5.0)
    assert guided_model(x, torch.full((1,), 2.5), cond).flatten()[0].item() == pytest.approx(1.0)
    assert guided_model(x, torch.full((1,), 1.0), cond).flatten()[0].item() == pytest.approx(1.0)  # (lo, hi]


def test_a_sample_guided_everywhere_by_interval_equals_plain_guidance_and_a_narrow_one_differs():
    model = tiny(0)
    plain = model.sample_latents(["heavy snow at night"], [4], 4, 3.0)
    wide = model.sample_latents(["heavy snow at night"], [4], 4, 3.0, guidance_interval=(0.0, 1e3))
    torch.testing.assert_close(wide, plain)
    narrow = model.sample_latents(["heavy snow at night"], [4], 4, 3.0, guidance_interval=(0.28, 5.42))
    unguided = model.sample_latents(["heavy snow at night"], [4], 4, 1.0)
    assert (narrow - plain).abs().max() > 1e-3 and (narrow - unguided).abs().max() > 1e-3


@pytest.mark.parametrize("interval", [(5.0, 1.0), (-1.0, 2.0), (float("nan"), 2.0), (1.0, float("inf")), ("a", 1)])
def test_a_bad_guidance_interval_is_refused_by_name(interval):
    with pytest.raises(DrivewmError, match="guidance interval"):
        sample(lambda x, s, c: x, tiny(0).conditioning(["fog"]), (1, 1, 2, 2), [0], 2, guidance_interval=interval)
