"""kill -9 at random points of every writer of clips or latents (generate, transfer, curate, tokenizer encode):
whatever each kill leaves, eval never scores a torn clip and every file under a final name reads whole; a rerun
on the same folder completes and leaves no temporary behind.

Each command runs in a child forked from this process (its imports done once, so a kill point costs only
the time until it), killed with SIGKILL after a delay drawn uniformly over the length of one whole run of it.
The kills follow one another on one output folder, as repeated crashes would.
"""

from __future__ import annotations

import json
import os
import random
import signal
import time
from pathlib import Path

import pytest
import torch

from drivewm.cli import main
from drivewm.clips.latents import LatentCache
from drivewm.clips.shards import iter_clips, list_shards, shard_folders
from drivewm.diffusion.dit_config import DiTConfig
from drivewm.diffusion.text2world import LatentInfo, Text2World, Text2WorldConfig
from drivewm.geometry import load_rig
from drivewm.lock import LOCK_NAME
from drivewm.tokenizer import Tokenizer, preset
from drivewm.transfer.config import TransferConfig
from drivewm.transfer.init import from_text2world

KILLS_PER_COMMAND = 20


def _child(argv: list[str]) -> int:
    """Fork a child that runs ``drivewm ARGV`` with its output discarded; returns its pid."""
    pid = os.fork()
    if pid == 0:  # the child: never returns into pytest
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        try:
            code = main(argv)
        except BaseException:
            code = 1
        os._exit(code)
    return pid


def _whole_run_s(argv: list[str]) -> float:
    """Seconds of one whole run of ``drivewm ARGV`` in a forked child, which must succeed."""
    tic = time.perf_counter()
    _, status = os.waitpid(_child(argv), 0)
    assert os.waitstatus_to_exitcode(status) == 0, argv
    return time.perf_counter() - tic


def _kill_at(argv: list[str], delay_s: float) -> None:
    pid = _child(argv)
    time.sleep(delay_s)
    os.kill(pid, signal.SIGKILL)
    os.waitpid(pid, 0)


def _temporaries(folder: Path) -> list[Path]:
    """Hidden names a writer leaves: temporaries (the folder lock is not one: the kernel drops its flock)."""
    return [p for p in folder.rglob(".*") if p.name != LOCK_NAME]


def _whole_keys(out: Path) -> set[str]:
    """Keys of every clip under a final name in ``out`` (a clip folder or a folder of them), each read whole:
    a torn file under a final name fails here."""
    keys = set()
    for folder in [out, *shard_folders(out)] if out.is_dir() else []:
        for shard in list_shards(folder):
            keys |= {clip.meta.key for clip in iter_clips(shard) if all(clip.video(c).size for c in clip.meta.cameras)}
    return keys


def _scored(out: Path, ev: Path, capsys) -> set[str] | None:
    """The clip keys ``drivewm eval`` scores in ``out`` (None when it finds nothing to score: exit 2)."""
    code = main(["eval", str(out), "--out", str(ev), "--metrics", "tse", "--no-pictures"])
    capsys.readouterr()
    assert code in (0, 2)
    return (
        {name.split("/")[-1] for name in json.loads((ev / "metrics.json").read_text())["clips"]} if code == 0 else None
    )


def _kill_and_rerun(argv_for, out: Path, check, rng: random.Random) -> int:
    """KILLS_PER_COMMAND kills of ``argv_for(out)`` at random points, ``check(out, False)`` after each, then a
    whole rerun and ``check(out, True)``; returns how many kills left a temporary behind."""
    whole_s = _whole_run_s(argv_for(out.parent / f"{out.name}-timing"))
    argv = argv_for(out)
    torn = 0
    for _ in range(KILLS_PER_COMMAND):
        _kill_at(argv, rng.uniform(0.0, whole_s))
        torn += bool(_temporaries(out)) if out.exists() else 0
        check(out, False)
    assert main(argv) == 0
    assert _temporaries(out) == []
    check(out, True)
    return torn


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, Path]:
    """A short simulated drive at 160x96 (front3), a debug tokenizer, a tiny Text2World on its latents of
    5-frame 48x80 clips and a tiny transfer model on its latents of the drive's 17-frame clips."""
    root = tmp_path_factory.mktemp("kill_inputs")
    sim = ["simulate", "--duration", "3.5", "--width", "160", "--height", "96", "--rig", "front3"]
    assert main([*sim, "--out", str(root / "logs")]) == 0
    assert main(["curate", str(root / "logs"), "--out", str(root / "clips"), "--recipe", "transfer"]) == 0
    torch.manual_seed(0)
    tok = Tokenizer(preset("debug"))
    tok.save_pretrained(root / "tok")
    mean, std = tok.latent_mean.tolist(), tok.latent_std.tolist()
    rig = load_rig("front1").scaled(80, 48, fit="stretch").to_dict()
    dit = DiTConfig(in_channels=16, hidden_dim=32, depth=1, num_heads=2, adaln_lora_dim=8)
    Text2World(
        Text2WorldConfig(dit), LatentInfo([16, 2, 6, 10], mean, std, 10.0, str(root / "tok"), rig)
    ).save_pretrained(root / "t2w")
    parent = Text2World(Text2WorldConfig(dit), LatentInfo([16, 5, 12, 20], mean, std, 10.0, str(root / "tok"), {}))
    from_text2world(parent, TransferConfig(), name="parent").save_pretrained(root / "transfer")
    return {name: root / name for name in ("logs", "clips", "tok", "t2w", "transfer")}


@pytest.mark.slow
def test_kill_9_at_random_points_never_leaves_a_torn_clip_scored(inputs, tmp_path, capsys):
    rng = random.Random(70)
    evals = iter(range(10**6))

    def check_clips(out: Path, complete: bool) -> None:
        """Eval scores only whole clips; once the run completed, all of them."""
        scored, whole = _scored(out, tmp_path / f"ev{next(evals)}", capsys), _whole_keys(out)
        assert scored == whole != set() if complete else scored is None or scored <= whole

    def check_latents(cache: Path, complete: bool) -> None:
        """Every latent file the index lists reads whole and finite; once the run completed, one per clip."""
        if complete or (cache / "index.json").is_file():
            latents = LatentCache(cache)
            assert all(torch.isfinite(latents[i].latents).all() for i in range(len(latents)))
            assert not complete or len(latents) == len(_whole_keys(inputs["clips"]))

    def out_flag(argv: list[str]):
        return lambda out: [*argv, "--out", str(out)]

    t2w, tok, clips = (str(inputs[name]) for name in ("t2w", "tok", "clips"))
    commands = {
        "generate": (out_flag(["generate", "--model", t2w, "--prompt", "snow", "--num-samples", "3", "--steps", "2"])),
        "transfer": out_flag(["transfer", clips, "--model", str(inputs["transfer"]), "--to", "snow", "--steps", "1"]),
        "curate": out_flag(["curate", str(inputs["logs"]), "--recipe", "transfer", "--set", "clips_per_shard=1"]),
        "encode": lambda out: ["tokenizer", "encode", "--model", tok, "--data", clips, "--name", out.name],
    }
    torn = {}
    for name, argv_for in commands.items():
        out = inputs["clips"] / "latents" / name if name == "encode" else tmp_path / name
        check = check_latents if name == "encode" else check_clips
        torn[name] = _kill_and_rerun(argv_for, out, check, rng)
    assert sum(torn.values()) > 0, torn  # some kills did land while a file was half-written
