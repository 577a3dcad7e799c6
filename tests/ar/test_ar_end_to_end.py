"""``drivewm ar train`` then ``drivewm ar eval`` and the generator, on a synthetic FSQ token cache."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from ar_synthetic import make_token_cache, make_tokenizer

from drivewm.ar.generator import ARGenerator
from drivewm.ar.sampling_config import TokenSampling
from drivewm.cli import main
from drivewm.clips.format import ClipMeta, clip_from_arrays
from drivewm.clips.shards import ShardWriter
from drivewm.geometry import load_rig
from drivewm.multiview.trajectories import named_poses


@pytest.mark.slow
def test_train_resume_eval_and_generate(tmp_path):
    tok = make_tokenizer(tmp_path / "tok")
    make_token_cache(tmp_path / "clips", tok, clips=256)
    out = tmp_path / "ar"
    base = ["ar", "train", "--data", str(tmp_path / "clips"), "--tokenizer", str(tok), "--out", str(out)]
    sets = [
        "model.hidden_dim=64",
        "model.depth=2",
        "model.max_frames=3",
        "train.batch_size=8",
        "train.lr=3e-3",
        "train.ema_decay=0.9",
        "data.holdout_percent=25",
    ]
    argv = base + [a for s in sets for a in ("--set", s)]
    assert main(argv + ["--set", "train.steps=40", "--set", "train.checkpoint_every=20"]) == 0
    assert main(argv + ["--set", "train.steps=80", "--set", "train.checkpoint_every=20"]) == 0  # resumes at 40
    rows = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    assert rows[-1]["step"] == 80 and rows[-1]["bits_per_token"] < rows[0]["bits_per_token"]

    assert (
        main(
            [
                "ar",
                "eval",
                "--model",
                str(out),
                "--data",
                str(tmp_path / "clips"),
                "--holdout-percent",
                "25",
                "--out",
                str(tmp_path / "eval"),
            ]
        )
        == 0
    )
    metrics = json.loads((tmp_path / "eval" / "metrics.json").read_text())
    # it learns: below the unigram baseline (the real run's 15% margin over the stronger baseline is in
    # docs/results.md; copying needs more steps than a test affords)
    assert metrics["copy"] < metrics["unigram"] and metrics["model"] < 0.97 * metrics["unigram"]

    gen = ARGenerator(out)
    rig = load_rig("front1").scaled(24, 16, fit="stretch")
    poses = named_poses("left", 1 + 2 * 8, 0.1)
    video = torch.rand(1, 3, 5, 16, 24) * 2 - 1
    window = gen.video2world(video, "a highway by day", rig, poses[:9], TokenSampling(top_k=20), seed=0)
    assert window.shape == (1, 3, 9, 16, 24) and window.abs().max() <= 1
    again = gen.video2world(video, "a highway by day", rig, poses[:9], TokenSampling(top_k=20), seed=0)
    assert torch.equal(window, again)
    chunks = gen.rollout(video[:, :, :1], "a highway by day", rig, poses, 2, TokenSampling(), seed=0)
    assert [c.shape[2] for c in chunks] == [9, 9]
    assert np.array_equal(chunks[1][:, :, 0].shape, chunks[0][:, :, -1].shape)

    shard = write_clip(tmp_path / "real", rig, poses)  # drivewm generate / rollout choose the AR generator
    assert (
        main(
            [
                "generate",
                "--model",
                str(out),
                "--condition-clip",
                str(shard),
                "--prompt",
                "a highway by day",
                "--out",
                str(tmp_path / "gen"),
                "--set",
                "tokens.top_k=20",
            ]
        )
        == 0
    )
    assert (
        main(
            [
                "rollout",
                "--model",
                str(out),
                "--clip",
                str(shard),
                "--out",
                str(tmp_path / "roll"),
                "--set",
                "rollout.windows=2",
            ]
        )
        == 0
    )
    manifest = [json.loads(line) for line in (tmp_path / "roll" / "manifest.jsonl").read_text().splitlines()]
    assert manifest[0]["rollout_of"] == "real000" and manifest[0]["tokens"]["top_k"] == 0


def write_clip(out_dir, rig, poses):
    """One 9-frame clip of random pixels at the tokenizer's 16 x 24 size, as a shard."""
    out_dir.mkdir(parents=True)
    frames = {cam: np.random.default_rng(0).integers(0, 255, (9, 16, 24, 3), dtype=np.uint8) for cam in rig.names}
    meta = ClipMeta(
        "real000", "synthetic", 0, 10.0, [j * 100_000_000 for j in range(9)], rig.to_dict(), caption="a highway by day"
    )
    with ShardWriter(out_dir, "real") as writer:
        writer.write(clip_from_arrays(meta, frames, poses[:9]))
    return sorted(out_dir.glob("*.tar"))[0]
