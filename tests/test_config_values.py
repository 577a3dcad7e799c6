"""Issue 15 item 8: every bad config value is one DrivewmError line naming the field, at the loader.

Each case ran into a traceback, or silently into a useless run, before configs were validated in
one place (drivewm.config.from_dict running every dataclass's validate()).
"""

from __future__ import annotations

import pytest

from drivewm.cli import main
from drivewm.config import apply_overrides, parse_override
from drivewm.diffusion.pretrain import pretrain_config
from drivewm.errors import DrivewmError
from drivewm.geometry import load_rig
from drivewm.tokenizer.config import TokenizerConfig
from drivewm.tokenizer.losses import LossConfig
from drivewm.train.loop import TrainConfig


@pytest.mark.parametrize(
    "override,message",
    [
        ("lr=nan", r"^train\.lr: expected a number, got 'nan'$"),
        ("lr=.nan", r"^train\.lr: expected a finite number, got nan$"),
        ("lr=.inf", r"^train\.lr: expected a finite number, got inf$"),
        ("lr=-1", r"^train: lr must be > 0, got -1\.0$"),
        ("batch_size=0", r"^train: batch_size must be >= 1, got 0$"),
        ("steps=-5", r"^train: steps must be >= 1, got -5$"),
        ("ema_decay=1", r"^train: ema_decay must be in \[0, 1\), got 1\.0$"),
        ("warmup_steps=-1", r"^train: warmup_steps must be >= 0, got -1$"),
        ("log_every=0", r"^train: log_every must be >= 1, got 0$"),
        ("betas=[0.9]", r"^train: betas must be two numbers in \[0, 1\), got \[0\.9\]$"),
        ("seed=18446744073709551616", r"^train: seed must be in \[0, 2147483647\], got 18446744073709551616$"),  # torch
        ("seed=-1", r"^train: seed must be in \[0, 2147483647\], got -1$"),  # --seed's range
    ],
)
def test_train_config_values_are_refused_with_the_field_named(override, message):
    with pytest.raises(DrivewmError, match=message):
        apply_overrides(TrainConfig, {}, [override], "train")


def test_a_valid_train_config_still_loads():
    cfg = apply_overrides(TrainConfig, {}, ["lr=1e-4", "steps=5", "batch_size=2", "ema_decay=0"], "train")
    assert (cfg.lr, cfg.steps, cfg.batch_size, cfg.ema_decay) == (1e-4, 5, 2, 0.0)


def test_pretrain_refuses_a_negative_learning_rate():
    with pytest.raises(DrivewmError, match=r"^pretrain\.train: lr must be > 0, got -0\.1$"):
        pretrain_config("debug", ["train.lr=-0.1"])


@pytest.mark.parametrize(
    "cls,override,message",
    [
        (TokenizerConfig, "base_channels=0", "base_channels must be >= 1"),
        (TokenizerConfig, "channel_multipliers=[1,0]", "channel_multipliers must be integers >= 1"),
        (LossConfig, "ssim=-0.5", "ssim must be >= 0"),
        (LossConfig, "l1=-.inf", "expected a finite number"),
    ],
)
def test_tokenizer_pieces_are_validated(cls, override, message):
    with pytest.raises(DrivewmError, match=message):
        apply_overrides(cls, {}, [override])


@pytest.mark.parametrize("text", ["crop=[64,", "a={b", "x=!!python/object:os.system ls", "k='unclosed"])
def test_unparsable_override_values_are_one_line_errors(text):
    with pytest.raises(DrivewmError, match=r"^override .*: value: not valid YAML"):
        parse_override(text)


def _run(capsys, argv: list[str]) -> tuple[int, str]:
    rc = main(argv)
    return rc, capsys.readouterr().err


def test_cli_bad_values_exit_2_with_one_line(capsys, tmp_path):
    rc, err = _run(
        capsys, ["pretrain", "--data", str(tmp_path), "--out", str(tmp_path / "o"), "--set", "train.lr=[64,"]
    )
    assert rc == 2 and err.count("\n") == 1 and err.startswith("error: override 'train.lr=[64,'")
    rc, err = _run(
        capsys, ["pretrain", "--data", str(tmp_path), "--out", str(tmp_path / "o"), "--set", "train.lr=-0.1"]
    )
    assert rc == 2 and err == "error: pretrain.train: lr must be > 0, got -0.1\n"
    rc, err = _run(capsys, ["simulate", "--drives", "0", "--out", str(tmp_path / "logs")])
    assert rc == 2 and err == "error: drivewm simulate: argument --drives: must be >= 1, got 0\n"
    assert not (tmp_path / "logs").exists() and not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    "camera,message",
    [
        ("{name: CAM, width: abc, height: 10, hfov_deg: 90, xyz: [0, 0, 1]}", "width must be a positive integer"),
        ("{name: CAM, width: 10, height: 100000000, hfov_deg: 90, xyz: [0, 0, 1]}", r"height must be .* <= 16384"),
        ("{name: CAM, width: 10, height: 10, K: [[5, 0, 5], [0, 5], [0, 0, 1]], xyz: [0, 0, 1]}", "K: expected 3x3"),
        ("{name: CAM, width: 10, height: 10, K: [[0, 0, 0], [0, 0, 0], [0, 0, 1]], xyz: [0, 0, 1]}", "K is singular"),
        ("{name: CAM, width: 10, height: 10, hfov_deg: 200, xyz: [0, 0, 1]}", "hfov_deg must be in"),
        ("{name: CAM, width: 10, height: 10, hfov_deg: 90, xyz: [0, 1]}", "xyz: expected finite numbers"),
        ("{name: ../x, width: 10, height: 10, hfov_deg: 90, xyz: [0, 0, 1]}", "camera name '../x'"),
        ("{name: CAM, width: 10, height: 10, hfov_deg: 90, xyz: [0, 0, 1], yaw_deg: east}", "yaw_deg: expected"),
    ],
)
def test_bad_rig_yaml_is_one_error_naming_file_and_camera(tmp_path, camera, message):
    path = tmp_path / "rig.yaml"
    path.write_text(f"name: r\ncameras:\n  - {camera}\n")
    with pytest.raises(DrivewmError, match=message) as err:
        load_rig(path)
    assert str(err.value).startswith(str(path)) and "\n" not in str(err.value)


def test_text_encoder_folder_with_pickled_weights_is_refused_before_loading(tmp_path):
    import pickle

    from drivewm.text import TextConfig, build_text_encoder

    (tmp_path / "config.json").write_text('{"model_type": "t5"}')
    (tmp_path / "pytorch_model.bin").write_bytes(pickle.dumps({"weight": [1.0]}))
    with pytest.raises(DrivewmError, match=r"no \*\.safetensors weights \(only pickled \['pytorch_model\.bin'\]"):
        build_text_encoder(TextConfig(kind="t5", path=str(tmp_path)))


@pytest.mark.parametrize(
    "argv,message",
    [
        (["rollout", "--clip", "c", "--speed", "nan"], "rollout.rollout.speed_mps: expected a finite number, got nan"),
        (["rollout", "--clip", "c", "--speed", "-5"], "rollout.speed_mps must be in [0, 100] m/s, got -5.0"),
        (["rollout", "--clip", "c", "--speed", "1e30"], "rollout.speed_mps must be in [0, 100] m/s, got 1e+30"),
        (["rollout", "--clip", "c", "--trajectory-guidance", "inf"], "trajectory_guidance: expected a finite number"),
        (["transfer", "c", "--to", "snow", "--guidance", "nan"], "transfer: --guidance must be a finite number >= 0"),
        (["transfer", "c", "--to", "snow", "--start-sigma", "-1"], "transfer: --start-sigma must be a finite number"),
        (["transfer", "c", "--to", "snow", "--detail-band", "nan"], "transfer: --detail-band must be a finite number"),
        (["transfer", "c", "--to", "snow", "--detail-band", "-2"], "transfer: --detail-band must be a finite number"),
    ],
)
def test_sampling_settings_are_refused_before_any_work(argv, message, capsys, tmp_path):
    """A NaN speed had made a blank rollout without a word, and a NaN transfer guidance failed every clip of
    every shard one after another (each clip only after its sampling): both are now one line at the start."""
    clips = tmp_path / "clips"
    clips.mkdir()
    argv = [str(clips) if a == "c" else a for a in argv]
    assert main([*argv, "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("fps", ["1e-300", "0", "-10", "1e9"])
def test_every_frame_rate_is_a_rate_a_camera_could_have(fps):
    """A frame rate of 1e-300 Hz had passed '> 0' and overflowed the frame period in ns deep inside a run
    (curation's tick clock, the simulator's ticks, a model's latent info); 1e9 Hz made clips of 1 ns."""
    from drivewm.curate.config import CurateConfig
    from drivewm.diffusion.text2world import LatentInfo
    from drivewm.sim.config import SimConfig

    rule = r"fps must be a frame rate in \[1/60, 1000\] Hz, got "
    for cls, base in [
        (CurateConfig, {}),
        (SimConfig, {}),
        (LatentInfo, {"latent_shape": [4, 2, 8, 8], "latent_mean": [0.0] * 4, "latent_std": [1.0] * 4}),
    ]:
        with pytest.raises(DrivewmError, match=rule):
            apply_overrides(cls, base, [f"fps={fps}"], "cfg")
        assert apply_overrides(cls, base, ["fps=12.5"], "cfg").fps == 12.5
