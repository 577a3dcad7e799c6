"""Outputs of simulate, curate, train and eval equal the ones recorded before a refactor (fixed seeds).

``tests/outputs_unchanged.json`` holds digests of each stage's output, recorded with the pinned
environment (torch 2.13.0 CPU, the libx264 of the PyAV wheel, OpenCV's JPEG coder). A digest covers
what a stage writes, not the container around it: the JPEG bytes, poses, calibration, scene and
boxes of a drive log (not the MCAP header, which names library versions); every member of every
clip shard (JSON with the source log's folder removed); the metrics of an eval. A trained model's
``model.safetensors`` is compared within rounding (:data:`WEIGHTS_RTOL`: per-tensor sums), since a
few training steps differ in the last bits between kinds of CPU. A change that means to alter
outputs re-records them with ``python tests/test_outputs_unchanged.py --record`` (which runs itself
again with tests/conftest.py's ``PINNED_ISA``, as pytest runs) and says so in its commit; a refactor
leaves them as they are.
"""

from __future__ import annotations

import hashlib
import io
import json
import sys
import tarfile
from pathlib import Path

import numpy as np
import pytest
import safetensors.torch
from synthetic_latents import make_synthetic_latent_cache

from drivewm.cli import main
from drivewm.logs.reader import read_log

GOLDEN = Path(__file__).with_name("outputs_unchanged.json")

#: Two short drives of the CLI chain: 18 frames each, one 17-frame clip per drive.
SIMULATE = [
    "simulate", "--source", "highway", "--scenario", "merge", "--weather", "rain", "--time-of-day", "dusk",
    "--duration", "1.8", "--width", "160", "--height", "96", "--seed", "11", "--drives", "2",
]  # fmt: skip
TOKENIZER = [
    "--preset",
    "debug",
    "--set",
    "train.steps=3",
    "--set",
    "train.batch_size=2",
    "--set",
    "data.stats_batches=1",
]
PRETRAIN = [
    "--preset", "debug", "--set", "model.hidden_dim=32", "--set", "model.depth=1", "--set", "model.num_heads=2",
    "--set", "model.adaln_lora_dim=8", "--set", "text.dim=16", "--set", "train.steps=3",
    "--set", "train.batch_size=2", "--set", "sample_steps=2",
]  # fmt: skip


def _sha(*chunks: bytes) -> str:
    digest = hashlib.sha256()
    for chunk in chunks:
        digest.update(len(chunk).to_bytes(8, "little"))
        digest.update(chunk)
    return digest.hexdigest()[:20]


def _rounded(obj):
    """``obj`` with every float rounded to 1e-10. Ego poses and box yaws come out of
    the simulator and the log reader with a different last bit in a pytest process than in a plain
    one (the images are the same bytes), so ``--record`` had written digests the test failed on."""
    if isinstance(obj, float):
        return round(obj, 10) + 0.0  # + 0.0: -0.0 reads as 0.0
    if isinstance(obj, dict):
        return {k: _rounded(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_rounded(v) for v in obj]
    if hasattr(obj, "tolist"):  # numpy arrays and scalars
        return _rounded(obj.tolist())
    return obj


def _json_bytes(obj) -> bytes:
    return json.dumps(_rounded(obj), sort_keys=True).encode()


def log_digest(path: Path) -> str:
    """A drive log's content: images (JPEG bytes and times), poses, rig, scene, boxes, static objects and road."""
    log = read_log(path)
    parts = [_json_bytes(log.rig.to_dict()), _json_bytes([log.scene.tags, log.scene.description])]
    for cam in log.rig.names:
        parts += [f.timestamp_ns.to_bytes(8, "little") + f.data for f in log.images[cam]]
    parts += [log.pose_timestamps_ns.tobytes(), _json_bytes(log.T_world_from_ego)]  # poses rounded like the boxes
    for tick, boxes in log.agents:
        fields = [(b.track_id, b.category, b.center_xyz, b.size_lwh, b.yaw_rad, b.color_rgb) for b in boxes]
        parts.append(_json_bytes([tick, fields]))
    parts += [_json_bytes([r.kind, r.points_xyz, r.line_type]) for r in log.road]
    statics = [(b.track_id, b.category, b.center_xyz, b.size_lwh, b.yaw_rad, b.color_rgb) for b in log.static]
    parts += [_json_bytes(statics)] if statics else []  # logs without static objects keep their digest
    return _sha(*parts)


def _portable(name: str, data: bytes) -> bytes:
    """A shard member with the source log's folder dropped (it names a temporary directory) and its
    floats (clip JSON, ego poses) rounded as :func:`_rounded` says."""
    if name.endswith(".npy"):
        return _json_bytes(np.load(io.BytesIO(data), allow_pickle=False))
    if not name.endswith(".json"):
        return data
    meta = json.loads(data)
    meta["source_log"] = Path(meta["source_log"]).name
    return _json_bytes(meta)


#: Shard members digested apart from the clip's frames, poses and JSON (``SHARD:layout``), so the
#: digests of those stay comparable with shards written before the members existed.
SCENE_MEMBERS = (".layout.npz",)


def _members_digest(tar: tarfile.TarFile, members: list[tarfile.TarInfo]) -> str:
    return _sha(*[m.name.encode() + _portable(m.name, tar.extractfile(m).read()) for m in members])


def clips_digest(clip_dir: Path) -> dict[str, str]:
    """Per shard: every member's name and bytes (the layout members under ``SHARD:layout``); and the
    manifest's rows (source log folder dropped)."""
    out = {}
    for shard in sorted(clip_dir.glob("*.tar")):
        with tarfile.open(shard) as tar:
            members = sorted(tar.getmembers(), key=lambda m: m.name)
            clip = [m for m in members if not m.name.endswith(SCENE_MEMBERS)]
            scene = [m for m in members if m.name.endswith(SCENE_MEMBERS)]
            out[shard.name] = _members_digest(tar, clip)
            if scene:
                out[f"{shard.name}:layout"] = _members_digest(tar, scene)
    rows = [json.loads(line) for line in (clip_dir / "manifest.jsonl").read_text().splitlines()]
    out["manifest.jsonl"] = _sha(*[_portable(".json", _json_bytes(r)) for r in rows])
    return out


def metrics_digest(eval_dir: Path) -> dict:
    """metrics.json without timings or paths: the aggregates (rounded to 9 digits), a digest of the per-clip values."""

    def clean(obj):
        if isinstance(obj, dict):
            dropped = ("config", "location", "input")
            return {k: clean(v) for k, v in obj.items() if not k.startswith("seconds") and k not in dropped}
        if isinstance(obj, list):
            return [clean(v) for v in obj]
        return float(f"{obj:.9g}") if isinstance(obj, float) else obj

    metrics = clean(json.loads((eval_dir / "metrics.json").read_text()))
    return {**metrics, "clips": _sha(_json_bytes(metrics["clips"]))}


#: Trained weights are compared within rounding, not byte for byte: a few training steps' weights
#: differ in the last bits between kinds of x86 CPU even on the pinned AVX2 paths (tests/conftest.py;
#: seen between the machines this suite runs on), while a change to the training math moves them by
#: far more than this.
WEIGHTS_RTOL, WEIGHTS_ATOL = 1e-4, 1e-6


def model_fingerprint(model_dir: Path) -> dict[str, list[float]]:
    """Per tensor of the weights file, by name: the sum, the sum of absolute values and the sum of
    squares of its values (float64)."""
    tensors = safetensors.torch.load_file(model_dir / "model.safetensors")
    out = {}
    for name, t in sorted(tensors.items()):
        x = t.double()
        out[name] = [float(x.sum()), float(x.abs().sum()), float((x * x).sum())]
    return out


def assert_same_weights(got: dict, want: dict) -> None:
    """Every tensor's fingerprint within :data:`WEIGHTS_RTOL` of its scale (the sum against the sum of
    absolute values, which keeps a tensor whose values cancel from passing on noise)."""
    assert sorted(got) == sorted(want)
    for name, (total, size, power) in want.items():
        scale = np.array([size, size, power])
        error = np.abs(np.array(got[name]) - np.array([total, size, power]))
        assert np.all(error <= WEIGHTS_RTOL * scale + WEIGHTS_ATOL), (name, got[name], want[name])


def _run(*argv) -> None:
    assert main([str(a) for a in argv]) == 0, argv


def cli_chain(root: Path) -> dict:
    """simulate -> curate -> eval -> tokenizer train through the command line; the digests of each."""
    logs, clips, ev, tok = root / "logs", root / "clips", root / "eval", root / "tok"
    _run(*SIMULATE, "--out", logs)
    _run("curate", logs, "--out", clips, "--recipe", "test")
    _run("eval", clips, "--out", ev, "--recipe", "quick", "--no-pictures")
    _run("tokenizer", "train", "--data", clips, "--out", tok, *TOKENIZER)
    return {
        "logs": {p.name: log_digest(p) for p in sorted(logs.glob("*.mcap"))},
        "clips": clips_digest(clips),
        "eval": metrics_digest(ev),
        "tokenizer": model_fingerprint(tok),
    }


def pretrain_digest(root: Path) -> dict:
    """Text2World pretraining of a tiny DiT for 3 steps on the seeded synthetic latent cache."""
    cache = make_synthetic_latent_cache(root / "latents", clips_per_condition=2)
    _run("pretrain", "--data", cache, "--out", root / "t2w", *PRETRAIN)
    return model_fingerprint(root / "t2w")


def fixture_digests(sim_log_dir: Path, sim_clip_dir: Path) -> dict:
    """The shared simulated logs and their clips (tests/conftest.py)."""
    return {
        "logs": {p.name: log_digest(p) for p in sorted(sim_log_dir.glob("*.mcap"))},
        "clips": clips_digest(sim_clip_dir),
    }


@pytest.fixture(scope="module")
def golden() -> dict:
    return json.loads(GOLDEN.read_text())


def test_fixture_logs_and_clips_unchanged(golden, sim_log_dir, sim_clip_dir):
    assert fixture_digests(sim_log_dir, sim_clip_dir) == golden["fixtures"]


@pytest.mark.slow
def test_cli_chain_outputs_unchanged(golden, tmp_path):
    """In a fresh interpreter, as a user runs the commands (the chain's outputs must not depend on
    what earlier tests left in the process; tests/sim/test_determinism.py checks that for the one
    leak found, highway-env's intersection scenario rewriting IDMVehicle's class constants)."""
    import subprocess

    code = (
        "import json, sys, torch; from pathlib import Path; sys.path.insert(0, sys.argv[1]); torch.set_num_threads(1);"
        " from test_outputs_unchanged import cli_chain; print(json.dumps(cli_chain(Path(sys.argv[2]))))"
    )
    run = subprocess.run(
        [sys.executable, "-c", code, str(Path(__file__).parent), str(tmp_path)], capture_output=True, text=True
    )
    assert run.returncode == 0, run.stderr[-3000:]
    got = json.loads(run.stdout.strip().splitlines()[-1])
    assert got["logs"] == golden["cli"]["logs"]
    assert got["clips"] == golden["cli"]["clips"]
    assert got["eval"] == golden["cli"]["eval"]
    assert_same_weights(got["tokenizer"], golden["cli"]["tokenizer"])


@pytest.mark.slow
def test_pretrain_output_unchanged(golden, tmp_path):
    import torch

    torch.set_num_threads(1)
    assert_same_weights(pretrain_digest(tmp_path), golden["pretrain"])


if __name__ == "__main__":
    if sys.argv[1:] != ["--record"]:
        raise SystemExit(f"usage: python {sys.argv[0]} --record   (rewrites {GOLDEN.name} from this checkout)")
    import os
    import tempfile

    unpinned = {k for k in ("ATEN_CPU_CAPABILITY", "NPY_DISABLE_CPU_FEATURES") if k not in os.environ}
    import conftest  # the shared fixtures' builders; sets the pinned vector ISA in os.environ
    import torch

    if unpinned & set(conftest.PINNED_ISA):  # numpy and torch loaded unpinned above: run again pinned, as pytest does
        os.execv(sys.executable, [sys.executable, *sys.argv])

    torch.set_num_threads(1)  # as every test runs (conftest._one_torch_thread): reductions depend on it

    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        record = {
            "fixtures": fixture_digests(conftest.sim_logs(), conftest.sim_clips()),
            "cli": cli_chain(root / "cli"),
            "pretrain": pretrain_digest(root / "t2w"),
        }
    GOLDEN.write_text(json.dumps(record, indent=1, sort_keys=True) + "\n")
    print(f"wrote {GOLDEN}")
