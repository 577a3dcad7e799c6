"""Fuzz (issue 15): seeded mutations of valid MCAP logs and clip shards (truncate, flip bytes, rename
members, edit JSON fields) run through ``drivewm curate``, ``tokenizer encode`` and ``eval``.

Whatever the mutation, each command returns 0 or 2 (never raises: no traceback), reports every bad
input with a clear reason (never "unexpected error"), writes nothing outside its output folder, and
still processes the good input in the same batch. The fast tier runs a few mutations of each kind;
the slow one many more.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from drivewm.cli import main
from drivewm.tokenizer.config import preset
from drivewm.tokenizer.model import Tokenizer

sys.path.insert(0, str(Path(__file__).parent / "clips"))
sys.path.insert(0, str(Path(__file__).parent / "curate"))
from hostile_shards import members, write_members, write_shard  # noqa: E402
from synth import write_synth_log  # noqa: E402

CONFIG = "test"  # the packaged curation recipe drivewm/recipes/curate/test.yaml
HOSTILE_VALUES = [
    None, -1, 0, 1e308, float("nan"), "abc", "../../evil", "/tmp/evil", [], {}, True, 10**30, "x" * 300,
    [[0, 0, 0], [0, 0, 0], [0, 0, 1]], [[1, 2], [3]], {"cameras": []}, [1, "a", None],
]  # fmt: skip
JSON_FIELDS = [
    ("key",), ("fps",), ("timestamps_ns",), ("rig",), ("format_version",), ("start_time_ns",), ("tags",),
    ("trajectory_ego",), ("quality",), ("rig", "cameras"), ("rig", "cameras", 0, "K"), ("rig", "cameras", 0, "name"),
    ("rig", "cameras", 0, "width"), ("rig", "cameras", 0, "T_ego_from_cam"), ("view_captions",),
]  # fmt: skip


def snapshot(root: Path) -> dict[Path, tuple[int, int]]:
    return {p: (p.stat().st_size, p.stat().st_mtime_ns) for p in root.rglob("*") if p.is_file()}


def run_cli(capsys, argv: list[str], root: Path, allowed: list[Path]) -> tuple[int, str]:
    """Run one command: it returns 0 or 2 without raising, prints no traceback, and changes files only
    under ``allowed`` folders."""
    before = snapshot(root)
    rc = main(argv)
    err = capsys.readouterr().err
    after = snapshot(root)
    changed = {p for p in after if before.get(p) != after[p]} | (set(before) - set(after))
    outside = [p for p in changed if not any(p.is_relative_to(a) for a in allowed)]
    assert rc in (0, 2) and "Traceback" not in err, err[-3000:]
    assert not outside, f"{argv[0]} wrote outside its output folder: {sorted(outside)[:5]}"
    assert "unexpected error" not in err, err[-3000:]
    return rc, err


def flip_bytes(data: bytes, rng: np.random.Generator) -> bytes:
    buf = bytearray(data)
    for pos in rng.integers(0, len(buf), int(rng.integers(1, 40))):
        buf[pos] ^= int(rng.integers(1, 256))
    return bytes(buf)


def truncate(data: bytes, rng: np.random.Generator) -> bytes:
    return data[: int(len(data) * rng.uniform(0.05, 0.97))]


def edit_field(meta: dict, path: tuple, value) -> None:
    node = meta
    for part in path[:-1]:
        node = node[part] if isinstance(node, dict) or (isinstance(node, list) and len(node) > part) else None
        if node is None:
            return
    if isinstance(node, dict) or (isinstance(node, list) and len(node) > path[-1]):
        node[path[-1]] = value


def mutate_shard(items: list[tuple[str, bytes]], kind: str, rng: np.random.Generator) -> list[tuple[str, bytes]]:
    """A mutated copy of a shard's members (rename / edit_json / flip a member's bytes)."""
    items = list(items)
    i = int(rng.integers(len(items)))
    name, data = items[i]
    key, _, rest = name.partition(".")
    if kind == "rename":
        new = rng.choice(
            [f"../{name}", f"/tmp/{name}", f"{key}.NOPE.mp4", f"other.{rest}", key, f".{name}", "a/b.json"]
        )
        items[i] = (str(new), data)
    elif kind == "edit_json":
        i = next(j for j, (n, _) in enumerate(items) if n.endswith(".json"))
        meta = json.loads(items[i][1])
        edit_field(
            meta,
            JSON_FIELDS[int(rng.integers(len(JSON_FIELDS)))],
            HOSTILE_VALUES[int(rng.integers(len(HOSTILE_VALUES)))],
        )
        items[i] = (items[i][0], json.dumps(meta).encode())
    else:
        items[i] = (name, flip_bytes(data, rng))
    return items


@pytest.fixture(scope="module")
def tokenizer_dir(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("tok") / "tok"
    Tokenizer(preset("debug")).save_pretrained(path)
    return path


def _shard_batch(root: Path, count: int, seed: int) -> tuple[Path, list[str]]:
    """A clip folder: one good shard (keys good0, good1) and ``count`` mutated copies of another shard."""
    clips = root / "clips"
    write_shard(clips, "good", ["good0", "good1"])
    template = members(write_shard(root / "src", "t", ["t0", "t1"]))
    tar_bytes = (root / "src" / "t-000000.tar").read_bytes()
    rng = np.random.default_rng(seed)
    kinds = ["truncate", "flip_tar", "rename", "edit_json", "flip_member"]
    for n in range(count):
        kind = kinds[n % len(kinds)]
        path = clips / f"m{n:02d}-000000.tar"
        if kind == "truncate":
            path.write_bytes(truncate(tar_bytes, rng))
        elif kind == "flip_tar":
            path.write_bytes(flip_bytes(tar_bytes, rng))
        else:
            renamed = [(f"m{n}{name[1:]}", data) for name, data in template]  # keys m<n>0, m<n>1: no clash
            write_members(path, mutate_shard(renamed, kind, rng))
    return clips, ["good0", "good1"]


def _log_batch(root: Path, count: int, seed: int) -> tuple[list[Path], Path]:
    """One good drive log and ``count`` mutated copies of another (truncated, bytes flipped)."""
    logs = root / "logs"
    good = write_synth_log(logs / "good.mcap", seed=1, n_frames=20, rig="front1")
    template = write_synth_log(root / "src" / "t.mcap", seed=2, n_frames=20, rig="front1").read_bytes()
    rng = np.random.default_rng(seed)
    paths = [good]
    for n in range(count):
        path = logs / f"m{n:02d}.mcap"
        path.write_bytes(truncate(template, rng) if n % 2 else flip_bytes(template, rng))
        paths.append(path)
    return paths, good


def _fuzz(root: Path, capsys, tokenizer_dir: Path, count: int, seed: int) -> None:
    logs, good = _log_batch(root, count, seed)
    rc, err = run_cli(
        capsys, ["curate", *map(str, logs), "--out", str(root / "out"), "--recipe", CONFIG], root, [root / "out"]
    )
    report = json.loads((root / "out" / "report.json").read_text())
    assert rc == 0 and report["logs"]["good"]["status"] == "ok" and report["logs"]["good"]["kept"] == 1
    assert all(log["status"] == "ok" or log["error"] for log in report["logs"].values())
    assert sum(log["status"] == "failed" for log in report["logs"].values()) >= count // 2  # truncations at least

    clips, good_keys = _shard_batch(root, count, seed)
    rc, err = run_cli(
        capsys, ["tokenizer", "encode", "--model", str(tokenizer_dir), "--data", str(clips)], root, [clips / "latents"]
    )
    index = json.loads((clips / "latents" / "tok" / "index.json").read_text())
    assert rc == 0 and set(good_keys) <= {row["key"] for row in index["clips"]}

    out = root / "eval"
    rc, err = run_cli(capsys, ["eval", str(clips), "--out", str(out), "--metrics", "tse", "--no-pictures"], root, [out])
    scored = json.loads((out / "metrics.json").read_text())["clips"]
    assert rc == 0 and all("error" not in scored[k] for k in good_keys)
    failed = [k for k, m in scored.items() if "error" in m]
    assert len(failed) >= count // 2 and all(f"warning: failed {scored[k]['error']}" in err for k in failed)


def test_fuzzed_logs_and_shards(tmp_path, capsys, tokenizer_dir):
    _fuzz(tmp_path, capsys, tokenizer_dir, count=5, seed=0)


@pytest.mark.slow  # about a minute: many more mutations
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_fuzzed_logs_and_shards_many(tmp_path, capsys, tokenizer_dir, seed):
    _fuzz(tmp_path, capsys, tokenizer_dir, count=15, seed=seed)
