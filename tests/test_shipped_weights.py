"""The weights drivewm ships (drivewm/weights/): intact, within the size limits, loadable, and
generating what they generated when they were exported (fixed seed, stored statistics).

``tests/shipped_generation.json`` holds per-camera pixel statistics of a small fixed-seed generation
with the shipped multi-view model, at generate's defaults (the network's own frames) and with the
``reprojected`` recipe's post-steps. Replacing the shipped weights or changing those settings
re-records it with ``python tests/test_shipped_weights.py --record`` in the same commit.
"""

from __future__ import annotations

import json
import re
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest
from safetensors import safe_open

from drivewm.cli import main
from drivewm.clips import iter_clips
from drivewm.errors import DrivewmError
from drivewm.generate.config import POST_STEPS
from drivewm.model_folders import WEIGHTS_DIR, shipped_model
from drivewm.product.release import MAX_FILE_BYTES, MAX_TOTAL_BYTES, check_manifest, export_run, folder_extra

STATS = Path(__file__).with_name("shipped_generation.json")
# generate's defaults otherwise (plain sampling, the prompt template)
GENERATE = [
    "generate", "--prompt", "a snowy highway at dusk, the car ahead brakes", "--rig", "nuscenes6",
    "--trajectory", "left", "--steps", "3", "--guidance", "3", "--seed", "7", "--num-samples", "1", "--device", "cpu",
]  # fmt: skip
#: The settings recorded: generate's defaults, and the opt-in post-steps of the ``reprojected`` recipe.
SETTINGS = {"defaults": [], "reprojected": ["--recipe", "reprojected", "--set", "reproject.steps=3"]}
KINDS = ("tokenizer", "text2world", "multiview", "transfer")


def test_every_shipped_file_is_in_the_manifest_with_its_sha256_and_within_the_limits():
    manifest = check_manifest()  # raises on any sha256 mismatch
    on_disk = {str(p.relative_to(WEIGHTS_DIR)) for p in WEIGHTS_DIR.rglob("*") if p.is_file()}
    assert on_disk - set(manifest["files"]) == {"MANIFEST.json", "MODEL_CARD.md"}
    sizes = [e["bytes"] for e in manifest["files"].values()]
    assert max(sizes) <= MAX_FILE_BYTES and sum(sizes) <= MAX_TOTAL_BYTES
    card = (WEIGHTS_DIR / "MODEL_CARD.md").read_text()
    assert all(e["sha256"] in card for e in manifest["files"].values())
    for kind in KINDS:
        with safe_open(str(shipped_model(kind) / "model.safetensors"), "pt") as f:
            dtypes = {f.get_slice(k).get_dtype() for k in f.keys()}
        assert dtypes <= {"F16", "I64", "BOOL"}, (kind, dtypes)
        assert manifest["training"][kind]["steps"] > 0


def test_the_shipped_diffusion_models_share_the_shipped_tokenizers_latent_space():
    """Every shipped diffusion model was trained on latents normalised by the shipped tokenizer's
    statistics; a tokenizer replaced by a decoder fine-tune (as the shipped one is) must keep
    them, and the encoder that made them, or every shipped model would read its latents wrongly."""
    tokenizer = json.loads((shipped_model("tokenizer") / "config.json").read_text())
    for kind in ("text2world", "multiview", "transfer"):
        latent = json.loads((shipped_model(kind) / "config.json").read_text())["latent"]
        assert latent["tokenizer"] == "../tokenizer", kind
        for stat in ("latent_mean", "latent_std"):
            assert latent[stat] == tokenizer[stat], (kind, stat)
    record = json.loads((WEIGHTS_DIR / "MANIFEST.json").read_text())["training"]["tokenizer"]
    assert all("freeze_encoder" in tune["note"] for tune in record.get("fine_tunes", []))


def test_a_changed_byte_is_refused(tmp_path):
    copy = tmp_path / "weights"
    shutil.copytree(WEIGHTS_DIR, copy)
    target = copy / "multiview" / "model.safetensors"
    data = bytearray(target.read_bytes())
    data[len(data) // 2] ^= 0xFF
    target.write_bytes(bytes(data))
    with pytest.raises(DrivewmError, match="multiview/model.safetensors: sha256 differs"):
        check_manifest(copy)


def test_export_of_a_run_writes_fp16_folders_manifest_and_card(tmp_path):
    """Round trip: a run made of the shipped folders exports to the same tensors, a manifest that
    checks, and a card naming every sha256; a file over the limit is refused."""
    run = tmp_path / "run"
    for kind in KINDS:
        shutil.copytree(shipped_model(kind), run / kind)
    files = export_run(run, tmp_path / "out", notes="trained for a test")
    manifest = check_manifest(tmp_path / "out")
    card = (tmp_path / "out" / "MODEL_CARD.md").read_text()
    assert all(e["sha256"] in card for e in manifest["files"].values()) and "trained for a test" in card
    assert {p.name for p in files} >= {"model.safetensors", "config.json", "MANIFEST.json", "MODEL_CARD.md"}
    for kind in KINDS:
        assert (tmp_path / "out" / kind / "model.safetensors").read_bytes() == (
            shipped_model(kind) / "model.safetensors"
        ).read_bytes()


def test_the_card_says_how_the_scored_clips_were_sampled_and_which_were_post_processed(tmp_path):
    """The evaluation section names each generated clip's sampler settings and post-steps as generate
    recorded them: the network's own frames apart from post-processed ones, each with its clip count."""
    from drivewm.clips.shards import write_manifest
    from drivewm.generate.config import RECIPES
    from drivewm.product.model_card import write_model_card

    run, out = tmp_path / "run", tmp_path / "out"
    plain = RECIPES.resolve(None, None, ["sampling.steps=20"]).record()
    post = RECIPES.resolve(None, "reprojected", ["sampling.steps=20"]).record()
    write_manifest(run / "generated" / "snow_left", [{"key": "a", **plain}, {"key": "b", **plain}])
    write_manifest(run / "generated" / "fog_left", [{"key": "c", **post}])
    out.mkdir()
    card = write_model_card(run, out, {"files": {}}).read_text()
    evaluation = card.split("## Evaluation")[1].split("## Files")[0]
    assert "- 2 generated clips: steps 20, sampler heun, guidance 7.0," in evaluation
    assert "no post-steps (the network's own frames)" in evaluation
    assert "- 1 generated clip: steps 20" in evaluation
    assert "post-processed by reproject, reshade, blend, stitch (reproject sigma 0.1, steps 10)" in evaluation
    assert "## Intended use and licence" in card and "Apache-2.0" in card


def test_a_fine_tune_replaces_one_folder_and_its_record_adds_up(tmp_path):
    """`replace_shipped` swaps one folder for its fine-tune: fp16, a manifest that checks against the new
    bytes, the other folders untouched, and steps and seconds added to the folder's record."""
    import torch
    from safetensors.torch import load_file

    from drivewm.product.release import replace_shipped
    from drivewm.train.checkpoint import load_model_folder, save_model_folder, save_train_state

    root = tmp_path / "weights"
    shutil.copytree(WEIGHTS_DIR, root)
    before = json.loads((root / "MANIFEST.json").read_text())
    info, state = load_model_folder(shipped_model("multiview"), "multiview")
    tuned = {k: v.float() + 0.01 if v.is_floating_point() else v for k, v in state.items()}
    extra = folder_extra(info)
    save_model_folder(tmp_path / "ft", "multiview", info["config"], tuned, extra)
    save_train_state(
        tmp_path / "ft", {"step": 120, "train_seconds": 30.0, "model": {}, "ema": {}, "optimizer": {}, "rng": {}}
    )
    manifest = replace_shipped("multiview", tmp_path / "ft", root)
    assert check_manifest(root) == manifest
    after = load_file(root / "multiview" / "model.safetensors")
    assert all(after[k].dtype == torch.float16 for k in after if after[k].is_floating_point())
    k = next(k for k in after if after[k].is_floating_point())
    assert torch.allclose(after[k].float(), tuned[k].half().float())
    for kind in ("tokenizer", "text2world", "transfer"):
        assert manifest["training"][kind] == before["training"][kind]
        for name in ("config.json", "model.safetensors"):
            assert manifest["files"][f"{kind}/{name}"] == before["files"][f"{kind}/{name}"]
    record, old = manifest["training"]["multiview"], before["training"]["multiview"]
    assert record["steps"] == old["steps"] + 120 and record["train_seconds"] == pytest.approx(old["train_seconds"] + 30)
    assert record["fine_tunes"][-1] == {"steps": 120, "train_seconds": 30.0}
    with pytest.raises(DrivewmError, match="no train_state.pt"):
        replace_shipped("multiview", shipped_model("multiview"), root)


def test_a_gpu_fine_tune_without_its_train_state_is_recorded_from_its_metrics_apart_from_cpu_time(tmp_path):
    """A run brought back from a GPU machine with its weights and metrics only: its steps and seconds come
    from the last metrics row, and its seconds count as GPU seconds, not CPU seconds."""
    from drivewm.product.release import replace_shipped

    root = tmp_path / "weights"
    shutil.copytree(WEIGHTS_DIR, root)
    before = json.loads((root / "MANIFEST.json").read_text())["training"]["multiview"]
    shutil.copytree(shipped_model("multiview"), tmp_path / "ft")
    rows = [{"step": 20, "loss": 0.5, "train_seconds": 4.0}, {"step": 40, "loss": 0.4, "train_seconds": 7.5}]
    (tmp_path / "ft" / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    manifest = replace_shipped("multiview", tmp_path / "ft", root, device="cuda (NVIDIA H200)", note="mixed 1:1")
    record = manifest["training"]["multiview"]
    assert record["steps"] == before["steps"] + 40
    assert record["train_seconds"] == before["train_seconds"]
    assert record["gpu_seconds"] == pytest.approx(before.get("gpu_seconds", 0.0) + 7.5)
    assert record["fine_tunes"][-1] == {
        "steps": 40,
        "train_seconds": 7.5,
        "device": "cuda (NVIDIA H200)",
        "note": "mixed 1:1",
    }
    (tmp_path / "ft" / "metrics.jsonl").write_text("not json\n")
    with pytest.raises(DrivewmError, match="not a training loop's metrics row"):
        replace_shipped("multiview", tmp_path / "ft", root)


def test_a_fine_tune_mixed_with_the_shipped_model_is_the_weighted_mean_and_keeps_the_chosen_settings(tmp_path):
    """`drivewm worldmodel interpolate` (WiSE-FT): every float tensor is (1 - alpha) * base + alpha * tuned,
    the config and latent settings are the folder named by --config-from, the shipped tokenizer stays
    reachable from anywhere, and models that do not mix are refused with the reason."""
    import torch

    from drivewm.multiview.model import MultiView
    from drivewm.product.release import interpolate_folders
    from drivewm.train.checkpoint import load_model_folder, save_model_folder

    info, base = load_model_folder("shipped:multiview", "multiview")
    tuned = {k: v.float() + 0.5 if v.is_floating_point() else v for k, v in base.items()}
    extra = folder_extra(info)
    config = json.loads(json.dumps(info["config"]))
    config["multiview"]["speed_mps"] = 7.0
    save_model_folder(tmp_path / "ft", "multiview", config, tuned, extra)
    shutil.copytree(shipped_model("tokenizer"), tmp_path / "tokenizer")  # the fine-tune's ../tokenizer
    out = tmp_path / "mixed"
    assert main(["worldmodel", "interpolate", "shipped:multiview", str(tmp_path / "ft"), "--alpha", "0.25",
                 "--config-from", "base", "--out", str(out)]) == 0  # fmt: skip
    got_info, got = load_model_folder(out, "multiview")
    k = next(k for k in base if base[k].is_floating_point())
    assert torch.allclose(got[k], base[k].float() + 0.125, atol=1e-6)
    assert got_info["config"]["multiview"]["speed_mps"] == info["config"]["multiview"]["speed_mps"]
    assert got_info["latent"]["tokenizer"] == "shipped:tokenizer"  # wherever drivewm is installed
    assert Path(MultiView.from_pretrained(out).latent.tokenizer) == shipped_model("tokenizer").resolve()
    assert MultiView.from_pretrained(out).cfg.multiview.speed_mps == info["config"]["multiview"]["speed_mps"]
    tuned_info, _ = load_model_folder(
        interpolate_folders("shipped:multiview", tmp_path / "ft", 1.0, tmp_path / "t"), "multiview"
    )
    assert tuned_info["config"]["multiview"]["speed_mps"] == 7.0
    with pytest.raises(DrivewmError, match=r"alpha must be in \[0, 1\]"):
        interpolate_folders("shipped:multiview", tmp_path / "ft", 1.5, tmp_path / "bad")
    with pytest.raises(DrivewmError, match="is a multiview model, .* a drivewm-tokenizer"):
        interpolate_folders("shipped:multiview", "shipped:tokenizer", 0.5, tmp_path / "bad")
    save_model_folder(tmp_path / "cut", "multiview", config, dict(list(tuned.items())[1:]), extra)
    with pytest.raises(DrivewmError, match="differ in structure"):
        interpolate_folders("shipped:multiview", tmp_path / "cut", 0.5, tmp_path / "bad")
    assert not (tmp_path / "bad").exists()


def test_the_model_cards_reprojected_figures_are_the_committed_benchmark_outputs():
    """The card's post-processed ``--recipe reprojected`` column is ``docs/benchmark/shipped/figures.json``
    (what ``drivewm worldmodel benchmark --recipe reprojected`` wrote), figure for figure, value and
    verdict; the network's own frames have a column of their own."""
    figures = json.loads((Path(__file__).parents[1] / "docs/benchmark/shipped/figures.json").read_text())
    card = (WEIGHTS_DIR / "MODEL_CARD.md").read_text()
    table = [[c.strip() for c in line.split("|")[1:-1]] for line in card.splitlines() if line.startswith("| ")]
    header = next(row for row in table if row[0] == "figure" and len(row) > 4)
    column = next(i for i, title in enumerate(header) if "--recipe reprojected" in title)
    assert header[column].startswith("post-processed") and header[1] == "network's own frames"
    rows = {row[0]: row[column] for row in table if len(row) == len(header)}
    measured = {name: f for name, f in figures.items() if isinstance(f, dict)}
    assert len(measured) == 13 and figures["generated_clips"] >= 24
    for name, figure in measured.items():
        value, verdict = rows[name].split()[0].rstrip(":"), re.search(r": (holds|fails)\b", rows[name]).group(1)
        if figure["value"] is not None:
            assert value == f"{figure['value']:g}", (name, value)
        assert verdict == ("holds" if figure["holds"] else "fails"), name


def test_the_model_card_cites_only_docs_that_exist_and_carries_no_dates():
    """Every repository path the shipped card names exists, and the card holds no dated history."""
    root = Path(__file__).parents[1]
    card = (WEIGHTS_DIR / "MODEL_CARD.md").read_text()
    paths = set(re.findall(r"\b((?:docs|studies|benchmarks|scripts|drivewm)/[\w./-]*\w/?)", card))
    assert "docs/results.md" in paths and "docs/benchmark/shipped/" in paths
    assert [p for p in sorted(paths) if not (root / p).exists()] == []
    assert re.findall(r"\b20\d\d-\d\d-\d\d\b", card) == []


def generation_stats(out: Path) -> dict[str, list[float]]:
    """Per camera of the generated clip: mean and std of the pixels, and the mean of the top and
    bottom thirds (sky and road, in a model that learned where they are)."""
    stats = {}
    for clip in iter_clips(out):
        for cam in clip.meta.cameras:
            frames = clip.video(cam).astype(np.float64)  # (T, H, W, 3)
            third = frames.shape[1] // 3
            stats[cam] = [frames.mean(), frames.std(), frames[:, :third].mean(), frames[:, -third:].mean()]
    return stats


@pytest.mark.slow
@pytest.mark.parametrize("settings", sorted(SETTINGS))
def test_fixed_seed_generation_matches_the_stored_statistics(tmp_path, settings):
    """No --model: generate uses the shipped multi-view model (and its shipped tokenizer). The clip
    records the post-steps it went through: none at the defaults."""
    assert main([*GENERATE, *SETTINGS[settings], "--out", str(tmp_path)]) == 0
    got = generation_stats(tmp_path)
    want = json.loads(STATS.read_text())[settings]
    (clip,) = iter_clips(tmp_path)
    assert clip.meta.extra["post_processing"] == ([] if settings == "defaults" else list(POST_STEPS))
    assert sorted(got) == sorted(want) and len(got) == 6  # one mp4 per nuScenes camera
    for cam, values in want.items():
        np.testing.assert_allclose(got[cam], values, atol=2.0, err_msg=cam)  # 8-bit levels


@pytest.mark.slow
def test_the_shipped_transfer_model_turns_an_unseen_clear_clip_to_snow_and_keeps_its_geometry(tmp_path, sim_clip_dir):
    """No --model: ``drivewm transfer`` uses the shipped transfer model. A clear-day clip of the test
    fixture (a drive it never saw) comes out as snow by the eval's classifier, with every SIFT match
    within 2 px of its source position (issue 18's must-hold), labels kept."""
    from drivewm.diffusion.generate import video_to_uint8
    from drivewm.multiview.coding import frames_to_video
    from drivewm.transfer.retarget import TargetCondition

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
    from transfer_metrics import adherent, sift_shift_px

    clear = next(c for c in iter_clips(sim_clip_dir) if c.meta.tags.get("weather") == "clear")
    assert main(["transfer", str(sim_clip_dir), "--to", "snow", "--max-clips", "1", "--out", str(tmp_path)]) == 0
    (out,) = list(iter_clips(tmp_path))
    assert out.meta.extra["transfer"]["source"]["key"] == clear.key and out.meta.tags["weather"] == "snow"
    videos = out.videos()
    source = video_to_uint8(frames_to_video(clear.videos(), videos.shape[2:4]))
    assert (
        adherent(videos, TargetCondition("snow", clear.meta.tags.get("time_of_day", "day")))["predicted"]["weather"]
        == "snow"
    )
    assert sift_shift_px(source, videos)["median_px"] <= 2.0


if __name__ == "__main__":
    if sys.argv[1:] != ["--record"]:
        raise SystemExit(f"usage: python {sys.argv[0]} --record   (rewrites {STATS.name} from the shipped weights)")
    import tempfile

    import torch

    torch.set_num_threads(1)
    stats = {}
    for name, flags in SETTINGS.items():
        with tempfile.TemporaryDirectory() as tmp:
            assert main([*GENERATE, *flags, "--out", tmp]) == 0
            stats[name] = generation_stats(Path(tmp))
    STATS.write_text(json.dumps(stats, indent=1) + "\n")
    print(f"wrote {STATS}")


def test_a_config_field_naming_a_shipped_model_loads_it():
    """``--set init=shipped:tokenizer`` (a tokenizer run's decoder fine-tuning)
    reads the installed folder, tensor for tensor; an unknown kind is a one-line error."""
    from drivewm.train.checkpoint import load_model_folder

    info, state = load_model_folder("shipped:tokenizer", "drivewm-tokenizer")
    _, direct = load_model_folder(shipped_model("tokenizer"), "drivewm-tokenizer")
    assert info["model_type"] == "drivewm-tokenizer" and state.keys() == direct.keys()
    assert all(np.array_equal(state[k].numpy(), direct[k].numpy()) for k in state)
    with pytest.raises(DrivewmError, match="no shipped model 'tokeniser'"):
        load_model_folder("shipped:tokeniser", "drivewm-tokenizer")


def test_the_bundles_named_shipped_find_their_tokenizer_and_parent_from_any_directory(tmp_path, monkeypatch):
    """``Transfer.from_pretrained("shipped:transfer")`` (the Python API, not only the CLI, which resolves
    the name first): the shipped configs point at ``../tokenizer`` and ``../text2world``, relative to the
    installed folder, not to the working directory (they were resolved against "shipped:transfer")."""
    from drivewm.diffusion.text2world import Text2World
    from drivewm.multiview.model import MultiView
    from drivewm.transfer.model import Transfer

    monkeypatch.chdir(tmp_path)
    tokenizer = shipped_model("tokenizer").resolve()
    transfer = Transfer.from_pretrained("shipped:transfer")
    assert Path(transfer.latent.tokenizer) == tokenizer
    assert Path(transfer.parent) == shipped_model("text2world").resolve()
    for bundle, kind in ((Text2World, "text2world"), (MultiView, "multiview")):
        assert Path(bundle.from_pretrained(f"shipped:{kind}").latent.tokenizer) == tokenizer, kind
