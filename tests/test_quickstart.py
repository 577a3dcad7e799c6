"""`drivewm quickstart` fine-tunes the shipped models through the public commands.

Fast: every stage of every profile parses, names the shipped models as ``shipped:KIND`` and chains
its outputs; the report's command block is shell-quoted with paths relative to the output folder.
Slow (end to end, ``--profile smoke`` from the shipped weights in drivewm/weights/): the fine-tuned
weights differ from the shipped ones, which stay byte-identical; the report has a number or a
footnoted reason in each of its real / shipped / fine-tuned columns; generated contact sheets have
a row per camera; a transfer model post-trained from the shipped Text2World model turns the first
curated clip to snow (shown in the report); the report's commands can be pasted in the output folder;
figures load in a real headless Chromium; a rerun reuses every stage.
"""

from __future__ import annotations

import dataclasses
import json
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch
from safetensors.torch import load_file

from drivewm import model_folders
from drivewm.cli import build_parser
from drivewm.clips import iter_clips, read_manifest
from drivewm.curate.contact_sheet import thumb_width
from drivewm.diffusion.dit_config import DiTConfig, upgrade_saved_config
from drivewm.product.quickstart import FINETUNED, FIRST_LOG, MODELS, load_profile, stage_commands
from drivewm.product.release import check_manifest
from drivewm.product.report import command_lines
from drivewm.train.checkpoint import WEIGHTS_NAME

#: Whichever slow test runs first runs the whole pipeline: minutes, far more on a loaded machine.
pytestmark = pytest.mark.timeout(3600)
CHROMIUM_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
#: Flags whose value is a path (or ``shipped:KIND``); with the positional inputs of these commands.
PATH_FLAGS = {"--out", "--data", "--model", "--init", "--tokenizer", "--reference"}
POSITIONAL_INPUT = {"view", "curate", "eval", "transfer"}


def named_paths(tokens: list[str]) -> list[str]:
    """The paths a ``drivewm ...`` command line names: values of PATH_FLAGS and positional inputs."""
    paths = [b for a, b in zip(tokens, tokens[1:]) if a in PATH_FLAGS]
    return paths + ([tokens[2]] if tokens[1] in POSITIONAL_INPUT else [])


def without(argv: list[str], *flags: str) -> list[str]:
    """``argv`` less the given flags and their values."""
    drop = {i + d for i, a in enumerate(argv) if a in flags for d in (0, 1)}
    return [a for i, a in enumerate(argv) if i not in drop]


def same_dit(saved: dict, shipped: dict) -> bool:
    """A saved DiT config is the shipped one: equal fields, and fields added since the shipped folder
    was written at the value it loads with (drivewm.diffusion.dit_config.SAVED_BEFORE, else the default)."""
    expected = {**dataclasses.asdict(DiTConfig()), **upgrade_saved_config({"dit": shipped})["dit"]}
    return saved == {k: expected[k] for k in saved} and shipped.keys() <= saved.keys()


def command_block(markdown: str) -> list[list[str]]:
    """The report's "Commands run" block, each command line split as a POSIX shell would."""
    block = markdown.split("## Commands run")[1].split("```sh\n")[1].split("```")[0]
    return [shlex.split(line) for line in block.splitlines() if line.strip() and not line.startswith("#")]


@pytest.mark.parametrize("profile", ["full", "smoke"])
def test_every_stage_parses_and_starts_from_the_shipped_models(profile, fake_shipped_weights, tmp_path):
    (fake_shipped_weights / "transfer").mkdir()  # the transfer model the quickstart fine-tunes
    (fake_shipped_weights / "transfer" / WEIGHTS_NAME).write_bytes(b"weights")
    stages = stage_commands(load_profile(profile), tmp_path / "qs")
    parser = build_parser()
    for name, argv in stages:
        args = parser.parse_args(argv)  # a typo in a profile fails here, not minutes into a run
        assert callable(args.func), name
    argv = dict(stages)
    names = list(argv)
    assert not any("tokenizer-train" in n or n == "pretrain" for n in names)  # nothing trains from scratch
    assert argv["tokenizer-encode"][argv["tokenizer-encode"].index("--model") + 1] == "shipped:tokenizer"
    assert argv["posttrain"][argv["posttrain"].index("--init") + 1] == "shipped:multiview"
    assert parser.parse_args(argv["posttrain"]).init == fake_shipped_weights / "multiview"
    encode_paired, transfer_train = argv["tokenizer-encode-paired"], argv["transfer-train"]
    assert encode_paired[encode_paired.index("--model") + 1] == "shipped:tokenizer"
    assert transfer_train[transfer_train.index("--init") + 1] == "shipped:transfer"
    assert parser.parse_args(transfer_train).init == fake_shipped_weights / "transfer"
    assert names.index("tokenizer-encode-paired") < names.index("transfer-train") < names.index("transfer")
    for g in load_profile(profile).generations:  # both models draw the same prompt with the same seed
        shipped, tuned = argv[f"generate-shipped-{g.name}"], argv[f"generate-finetuned-{g.name}"]
        assert shipped[shipped.index("--model") + 1] == "shipped:multiview"
        assert tuned[tuned.index("--model") + 1] == str(tmp_path / "qs" / FINETUNED)
        assert without(shipped, "--model", "--out") == without(tuned, "--model", "--out")
    assert names.index("tokenizer-encode") < names.index("posttrain") < names.index("generate-finetuned-snow_left")
    evals = [n for n in names if n.startswith("eval-")]
    assert names[-len(evals) :] == evals and len(evals) == 1 + 2 * len(load_profile(profile).generations)


def test_command_lines_quote_arguments_and_name_paths_relative_to_the_output_folder(tmp_path):
    out = tmp_path / "my quickstart"  # a space, so that unquoted paths would split
    stages = [
        (n, [str(out / "logs" / "a.mcap") if a == FIRST_LOG else a for a in argv])
        for n, argv in stage_commands(load_profile("full"), out)
    ]
    lines = command_lines(stages, out)
    assert lines[0].startswith("#") and "output folder" in lines[0]
    commands = [shlex.split(line) for line in lines[1:]]
    assert [c[1:] for c in commands[:1]] == [
        ["simulate", "--recipe", "quickstart", "--rig", "nuscenes6", "--out", "logs"]
    ]
    prompts = [c[c.index("--prompt") + 1] for c in commands if "--prompt" in c]
    assert prompts[0] == "heavy snow on a highway, daytime, the ego car turns left"  # one argument, not eight
    assert "resolution=[160,96]" in commands[2]
    assert not [t for c in commands for t in c if t.startswith("/") or "{" in t or str(tmp_path) in t]
    assert commands[1][2] == "logs/a.mcap"


def run_quickstart(out: Path) -> str:
    proc = subprocess.run(
        [sys.executable, "-m", "drivewm.cli", "quickstart", "--profile", "smoke", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=3000,
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return proc.stdout


@pytest.fixture(scope="module")
def shipped_manifest() -> dict:
    """The shipped weights' manifest, checked (sha256 of every file) before the quickstart runs."""
    return check_manifest()


@pytest.fixture(scope="module")
def quickstart_dir(tmp_path_factory, shipped_manifest) -> tuple[Path, str]:
    out = tmp_path_factory.mktemp("quickstart")
    return out, run_quickstart(out)


def test_the_reports_turn_sign_is_the_benchmarks_figure_and_says_why_it_is_missing():
    """The report's ``turn_sign`` row: turning clips whose yaw has the asked sign, an unreadable turn
    a failure (as in the world-model benchmark); a set where nothing turns gets a dash saying so."""
    from drivewm.product.report import _missing_reason, with_turn_sign

    def clip(asked, read):
        return {"conditioned_yaw_change_deg": asked, "yaw_change_deg": read}

    clips = [clip(30.0, 12.0), clip(30.0, 2.0), clip(-30.0, 4.0), clip(-30.0, None), clip(0.0, 9.0)]
    got = with_turn_sign({"num_clips": 5, "clips": {str(i): c for i, c in enumerate(clips)}})
    assert got["turn_sign"] == 0.5 and got["num_clips"] == 5  # 2 of 4 turning clips; straight ones do not count
    straight = with_turn_sign({"clips": {"a": clip(1.0, 3.0)}})
    assert straight["turn_sign"] is None
    assert "turns by more than the benchmark's 5 degrees" in _missing_reason(straight, "turn_sign")
    assert with_turn_sign({}) == {}  # a set whose eval did not run stays empty


@pytest.mark.slow
def test_every_stage_ran_and_both_models_are_scored(quickstart_dir):
    out, stdout = quickstart_dir
    profile = load_profile("smoke")
    assert "expected about" in stdout  # says up front how long it will take
    clips = list(iter_clips(out / "clips"))
    assert clips and all(c.meta.cameras == clips[0].meta.cameras for c in clips)
    for model in MODELS:
        for g in profile.generations:
            generated = list(iter_clips(out / "generated" / model / g.name))
            assert generated, (model, g.name)
            assert generated[0].meta.cameras == clips[0].meta.cameras  # all six views generated
            assert generated[0].videos().shape[:2] == (len(clips[0].meta.cameras), clips[0].meta.num_frames)
            metrics = json.loads((out / "eval" / model / g.name / "metrics.json").read_text())
            assert metrics["num_clips"] == 1 and "pose_success" in metrics
    real = json.loads((out / "eval" / "real" / "metrics.json").read_text())
    assert real["tse"] is not None and 0 < real["tse"] < 2.0  # simulated clips are geometrically consistent
    tok = json.loads((out / "tokenizer_eval" / "metrics.json").read_text())
    assert tok["psnr"] > 8.0  # the shipped tokenizer beats a constant grey image (about 6 dB on these renders)


@pytest.mark.slow
def test_fine_tuning_changes_a_copy_and_leaves_the_shipped_weights_alone(quickstart_dir, shipped_manifest):
    out, _ = quickstart_dir
    assert check_manifest() == shipped_manifest  # every shipped file still has its sha256
    shipped = load_file(model_folders.shipped_model("multiview") / WEIGHTS_NAME)
    tuned = load_file(out / FINETUNED / WEIGHTS_NAME)
    assert tuned.keys() == shipped.keys() and all(tuned[k].shape == shipped[k].shape for k in shipped)
    changed = [k for k in shipped if not np.allclose(tuned[k].float().numpy(), shipped[k].float().numpy(), atol=1e-4)]
    assert len(changed) > len(shipped) // 2, f"only {len(changed)} of {len(shipped)} tensors moved"
    shipped_cfg = json.loads((model_folders.shipped_model("multiview") / "config.json").read_text())["config"]
    tuned_cfg = json.loads((out / FINETUNED / "config.json").read_text())["config"]
    assert same_dit(tuned_cfg["dit"], shipped_cfg["dit"])  # the shipped architecture, whatever its preset


@pytest.mark.slow
def test_one_curated_clip_is_transferred_to_snow_by_the_fine_tuned_shipped_transfer_model(quickstart_dir):
    from drivewm.transfer.model import Transfer

    out, _ = quickstart_dir
    source = next(iter_clips(out / "clips"))
    (done,) = list(iter_clips(out / "transfer"))  # --max-clips 1: the first curated clip
    assert done.meta.extra["transfer"]["source"]["key"] == source.key
    assert done.meta.cameras == source.meta.cameras and done.videos().shape[:2] == source.videos().shape[:2]
    assert done.meta.tags["weather"] == "snow" and done.meta.timestamps_ns == source.meta.timestamps_ns
    assert {r["pair_id"] for r in read_manifest(out / "paired_clips")} != {""}  # the model trained on pairs
    shipped_t2w, shipped_transfer = model_folders.shipped_model("text2world"), model_folders.shipped_model("transfer")
    transfer_model = json.loads((out / "transfer_model" / "config.json").read_text())
    assert transfer_model["parent"] == "shipped:text2world"  # the shipped transfer model's lineage
    assert Transfer.from_pretrained(out / "transfer_model").parent == str(shipped_t2w.resolve())
    shipped_cfg, tuned_cfg = (
        json.loads((shipped_transfer / "config.json").read_text())["config"],
        transfer_model["config"],
    )
    assert tuned_cfg["transfer"] == shipped_cfg["transfer"]  # the shipped transfer model, fine-tuned as it is
    assert same_dit(tuned_cfg["dit"], shipped_cfg["dit"])
    train_state = torch.load(out / "transfer_model" / "train_state.pt", weights_only=False)
    assert train_state["config"]["init"] == str(shipped_transfer.resolve())
    assert f"Transferred: {done.key}" in (out / "report.md").read_text()


def test_a_generated_columns_title_names_its_post_processing(tmp_path):
    """A generated set's column says whether its clips are the network's own frames or which post-steps
    they went through (from the clips' ``post_processing``), so a stitched CSE never passes for the network's."""
    from drivewm.clips.shards import write_manifest
    from drivewm.product.report import post_processing, set_title

    plain = write_manifest(tmp_path / "plain", [{"key": "a", "post_processing": []}])
    stitched = write_manifest(
        tmp_path / "stitched", [{"key": "a", "post_processing": ["reproject", "stitch"]}, {"key": "b"}]
    )
    facts = {"post_processing": {"shipped": post_processing([plain]), "finetuned": post_processing([plain, stitched])}}
    assert set_title("real", facts) == "real clips"
    assert set_title("shipped", facts) == "shipped model, network's own frames"
    assert set_title("finetuned", facts) == "fine-tuned model, post-processed: reproject, stitch"


@pytest.mark.slow
def test_report_has_real_shipped_and_fine_tuned_columns_with_numbers(quickstart_dir):
    out, _ = quickstart_dir
    md = (out / "report.md").read_text()
    table = [line for line in md.split("## Consistency benchmark")[1].split("\n\n")[1].splitlines()]
    header = [c.strip() for c in table[0].strip("|").split("|")]
    own = ["shipped model, network's own frames", "fine-tuned model, network's own frames"]
    assert [h.split(" (")[0] for h in header[2:]] == ["real clips", *own]  # generate's default: no post-steps
    rows = {r.split("|")[1].strip(" `"): [c.strip() for c in r.strip("|").split("|")[2:]] for r in table[2:]}
    for key in ("pose_success", "tse"):
        assert re.fullmatch(r"\d+\.\d{3}", rows[key][0]), rows[key]  # real clips: a number
    assert all(re.fullmatch(r"\d+\.\d{3}", c) for c in rows["pose_success"])  # three numbers
    notes = dict(re.findall(r"^\[(\d+)\] (.+?)\s*$", md, re.M))
    for cells in rows.values():
        for cell in cells:  # a number, or a dash whose footnote says why eval gave none
            assert re.fullmatch(r"\d+\.\d{3}", cell) or re.fullmatch(r"— \[(\d+)\]", cell), cell
            if cell.startswith("—"):
                assert notes[cell[3:-1]].split(": ", 1)[1], cell
    assert "n/a" not in md


@pytest.mark.slow
def test_generated_contact_sheets_have_a_row_per_camera_like_the_real_one(quickstart_dir):
    out, _ = quickstart_dir
    real = cv2.imread(str(out / "clips" / "contact_sheet.png"))
    for model in MODELS:
        folder = out / "generated" / model / "snow_left"
        clips = list(iter_clips(folder))
        sheet = cv2.imread(str(folder / "contact_sheet.png"))
        v, _, h, w, _ = clips[0].videos().shape
        view_w = thumb_width(w)  # each camera a row of thumbnails, as on the real sheet
        assert all(len(f"{c.key}: {c.meta.caption}") < 3 * view_w // 6 for c in clips)  # one caption line
        view_h = round(h * view_w / w)
        assert sheet.shape[:2] == (len(clips) * (20 + v * view_h + 6), real.shape[1]), model


@pytest.mark.slow
def test_report_commands_paste_into_a_shell_in_the_output_folder(quickstart_dir):
    out, _ = quickstart_dir
    commands = command_block((out / "report.md").read_text())
    assert len(commands) == len(list((out / ".stages").glob("*.json")))
    parser = build_parser()
    for tokens in commands:
        assert tokens[0] == "drivewm" and callable(parser.parse_args(tokens[1:]).func), tokens
        for path in named_paths(tokens):
            assert not Path(path).is_absolute() and "{" not in path, tokens
            if not path.startswith("shipped:"):
                assert (out / path).exists(), f"{path} (from {shlex.join(tokens)}) is not in {out}"
    prompts = [t[t.index("--prompt") + 1] for t in commands if "--prompt" in t]
    assert prompts and all(" " in p for p in prompts)  # a whole prompt is one argument


@pytest.mark.slow
@pytest.mark.skipif(
    shutil.which("chromium") is None, reason="Debian's chromium is not installed (scripts/run-tests.sh installs it)"
)
def test_report_figures_load_in_headless_chromium(quickstart_dir, tmp_path):
    out, _ = quickstart_dir
    dom = subprocess.run(
        [
            "chromium",
            *CHROMIUM_FLAGS,
            f"--user-data-dir={tmp_path / 'profile'}",
            "--virtual-time-budget=10000",
            "--dump-dom",
            (out / "report.html").as_uri(),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    ).stdout
    body = re.search(r'<body data-figures="(\d+)" data-figures-loaded="(\d+)"', dom)
    assert body, dom[:500]
    expected, loaded = int(body.group(1)), int(body.group(2))
    assert expected >= 5 and loaded == expected  # real, shipped and fine-tuned sheets, tokenizer, curves
    assert '<table id="eval-table">' in dom


@pytest.mark.slow
def test_rerun_reuses_finished_stages(quickstart_dir):
    out, _ = quickstart_dir
    stdout = run_quickstart(out)
    stages = re.findall(r"\[quickstart\] (\S+): ", stdout)
    assert stages and all(f"[quickstart] {s}: done before, skipped" in stdout for s in stages)


@pytest.mark.slow
def test_a_moved_quickstart_resumes_and_its_fine_tuned_models_find_their_tokenizer(quickstart_dir):
    """The run folder renamed: every stage counts as done, and the fine-tuned models name the shipped
    tokenizer (``shipped:tokenizer``) and their own folders relative to the run, not by the old path."""
    from drivewm.multiview.model import MultiView
    from drivewm.transfer.model import Transfer

    out, _ = quickstart_dir
    moved = out.with_name(out.name + "_moved")
    shutil.move(out, moved)
    try:
        stdout = run_quickstart(moved)
        stages = re.findall(r"\[quickstart\] (\S+): ", stdout)
        assert stages and all(f"[quickstart] {s}: done before, skipped" in stdout for s in stages)
        assert json.loads((moved / FINETUNED / "config.json").read_text())["latent"]["tokenizer"] == "shipped:tokenizer"
        tokenizer = Path(MultiView.from_pretrained(moved / FINETUNED).latent.tokenizer)
        assert tokenizer == model_folders.shipped_model("tokenizer").resolve()
        transfer = Transfer.from_pretrained(moved / "transfer_model")
        assert str(out) not in transfer.parent and Path(transfer.latent.tokenizer) == tokenizer
        assert str(out) not in (moved / "report.md").read_text()
    finally:
        shutil.move(moved, out)
