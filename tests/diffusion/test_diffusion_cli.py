"""``drivewm pretrain`` / ``drivewm generate`` end to end with a real (random) tokenizer, and bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from drivewm.cli import main
from drivewm.clips import iter_clips
from drivewm.clips.format import ClipMeta
from drivewm.clips.latents import write_latent_clip, write_latent_index
from drivewm.config import to_dict
from drivewm.geometry import load_rig
from drivewm.tokenizer import Tokenizer, preset

TINY = [
    "model.hidden_dim=32",
    "model.depth=1",
    "model.num_heads=2",
    "model.adaln_lora_dim=8",
    "text.dim=16",
    "train.steps=3",
    "train.batch_size=2",
    "train.log_every=1",
    "sample_steps=2",
]


def _save_tokenizer(path: Path, **changes) -> Tokenizer:
    torch.manual_seed(0)
    tok = Tokenizer(preset("debug").__class__(**{**to_dict(preset("debug")), **changes}))
    tok.save_pretrained(path)
    return tok


def _write_cache(cache: Path, tok: Tokenizer, tok_dir: Path, n: int) -> None:
    """n clips of 5 frames at 16x32: latents (1, 16, 2, 2, 4) drawn at random."""
    rig = load_rig("front1").scaled(32, 16, fit="stretch").to_dict()
    rows = []
    for i in range(n):
        meta = ClipMeta(
            f"c{i}",
            "synthetic",
            0,
            10.0,
            [j * 100_000_000 for j in range(5)],
            rig,
            caption=["clear day", "heavy snow"][i % 2],
        )
        rows.append(write_latent_clip(cache, meta, torch.randn(1, 16, 2, 2, 4), np.tile(np.eye(4), (5, 1, 1))))
    info = {
        "path": str(tok_dir),
        "config": to_dict(tok.config),
        "latent_mean": tok.latent_mean.tolist(),
        "latent_std": tok.latent_std.tolist(),
    }
    write_latent_index(cache, info, rows)


@pytest.fixture(scope="module")
def clipdir(tmp_path_factory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("cli")
    tok_dir = root / "tok"
    tok = _save_tokenizer(tok_dir)
    _write_cache(root / "clips" / "latents" / "tok", tok, tok_dir, 4)
    return root / "clips", tok_dir


def _run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.mark.slow
def test_pretrain_then_generate_writes_clips_mp4_and_contact_sheet(clipdir, tmp_path, capsys):
    data, tok_dir = clipdir
    code, out, err = _run(
        capsys,
        "pretrain",
        "--data",
        data,
        "--tokenizer",
        tok_dir,
        "--out",
        tmp_path / "t2w",
        *[a for o in TINY for a in ("--set", o)],
    )
    assert code == 0, err
    assert json.loads((tmp_path / "t2w" / "config.json").read_text())["model_type"] == "text2world"
    assert (tmp_path / "t2w" / "samples" / "step_0000003.png").is_file() and (
        tmp_path / "t2w" / "metrics.jsonl"
    ).is_file()
    code, out, err = _run(
        capsys,
        "generate",
        "--model",
        tmp_path / "t2w",
        "--prompt",
        "heavy snow",
        "--steps",
        "2",
        "--num-samples",
        "2",
        "--set",
        "sampling.guidance_interval=[0.5,3]",
        "--out",
        tmp_path / "gen",
    )
    assert code == 0, err
    clips = list(iter_clips(tmp_path / "gen"))
    assert [c.meta.caption for c in clips] == ["heavy snow", "heavy snow"] and clips[0].meta.extra["seed"] == 0
    assert clips[0].meta.extra["guidance_interval"] == [0.5, 3.0]
    video = clips[1].video(clips[1].meta.cameras[0])
    assert video.shape == (5, 16, 32, 3) and clips[1].meta.get_rig().cameras[0].width == 32
    assert (tmp_path / "gen" / "sample_001.mp4").stat().st_size > 0 and (
        tmp_path / "gen" / "contact_sheet.png"
    ).is_file()


@pytest.mark.parametrize("value", ["[5,1]", "[-1,2]", "[.nan,2]", "[1]", "[a,b]", "1"])
def test_a_bad_guidance_interval_is_one_line_before_any_model_loads(tmp_path, capsys, value):
    out = tmp_path / "gen"
    code, _, err = _run(
        capsys, "generate", "--prompt", "fog", "--out", out, f"--set=sampling.guidance_interval={value}"
    )
    assert code == 2 and "guidance_interval" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_dry_run_prints_resolved_config_with_overrides(clipdir, tmp_path, capsys):
    data, tok_dir = clipdir
    code, out, _ = _run(
        capsys,
        "pretrain",
        "--preset",
        "small",
        "--data",
        data,
        "--tokenizer",
        tok_dir,
        "--out",
        tmp_path / "x",
        "--set",
        "train.steps=7",
        "--dry-run",
    )
    cfg = json.loads(out)
    assert (
        code == 0 and cfg["train"]["steps"] == 7 and cfg["model"]["hidden_dim"] == 384 and not (tmp_path / "x").exists()
    )


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--preset", "huge"], "invalid choice: 'huge'"),
        (["--set", "train.stepz=3"], "unknown key(s) ['stepz']"),
        (["--set", "train.steps=many"], "train.steps: expected an integer"),
        (["--set", "trainsteps"], "expected KEY=VALUE"),
    ],
)
def test_bad_recipe_gets_one_line_error(clipdir, tmp_path, capsys, extra, message):
    data, tok_dir = clipdir
    code, _, err = _run(capsys, "pretrain", "--data", data, "--tokenizer", tok_dir, "--out", tmp_path / "x", *extra)
    assert code == 2 and message in err and err.count("\n") == 1


def test_empty_cache_mismatched_tokenizer_and_wrong_model_are_refused(clipdir, tmp_path, capsys):
    data, tok_dir = clipdir
    empty = tmp_path / "empty" / "latents" / "tok"
    write_latent_index(empty, {"path": None}, [])
    code, _, err = _run(capsys, "pretrain", "--data", empty.parents[1], "--tokenizer", tok_dir, "--out", tmp_path / "x")
    assert code == 2 and "holds no clips" in err
    other = tmp_path / "tok"  # same folder name, another tokenizer
    _save_tokenizer(other, base_channels=8)
    code, _, err = _run(capsys, "pretrain", "--data", data, "--tokenizer", other, "--out", tmp_path / "x")
    assert code == 2 and "encoded by another tokenizer" in err
    code, _, err = _run(capsys, "pretrain", "--data", tmp_path, "--tokenizer", tok_dir, "--out", tmp_path / "x")
    assert code == 2 and "no latent cache" in err
    code, _, err = _run(capsys, "generate", "--model", tok_dir, "--prompt", "snow", "--out", tmp_path / "g")
    assert code == 2 and "cannot generate from model_type 'drivewm-tokenizer'" in err


def test_progressive_schedule_images_then_video_warm_starts_the_same_network(clipdir, tmp_path, capsys):
    data, tok_dir = clipdir
    flags = [a for o in TINY for a in ("--set", o)]
    common = ("--data", data, "--tokenizer", tok_dir)
    code, _, err = _run(capsys, "pretrain", *common, "--out", tmp_path / "img", "--set", "data.frames=1", *flags)
    assert code == 0, err
    image_model = json.loads((tmp_path / "img" / "config.json").read_text())
    assert image_model["latent"]["latent_shape"] == [16, 1, 2, 4]  # the first latent frame: an image latent
    code, _, err = _run(capsys, "pretrain", *common, "--out", tmp_path / "vid", "--init", tmp_path / "img", *flags)
    assert code == 0, err
    assert json.loads((tmp_path / "vid" / "config.json").read_text())["latent"]["latent_shape"] == [16, 2, 2, 4]
    from safetensors.torch import load_file

    from drivewm.diffusion.pretrain import warm_start
    from drivewm.diffusion.text2world import Text2World

    img = load_file(str(tmp_path / "img" / "model.safetensors"))
    fresh = Text2World.from_pretrained(tmp_path / "vid")  # trained on from the image weights: differs from them
    assert any(not torch.equal(fresh.dit.state_dict()[k], img[k]) for k in img)
    warm_start(fresh, tmp_path / "img")  # what the video stage starts from: exactly the image model
    assert all(torch.equal(fresh.dit.state_dict()[k], img[k]) for k in img)
    state = torch.load(tmp_path / "vid" / "train_state.pt", weights_only=True)
    assert state["config"]["init"] == str((tmp_path / "img").resolve())
    code, _, err = _run(
        capsys,
        "pretrain",
        *common,
        "--out",
        tmp_path / "bad",
        "--init",
        tmp_path / "img",
        *flags,
        "--set",
        "model.depth=2",
    )
    assert code == 2 and "config differs from this run's at ['depth']" in err


def test_pretrain_without_tokenizer_decodes_with_the_one_that_encoded_the_latents(tmp_path, capsys):
    """No --tokenizer: the cache's own tokenizer is recorded in the model (its samples are images); once
    that folder is gone, pretrain and generate both say the samples are latent previews."""
    tok_dir = tmp_path / "tok"
    tok = _save_tokenizer(tok_dir)
    _write_cache(tmp_path / "clips" / "latents" / "tok", tok, tok_dir, 2)
    flags = [a for o in [*TINY, "train.steps=1", "data.latents=tok"] for a in ("--set", o)]
    code, _, err = _run(capsys, "pretrain", "--data", tmp_path / "clips", "--out", tmp_path / "a", *flags)
    assert code == 0, err
    assert json.loads((tmp_path / "a" / "config.json").read_text())["latent"]["tokenizer"] == "../tok"  # same run
    assert "decoding with" in err and "warning" not in err
    import shutil

    shutil.rmtree(tok_dir)
    code, _, err = _run(capsys, "pretrain", "--data", tmp_path / "clips", "--out", tmp_path / "b", *flags)
    assert code == 0, err
    assert json.loads((tmp_path / "b" / "config.json").read_text())["latent"]["tokenizer"] is None
    assert f"its tokenizer {tok_dir.resolve()} is gone" in err and "latent previews" in err
    code, _, err = _run(
        capsys, "generate", "--model", tmp_path / "b", "--prompt", "snow", "--steps", "1", "--out", tmp_path / "g"
    )
    assert code == 0 and "records no tokenizer: its samples are latent previews" in err


def test_weights_of_another_parameterization_are_refused_naming_the_setting(clipdir, tmp_path, capsys):
    """An EDM-trained image model warm-starting a run left at the default (flow) scalings, or an EDM run
    resumed with the default, would train another function from step one: both refused, with the --set
    that continues the weights as they were trained."""
    data, tok_dir = clipdir
    common = ("--data", data, "--tokenizer", tok_dir, *[a for o in [*TINY, "train.steps=1"] for a in ("--set", o)])
    edm = ("--set", "edm.parameterization=edm")
    code, _, err = _run(capsys, "pretrain", *common, *edm, "--set", "data.frames=1", "--out", tmp_path / "img")
    assert code == 0, err
    code, _, err = _run(capsys, "pretrain", *common, "--init", tmp_path / "img", "--out", tmp_path / "vid")
    assert code == 2 and "pass --set edm.parameterization=edm" in err and not (tmp_path / "vid").exists()
    code, _, err = _run(capsys, "pretrain", *common, *edm, "--init", tmp_path / "img", "--out", tmp_path / "vid")
    assert code == 0, err
    more = ("--set", "train.steps=2", "--set", "data.frames=1")
    code, _, err = _run(capsys, "pretrain", *common, *more, "--out", tmp_path / "img")  # resumed, default recipe
    assert code == 2 and "the run in this folder was trained with edm" in err and "edm.parameterization=edm" in err
    code, _, err = _run(capsys, "pretrain", *common, *more, *edm, "--out", tmp_path / "img")
    assert code == 0, err
