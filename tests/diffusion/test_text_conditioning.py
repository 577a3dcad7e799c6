"""Text conditioning works: a debug Text2World model trained on simulated clear-day and snow clips
generates, for each prompt, clips that a simple statistic assigns to the prompted condition.

Latents: to fit the test budget the clips are coded by a fixed, lossy stand-in for the tokenizer
(every 8th video frame, 32x32 average pooling of RGB in [-1, 1]: (3, 3, 6, 10) per view), written as
a real latent cache; "decoding" upsamples them (drivewm.diffusion.generate.latents_preview). The
statistic is the eval stage's ``ground_luma`` (drivewm.eval.adherence.condition_scores: mean luma of
the bottom third, where snow cover is bright), with the decision threshold half-way between the two
conditions' means on the training clips themselves.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from einops import rearrange

from drivewm.clips import iter_clips
from drivewm.clips.latents import write_latent_clip, write_latent_index
from drivewm.diffusion.generate import latents_preview
from drivewm.diffusion.pretrain import pretrain, pretrain_config
from drivewm.diffusion.text2world import Text2World
from drivewm.eval.adherence import condition_scores

pytestmark = pytest.mark.slow  # trains a Text2World model

DRIVES = {"clear": "highway_clear", "snow": "highway_snow"}


def pooled_latents(videos: np.ndarray) -> torch.Tensor:
    """uint8 (V, T, H, W, 3) -> (V, 3, t, H/32, W/32) in [-1, 1], frames 0, 8, 16, ..."""
    x = torch.from_numpy(videos[:, ::8]).float() / 127.5 - 1
    x = rearrange(x, "v t h w c -> (v t) c h w")
    return rearrange(F.avg_pool2d(x, 32), "(v t) c h w -> v c t h w", v=videos.shape[0])


def ground_luma(video: np.ndarray) -> float:
    """The eval stage's snow-cover statistic of a uint8 (T, H, W, 3) video, 0..1."""
    return condition_scores(video)["ground_luma"]


@pytest.fixture(scope="module")
def condition_cache(sim_clip_dir: Path, tmp_path_factory) -> tuple[Path, dict[str, list[str]], dict[str, list[float]]]:
    """Latent cache of the clear and snow highway clips; their view captions and statistics by condition."""
    out = tmp_path_factory.mktemp("cond_latents")
    rows, captions, stats = [], {k: [] for k in DRIVES}, {k: [] for k in DRIVES}
    for clip in iter_clips(sim_clip_dir):
        cond = next((k for k, drive in DRIVES.items() if drive in clip.meta.source_log), None)
        if cond is None:
            continue
        z = pooled_latents(clip.videos())
        rows.append(write_latent_clip(out, clip.meta, z, clip.T_world_from_ego))
        captions[cond] += [clip.meta.view_captions.get(c, clip.meta.caption) for c in clip.meta.cameras]
        stats[cond] += [ground_luma(v) for v in latents_preview(z)]
    assert all(captions.values()), f"need clear and snow highway clips in {sim_clip_dir}"
    write_latent_index(out, {"path": None, "latent_mean": [0.0] * 3, "latent_std": [0.5] * 3}, rows)
    return out, captions, stats


@pytest.fixture(scope="module")
def trained(condition_cache, tmp_path_factory) -> Text2World:
    cache, _, _ = condition_cache
    cfg = pretrain_config(
        "debug",
        [
            "train.steps=250",
            "train.batch_size=8",
            "train.log_every=50",
            "train.checkpoint_every=1000",
            "model.hidden_dim=96",
            "model.depth=3",
            "model.num_heads=4",
            "sample_steps=4",
            "edm.text_dropout=0.2",
        ],
    )
    out = tmp_path_factory.mktemp("t2w_cond")
    pretrain(cfg, cache, None, out)
    return Text2World.from_pretrained(out)


def _classify(
    model: Text2World, captions: dict[str, list[str]], threshold: float, snow_brighter: bool, guidance: float
):
    """Generate one clip per distinct view caption of each condition; fraction assigned correctly, mean stat gap."""
    correct, means = [], {}
    for i, (cond, caps) in enumerate(captions.items()):
        prompts = sorted(set(caps))
        videos = latents_preview(
            model.sample_latents(prompts, [100 * i + j for j in range(len(prompts))], steps=12, guidance=guidance)
        )
        values = np.array([ground_luma(v) for v in videos])
        means[cond] = values.mean()
        is_snow = values > threshold if snow_brighter else values < threshold
        correct += list(is_snow if cond == "snow" else ~is_snow)
    return float(np.mean(correct)), abs(means["snow"] - means["clear"])


def test_generated_clips_follow_the_prompted_condition_and_guidance_strengthens_it(condition_cache, trained):
    _, captions, stats = condition_cache
    clear, snow = np.mean(stats["clear"]), np.mean(stats["snow"])
    assert abs(snow - clear) > 0.05, f"the statistic must separate the data first: clear {clear:.3f}, snow {snow:.3f}"
    threshold = (clear + snow) / 2
    acc_guided, gap_guided = _classify(trained, captions, threshold, snow > clear, guidance=4.0)
    acc_plain, gap_plain = _classify(trained, captions, threshold, snow > clear, guidance=1.0)
    print(
        f"clear {clear:.3f} snow {snow:.3f}; accuracy guided {acc_guided:.2f} (gap {gap_guided:.3f}), plain "
        f"{acc_plain:.2f} (gap {gap_plain:.3f})"
    )
    assert acc_guided >= 0.9, "chance is 0.5"
    assert gap_guided > gap_plain
