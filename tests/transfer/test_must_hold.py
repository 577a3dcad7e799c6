"""The must-holds of issue 18 on a small, fast configuration: train a tiny transfer model on one
simulated drive in clear and snow, transfer another drive (never seen) from clear to snow, and score
it against the simulator's own snow rendering of that drive, beside SDEdit at the same network
evaluations. The tokenizer is the fixed pooling stand-in of the multi-view tests (8x8 average
pooling, every 4th frame repeated), so the test needs no tokenizer training. Its blocky decodes
defeat the pixel-level must-holds for any method, the truth included: SIFT on 8x8 blocks matches
ambiguously (median displacement 10-25 px even between the coded truth and itself transferred),
and the adherence classifier does not call the coded true snow clip snow. So this test asserts the
image must-holds (PSNR and SSIM against the truth, over SDEdit) and leaves SIFT, CSE and adherence
to benchmarks/bench_transfer.py on real models (docs/transfer.md has the figures)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from drivewm.transfer.model import Transfer
from drivewm.transfer.retarget import TargetCondition
from drivewm.transfer.sdedit import sdedit_latents
from drivewm.transfer.train import RECIPES, train_transfer

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "multiview"))
from mv_standin import PoolTokenizer, write_pooled_cache  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from transfer_tiny import paired_clips, pooled_parent  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from transfer_benchmark import NOISE_NAME, paired_cases, run_cases, summarize  # noqa: E402

CLEAR, SNOW = TargetCondition("clear", "day"), TargetCondition("snow", "day")


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    root = tmp_path_factory.mktemp("must_hold")
    train_clips, test_clips = paired_clips(root, 21), paired_clips(root, 22)
    cache = write_pooled_cache(train_clips, root / "latents", PoolTokenizer(8))
    parent = pooled_parent(root / "t2w")
    cfg = RECIPES.resolve("debug", overrides=["train.steps=150", "train.lr=2e-3", "train.checkpoint_every=150"])
    train_transfer(cfg, root / "t2w", cache, root / "transfer")
    return Transfer.from_pretrained(root / "transfer"), parent, test_clips


@pytest.mark.slow
def test_transfer_beats_sdedit_against_the_truth(trained) -> None:
    model, parent, test_clips = trained
    cases = paired_cases(test_clips, CLEAR, [SNOW])
    assert len(cases) == 1 and cases[0].source.meta.pair_id == cases[0].target.meta.pair_id

    def transfer(z, captions, target, seeds):
        return model.transfer_latents(z, captions, [target] * len(captions), seeds, steps=4)

    methods = {"transfer": transfer}
    for s in (0.5, 2.0, 8.0):  # SDEdit at the same 4 Euler steps: the same network evaluations
        methods[f"sdedit@{s:g}"] = lambda z, c, t, seeds, s=s: sdedit_latents(parent, z, c, seeds, s, steps=4)
    summary = summarize(run_cases(cases, methods, PoolTokenizer(8)))["all"]
    best = max((m for m in summary if m.startswith("sdedit@")), key=lambda m: summary[m]["psnr"])
    ours = summary["transfer"]
    # measured after the merge of main (studies/transfer_conditioning.py): transfer 16.1 dB, best SDEdit 9.6,
    # identity (clear vs snow) 8.6, coded truth 17.9
    assert ours["psnr"] >= summary[best]["psnr"] + 3.0, summary
    assert ours["ssim"] > summary[best]["ssim"], summary
    assert ours["psnr"] >= summary["identity"]["psnr"] + 3.0, summary
    assert ours["psnr"] >= summary["tokenizer"]["psnr"] - 3.0, summary
    # the source with 1 level of noise scores to the truth what the source itself does
    assert summary[NOISE_NAME]["psnr"] == pytest.approx(summary["identity"]["psnr"], abs=0.05), summary
