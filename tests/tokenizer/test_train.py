"""Training on simulated clips, held-out reconstruction, FSQ codebook use, exact resume, CLI.

PSNR bound (held-out simulated clips, the debug size at 4x8x8 (0.12M parameters), 100 steps of 4 crops of
64x96x9 at the preset's lr 3e-3): the untrained network is by construction a block-average codec
(identity-initialized ends, zero-initialized residual branches, averaging shortcuts), which
scores 21.3 dB (SSIM 0.49) on these clips; 100 steps must add at least 1.5 dB and reach 23 dB
(measured: 24.2 dB, SSIM 0.68). The bound proves that training reduces held-out error well
beyond its starting codec, which a broken loss, causal mask or data path would not; the shipped
tokenizer's quality is measured by benchmarks/bench_tokenizer.py and its model card.
"""

import dataclasses
import json

import pytest
import torch
from tokenizer_synthetic import write_synthetic_clips

from drivewm.cli import main
from drivewm.clips.latents import LatentCache
from drivewm.errors import DrivewmError
from drivewm.tokenizer import Tokenizer, preset
from drivewm.tokenizer.data import load_clips
from drivewm.tokenizer.evaluate import evaluate_tokenizer
from drivewm.tokenizer.latent_cache import clip_video
from drivewm.tokenizer.losses import LossConfig, TokenizerLoss
from drivewm.tokenizer.metrics import psnr
from drivewm.tokenizer.recipe import RECIPES, TokenizerTrainConfig
from drivewm.tokenizer.tiling import TilingConfig, decode_tiled, encode_tiled
from drivewm.tokenizer.train import load_parent, tokenizer_train

pytestmark = pytest.mark.slow  # trains tokenizers

HOLDOUT = 25  # percent of clips held out by key hash: 3 of the 12 simulated clips
VIEWS = 2  # cameras scored per held-out clip (evaluation at 192x320 dominates the test time)


def run_config(steps: int, *overrides: str, compression: str = "4x8x8", fsq: bool = False) -> TokenizerTrainConfig:
    """A debug-size run of ``steps`` on small crops."""
    base = ["train.batch_size=4", "data.frames=9", "data.crop=[64,96]", f"data.holdout_percent={HOLDOUT}"]
    base += [f"train.steps={steps}", "train.checkpoint_every=50", "train.log_every=10"]
    return RECIPES.resolve("debug", None, [*base, *overrides], {"compression": compression, "fsq": fsq})


@pytest.fixture(scope="module")
def trained(sim_clip_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("tok") / "debug"
    tokenizer_train(run_config(100), sim_clip_dir, out)
    return out


def test_trained_debug_model_reconstructs_heldout_sim_clips(trained, sim_clip_dir, tmp_path):
    torch.manual_seed(0)
    Tokenizer(preset("debug")).save_pretrained(tmp_path / "untrained")
    before = evaluate_tokenizer(
        tmp_path / "untrained", sim_clip_dir, tmp_path / "e0", "holdout", HOLDOUT, max_views=VIEWS, progress=False
    )
    after = evaluate_tokenizer(
        trained, sim_clip_dir, tmp_path / "e1", "holdout", HOLDOUT, max_views=VIEWS, progress=False
    )
    assert after["clips_scored"] == 3
    assert after["psnr"] > 23.0 and after["psnr"] > before["psnr"] + 1.5, (before["psnr"], after["psnr"])
    assert after["ssim"] > before["ssim"] + 0.15
    assert after["temporal_l1"] < before["temporal_l1"]
    assert after["compression_ratio"] == pytest.approx(3 * 17 * 64 / (16 * 5))
    assert (tmp_path / "e1" / "side_by_side.png").stat().st_size > 10_000
    written = json.loads((tmp_path / "e1" / "metrics.json").read_text())
    assert written["psnr"] == after["psnr"] and len(written["clips"]) == 3
    tok = Tokenizer.from_pretrained(trained)  # latent statistics came with the model folder
    assert (tok.latent_std > 0).all() and not torch.equal(tok.latent_std, torch.ones_like(tok.latent_std))


def test_tiled_and_chunked_equal_one_pass_on_trained_model(trained, sim_clip_dir):
    tok = Tokenizer.from_pretrained(trained)
    video = clip_video(load_clips(sim_clip_dir, "holdout", HOLDOUT)[0])[:2]  # (2, 3, 17, 192, 320)
    with torch.no_grad():
        z = tok.encode(video)
        recon = tok.decode(z)
    tiling = TilingConfig(chunk_latent_frames=2, tile_latent=16, overlap_latent=6)  # 2x3 tiles, 3 time chunks
    z_tiled = encode_tiled(tok, video, tiling)
    recon_tiled = decode_tiled(tok, z, tiling)
    assert (z_tiled - z).abs().mean() < 0.02 * z.abs().mean()
    assert psnr(recon_tiled, recon) > 40.0  # tiles blend to the one-pass result within 1% of the range
    assert psnr(decode_tiled(tok, z_tiled, tiling), recon) > 35.0


def test_fsq_variant_uses_its_codebook(sim_clip_dir, tmp_path):
    # 40 steps; the 1,000-code debug codebook ([8, 5, 5, 5]) on 3 held-out clips x 2 views (14,400 code positions):
    # measured ~11% of the codes used (14.5% with all 6 views); a collapsed quantizer would use a handful
    tokenizer_train(run_config(40, fsq=True), sim_clip_dir, tmp_path / "fsq")
    metrics = evaluate_tokenizer(
        tmp_path / "fsq", sim_clip_dir, tmp_path / "eval", "holdout", HOLDOUT, max_views=VIEWS, progress=False
    )
    print("fsq codebook usage", metrics["codebook_usage"], "psnr", metrics["psnr"])
    assert metrics["codebook_usage"] > 0.08, metrics["codebook_usage"]
    assert metrics["bits_per_pixel"] == pytest.approx(5 * 24 * 40 * 9.9658 / (17 * 192 * 320), rel=1e-3)
    assert metrics["psnr"] > 18.0


def test_resume_continues_exactly(sim_clip_dir, tmp_path):
    # with the adversarial term on from step 1, so the discriminator and its optimizer resume too
    small = ["train.batch_size=2", "data.frames=5", "data.crop=[32,48]", "train.checkpoint_every=2"]
    small += ["data.stats_batches=1", "loss.adversarial=0.1", "loss.adversarial_start=1", "train.log_every=1"]
    cfg = run_config(4, *small)
    tokenizer_train(cfg, sim_clip_dir, tmp_path / "straight")
    tokenizer_train(cfg, sim_clip_dir, tmp_path / "resumed", stop_after=2)  # "killed" after the step-2 checkpoint
    assert torch.load(tmp_path / "resumed" / "train_state.pt", weights_only=True)["step"] == 2
    tokenizer_train(cfg, sim_clip_dir, tmp_path / "resumed")
    a = torch.load(tmp_path / "straight" / "train_state.pt", weights_only=True)
    b = torch.load(tmp_path / "resumed" / "train_state.pt", weights_only=True)
    assert a["step"] == b["step"] == 4
    for part in ("model", "ema"):
        for key in a[part]:
            assert torch.equal(a[part][key], b[part][key]), (part, key)
    for key in a["task"]["adversary"]["disc"]:
        assert torch.equal(a["task"]["adversary"]["disc"][key], b["task"]["adversary"]["disc"][key]), key
    rows = [json.loads(line) for line in (tmp_path / "straight" / "metrics.jsonl").read_text().splitlines()]
    resumed = [json.loads(line) for line in (tmp_path / "resumed" / "metrics.jsonl").read_text().splitlines()]
    assert [r["step"] for r in resumed] == [1, 2, 3, 4]  # no duplicated rows past the resume step
    assert [r["loss"] for r in rows] == [r["loss"] for r in resumed]
    assert "adversarial" in rows[-1] and "discriminator" in rows[-1] and "psnr" in rows[-1]
    with pytest.raises(DrivewmError, match="different model"):
        tokenizer_train(run_config(6, *small, "data.frames=9", compression="8x8x8"), sim_clip_dir, tmp_path / "resumed")


def test_cli_encode_decode_eval(trained, sim_clip_dir, tmp_path, capsys):
    clips = tmp_path / "clips"
    clips.mkdir()
    for shard in sorted(sim_clip_dir.glob("*.tar"))[:1]:
        (clips / shard.name).symlink_to(shard)
    write_synthetic_clips(clips, clips=1, T=17, H=100, W=160)  # a clip whose height is no multiple of 8
    assert main(["tokenizer", "encode", "--model", str(trained), "--data", str(clips), "--name", "dbg"]) == 0
    assert "skipped syn000: video is 100x160" in capsys.readouterr().out  # reported, the others kept
    cache = LatentCache(clips / "latents" / "dbg")
    assert len(cache) == 3
    item = cache[0]
    tok = Tokenizer.from_pretrained(trained)
    clip = next(c for c in load_clips(clips) if c.key == item.meta.key)
    with torch.no_grad():
        assert torch.allclose(item.latents, tok.encode(clip_video(clip)), atol=1e-5)
    assert cache.latent_mean.tolist() == pytest.approx(tok.latent_mean.tolist())
    assert item.latents.shape == (6, 16, 5, 24, 40) and item.T_world_from_ego.shape == (17, 4, 4)

    out = tmp_path / "decoded"
    assert (
        main(
            [
                "tokenizer",
                "decode",
                "--model",
                str(trained),
                "--latents",
                str(clips / "latents" / "dbg"),
                "--key",
                item.meta.key,
                "--out",
                str(out),
            ]
        )
        == 0
    )
    assert sorted(p.name for p in out.iterdir()) == sorted(f"{item.meta.key}.{c}.mp4" for c in item.meta.cameras)
    assert (
        main(
            [
                "tokenizer",
                "eval",
                "--model",
                str(trained),
                "--data",
                str(clips),
                "--out",
                str(tmp_path / "ev"),
                "--max-views",
                "1",
            ]
        )
        == 0
    )
    scored = json.loads((tmp_path / "ev" / "metrics.json").read_text())
    assert scored["psnr"] > 18.0 and list(scored["skipped"]) == ["syn000"] and scored["clips_scored"] == 3
    # --max-clips spreads over the clips as drivewm eval's does (it had taken the first N: one drive)
    argv = ["tokenizer", "eval", "--model", str(trained), "--data", str(clips), "--max-views", "1", "--max-clips", "2"]
    assert main([*argv, "--out", str(tmp_path / "ev2")]) == 0
    keys = [c.key for c in load_clips(clips)]
    spread_keys = json.loads((tmp_path / "ev2" / "metrics.json").read_text())["clips"]
    assert sorted(spread_keys) == sorted(k for k in (keys[0], keys[2]) if k != "syn000")

    assert main(["tokenizer", "encode", "--model", str(tmp_path / "nope"), "--data", str(clips)]) == 2
    assert "not a drivewm model folder" in capsys.readouterr().err


def test_cli_train_overrides_and_bad_config(sim_clip_dir, tmp_path, capsys):
    assert (
        main(
            [
                "tokenizer",
                "train",
                "--preset",
                "debug",
                "--compression",
                "8x8x8",
                "--data",
                str(sim_clip_dir),
                "--out",
                str(tmp_path / "t"),
                "--set",
                "train.steps=1",
                "--set",
                "data.frames=9",
                "--set",
                "data.crop=[32,48]",
                "--set",
                "train.batch_size=1",
                "--set",
                "data.stats_batches=1",
            ]
        )
        == 0
    )
    assert json.loads((tmp_path / "t" / "config.json").read_text())["config"]["temporal_compression"] == 8
    assert (
        main(
            ["tokenizer", "train", "--data", str(sim_clip_dir), "--out", str(tmp_path / "u"), "--set", "data.frames=8"]
        )
        == 2
    )
    assert "data.frames=8 must be 1 + k*4" in capsys.readouterr().err
    assert (
        main(
            [
                "tokenizer",
                "train",
                "--data",
                str(sim_clip_dir),
                "--out",
                str(tmp_path / "u"),
                "--set",
                "train.lr_typo=1",
            ]
        )
        == 2
    )


def test_perceptual_term_needs_local_weights(tmp_path):
    from drivewm.tokenizer.adversarial import Adversary

    with pytest.raises(DrivewmError, match="discriminator weights not found"):
        Adversary(1e-4, str(tmp_path / "disc.safetensors"))
    with pytest.raises(DrivewmError, match="never downloads"):
        TokenizerLoss(LossConfig(perceptual=0.1))
    with pytest.raises(DrivewmError, match="not found"):
        TokenizerLoss(LossConfig(perceptual=0.1, perceptual_weights=str(tmp_path / "vgg.safetensors")))
    # user-provided local weights (random here: the loading path and the term are what is tested)
    from safetensors.torch import save_file

    from drivewm.tokenizer.losses import _VGG16

    state, cin, index = {}, 3, 0
    for v in _VGG16:
        if v == "M":
            index += 1
            continue
        state[f"features.{index}.weight"] = torch.randn(v, cin, 3, 3) * 0.05
        state[f"features.{index}.bias"] = torch.zeros(v)
        cin, index = v, index + 2
    save_file(state, str(tmp_path / "vgg.safetensors"))
    loss = TokenizerLoss(LossConfig(perceptual=0.1, perceptual_weights=str(tmp_path / "vgg.safetensors")))
    x = torch.rand(1, 3, 2, 32, 32) * 2 - 1
    _, same = loss(x, x)
    _, diff = loss(x.flip(-1), x)
    assert same["perceptual"] == pytest.approx(0.0, abs=1e-6) and diff["perceptual"] > 0.01


def test_decoder_fine_tuning_keeps_the_latent_space(trained, sim_clip_dir, tmp_path):
    """init + freeze_encoder: only the decoder trains, so latents (and latent caches made with the
    parent) stay valid while reconstructions improve."""
    # other crops than the parent's: statistics measured again on them would differ
    overrides = [f"init={trained}", "freeze_encoder=true", "train.checkpoint_every=20", "data.crop=[48,80]"]
    cfg = run_config(20, *overrides, "data.frames=17", "train.seed=5")
    tokenizer_train(cfg, sim_clip_dir, tmp_path / "dec")
    parent, tuned = Tokenizer.from_pretrained(trained), Tokenizer.from_pretrained(tmp_path / "dec")
    for (name, a), (_, b) in zip(parent.encoder.state_dict().items(), tuned.encoder.state_dict().items()):
        assert torch.equal(a, b), name
    assert torch.equal(parent.latent_std, tuned.latent_std) and torch.equal(parent.latent_mean, tuned.latent_mean)
    assert any(not torch.equal(a, b) for a, b in zip(parent.decoder.parameters(), tuned.decoder.parameters()))
    with pytest.raises(DrivewmError, match="freeze_encoder needs init"):
        run_config(1, "freeze_encoder=true")


def test_a_deeper_decoder_grows_from_its_parent(trained, sim_clip_dir, tmp_path):
    """decoder_mid_blocks above the parent's: the added blocks start as the identity, so the grown
    tokenizer decodes exactly as its parent at step 0; a decoder fine-tune then trains them on the
    parent's latents. Any other change of shape still fails to load."""
    parent = Tokenizer.from_pretrained(trained)
    have = parent.config.decoder_mid_blocks
    grown = Tokenizer(dataclasses.replace(parent.config, decoder_mid_blocks=have + 2))
    load_parent(grown, trained)
    video = torch.rand(1, 3, 9, 64, 96, generator=torch.Generator().manual_seed(0)) * 2 - 1
    with torch.no_grad():
        z = parent.encode(video)
        assert torch.equal(grown.encode(video), z)
        assert torch.equal(grown.decode(z), parent.decode(z))
    for changed in ({"base_channels": parent.config.base_channels * 2}, {"encoder_mid_blocks": 2}):
        with pytest.raises(DrivewmError, match="does not match"):
            load_parent(Tokenizer(dataclasses.replace(parent.config, **changed)), trained)

    tune = [f"init={trained}", "freeze_encoder=true", f"model.decoder_mid_blocks={have + 2}", "train.lr=1e-2"]
    tokenizer_train(run_config(10, *tune), sim_clip_dir, tmp_path / "deeper")
    tuned = Tokenizer.from_pretrained(tmp_path / "deeper")
    assert len(tuned.decoder.mid) == have + 2
    assert tuned.decoder.mid[have + 1].conv2.temporal.conv.weight.abs().sum() > 0  # the added blocks trained
    with torch.no_grad():
        assert torch.equal(tuned.encode(video), z)


def test_decoder_fine_tuning_of_a_linear_code_tokenizer_keeps_its_latents(sim_clip_dir, tmp_path):
    """The PCA code is half of the encoder (its basis codes and decodes): freeze_encoder must freeze it,
    or a decoder fine-tune of the recipe's tokenizer (`linear_code: pca`) moves every latent."""
    pca = ["model.linear_code=pca", "data.linear_fit_batches=2", "data.stats_batches=2"]
    tokenizer_train(run_config(10, *pca), sim_clip_dir, tmp_path / "parent")
    tune = [f"init={tmp_path / 'parent'}", "freeze_encoder=true", "train.lr=1e-2"]
    tokenizer_train(run_config(10, *pca, *tune), sim_clip_dir, tmp_path / "dec")
    parent, tuned = Tokenizer.from_pretrained(tmp_path / "parent"), Tokenizer.from_pretrained(tmp_path / "dec")
    video = torch.rand(1, 3, 9, 64, 96, generator=torch.Generator().manual_seed(0)) * 2 - 1
    with torch.no_grad():
        assert torch.equal(parent.encode(video), tuned.encode(video))
        assert not torch.equal(parent.decode(parent.encode(video)), tuned.decode(tuned.encode(video)))
