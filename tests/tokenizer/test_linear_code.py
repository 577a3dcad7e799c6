"""The PCA linear code beside the tokenizer's networks (drivewm.tokenizer.linear_code).

The untrained ``linear_code=pca`` tokenizer must *be* the PCA codec of 4x8x8x3 pixel blocks: its
reconstruction is compared with a NumPy principal-component projection of the same blocks, built
without the Haar patch, so a wrong fold order, a non-orthonormal patch or a head that is not
silent fails it. Causality (chunked = one pass) holds for the linear path too.
"""

import json

import numpy as np
import pytest
import torch
from tokenizer_synthetic import road_video, write_synthetic_clips

from drivewm.errors import DrivewmError
from drivewm.tokenizer import Tokenizer, preset
from drivewm.tokenizer.causal import CausalContext
from drivewm.tokenizer.data import to_model_range
from drivewm.tokenizer.recipe import RECIPES
from drivewm.tokenizer.train import tokenizer_train


def pca_tokenizer(size: str, *videos: torch.Tensor, compression: str = "4x8x8") -> Tokenizer:
    cfg = preset(size, compression)
    cfg.linear_code = "pca"
    torch.manual_seed(0)
    tok = Tokenizer(cfg).eval()
    tok.linear.fit([tok.patch(v) for v in videos])
    return tok


def road(T: int = 9, seed: int = 0) -> torch.Tensor:
    """(1, 3, T, 48, 80) in [-1, 1]: a synthetic road scene in motion."""
    return to_model_range(road_video(T, 48, 80, seed))[None]


def numpy_pca_reconstruction(video: np.ndarray, channels: int) -> np.ndarray:
    """Frames 1.. of ``video`` (3, T, H, W), T = 1 + 4k, coded by the top ``channels`` principal
    components of its 4x8x8x3 pixel blocks; the fit includes frame 0 as a block of four copies."""
    padded = np.concatenate([np.repeat(video[:, :1], 3, axis=1), video], axis=1)  # (3, 4 + 4k, H, W)
    c, t, h, w = padded.shape
    blocks = padded.reshape(c, t // 4, 4, h // 8, 8, w // 8, 8).transpose(1, 3, 5, 0, 2, 4, 6).reshape(-1, c * 256)
    mean = blocks.mean(0)
    _, _, vt = np.linalg.svd(blocks - mean, full_matrices=False)
    coded = (blocks - mean) @ vt[:channels].T @ vt[:channels] + mean
    coded = coded.reshape(t // 4, h // 8, w // 8, c, 4, 8, 8).transpose(3, 0, 4, 1, 5, 2, 6).reshape(c, t, h, w)
    return coded[:, 4:]


def test_untrained_pca_tokenizer_is_the_pca_codec_of_pixel_blocks():
    video = road()
    tok = pca_tokenizer("tiny", video)
    with torch.no_grad():
        recon, latents = tok(video)
    assert latents.shape == (1, 16, 3, 6, 10)
    expected = numpy_pca_reconstruction(video[0].double().numpy(), 16)
    assert np.abs(recon[0, :, 1:].double().numpy() - expected).max() < 1e-4
    basis = tok.linear.basis.detach()
    assert torch.allclose(basis @ basis.T, torch.eye(16), atol=1e-5)  # orthonormal rows


def test_pca_start_beats_the_block_average_start_on_unseen_frames():
    # fitted on four synthetic drives, scored on a fifth: the linear code generalizes, and it starts
    # well above the default network's untrained block-average codec (measured 24.4 against 20.3 dB)
    fit, scored = [road(9, seed=s) for s in range(4)], road(9, seed=9)
    tok = pca_tokenizer("tiny", *fit)
    torch.manual_seed(0)
    plain = Tokenizer(preset("tiny")).eval()
    with torch.no_grad():
        pca_mse = (tok(scored)[0] - scored).pow(2).mean().item()
        plain_mse = (plain(scored)[0] - scored).pow(2).mean().item()
    pca_db, plain_db = 10 * np.log10(4 / pca_mse), 10 * np.log10(4 / plain_mse)
    assert pca_db > 23 and pca_db > plain_db + 3, (pca_db, plain_db)


@pytest.mark.parametrize("compression", ["4x8x8", "8x8x8"])
def test_linear_path_is_causal_chunked_equals_one_pass(compression):
    video = road(17)
    tok = pca_tokenizer("debug", video, compression=compression)
    f = tok.config.temporal_compression
    with torch.no_grad():
        whole = tok.encode(video)
        ctx = CausalContext()
        first = tok.encode(video[:, :, : 1 + f], ctx)
        ctx.next_chunk()
        rest = tok.encode(video[:, :, 1 + f :], ctx)
        assert torch.allclose(torch.cat([first, rest], 2), whole, atol=1e-4)
        ctx = CausalContext()
        head = tok.decode(whole[:, :, :2], ctx)
        ctx.next_chunk()
        tail = tok.decode(whole[:, :, 2:], ctx)
        assert torch.allclose(torch.cat([head, tail], 2), tok.decode(whole), atol=1e-4)


def test_pca_code_saves_and_loads(tmp_path):
    video = road()
    tok = pca_tokenizer("debug", video)
    tok.save_pretrained(tmp_path / "tok")
    loaded = Tokenizer.from_pretrained(tmp_path / "tok")
    assert loaded.config.linear_code == "pca"
    with torch.no_grad():
        assert torch.equal(loaded(video)[0], tok(video)[0])


def test_bad_linear_code_settings_are_refused():
    cfg = preset("debug", fsq=True)
    cfg.linear_code = "pca"
    with pytest.raises(DrivewmError, match="continuous latents"):
        Tokenizer(cfg)
    with pytest.raises(DrivewmError, match="'svd' is not one of \\['none', 'pca'\\]"):
        RECIPES.resolve("debug", None, ["model.linear_code=svd"])


def test_training_fits_the_code_then_resumes_exactly(tmp_path):
    # the fit is repeated on resume and then replaced by the checkpoint's trained code, so a run
    # killed after its step-3 checkpoint ends bit-equal to one that was not
    clips = write_synthetic_clips(tmp_path / "clips", clips=2, T=9, H=48, W=80)
    overrides = ["model.linear_code=pca", "train.batch_size=2", "data.frames=5", "data.crop=[32,48]"]
    overrides += ["data.holdout_percent=0", "data.linear_fit_batches=4", "data.stats_batches=1"]
    overrides += ["train.steps=6", "train.checkpoint_every=3", "train.log_every=1"]
    cfg = RECIPES.resolve("debug", None, overrides)
    tokenizer_train(cfg, clips, tmp_path / "straight")
    tokenizer_train(cfg, clips, tmp_path / "resumed", stop_after=3)
    tokenizer_train(cfg, clips, tmp_path / "resumed")
    a = torch.load(tmp_path / "straight" / "train_state.pt", weights_only=True)
    b = torch.load(tmp_path / "resumed" / "train_state.pt", weights_only=True)
    for part in ("model", "ema"):
        for key in a[part]:
            assert torch.equal(a[part][key], b[part][key]), (part, key)
    basis = a["model"]["linear.basis"]
    assert basis.shape == (16, 768)
    assert torch.allclose(basis @ basis.T, torch.eye(16), atol=0.05)  # fitted, then trained a little
    rows = [json.loads(line) for line in (tmp_path / "straight" / "metrics.jsonl").read_text().splitlines()]
    assert rows[0]["psnr"] > 20  # step 1 codes with the fitted PCA: 22.4 dB (the block-average start: 17.6)
