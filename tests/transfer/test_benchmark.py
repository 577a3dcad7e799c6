"""Which held-out pairs the transfer benchmark scores."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

from drivewm.model_folders import WEIGHTS_DIR

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from transfer_benchmark import spread_over_drives  # noqa: E402


def test_a_subset_of_pairs_spans_every_drive_even_where_a_clip_was_dropped() -> None:
    # three drives of five clips; curation dropped drive b's first clip (bad exposure at night)
    ids = [f"{d}-s{n}-h-t{t:06d}" for d, n in (("a", 1), ("b", 2), ("c", 3)) for t in range(0, 340, 68)]
    ids.remove("b-s2-h-t000000")
    order = spread_over_drives(ids[::-1])
    assert order[:3] == ["a-s1-h-t000000", "b-s2-h-t000068", "c-s3-h-t000000"]
    assert order[3:6] == ["a-s1-h-t000068", "b-s2-h-t000136", "c-s3-h-t000068"]
    assert sorted(order) == sorted(ids)  # nothing lost, nothing twice
    # evenly spaced over the sorted ids (the rule before) took drive a's last clip and skipped drive b
    before = [sorted(ids)[int(k * len(ids) / 3)] for k in range(3)]
    assert [i.split("-")[0] for i in before] == ["a", "a", "c"]


def load_bench_transfer():
    path = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_transfer.py"
    spec = importlib.util.spec_from_file_location("bench_transfer", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--max-pairs", "0"], "--max-pairs must be >= 1"),
        (["--sdedit-sigmas", ","], "--sdedit-sigmas: at least one"),
        (["--sdedit-sigmas", "1,x"], "--sdedit-sigmas: comma-separated numbers"),
        (["--looks", "both"], "--looks: comma-separated shared and/or own"),
        (["--targets", "rain:day"], "no held-out pairs in .*clear:day.*rain:day"),
    ],
)
def test_bench_transfer_refuses_what_it_cannot_score(tmp_path, args, message) -> None:
    """Each refused with one line naming the option; the last after the models load, on a folder of
    clips without a rain pair (an empty one)."""
    bench = load_bench_transfer()
    with pytest.raises(SystemExit, match=message):
        bench.main(["--model", str(WEIGHTS_DIR / "transfer"), "--data", str(tmp_path), *args])


def test_bench_transfer_names_a_missing_folder(tmp_path) -> None:
    with pytest.raises(SystemExit, match="--data: .*none does not exist"):
        load_bench_transfer().main(["--model", str(WEIGHTS_DIR / "transfer"), "--data", str(tmp_path / "none")])
    with pytest.raises(SystemExit, match="--parent: .*t2w does not exist"):
        load_bench_transfer().main(["--parent", str(tmp_path / "t2w"), "--data", str(tmp_path)])


def test_bench_transfer_reads_shipped_names_as_the_installed_folders(tmp_path, capsys) -> None:
    """No --model: the shipped transfer model, as ``drivewm transfer`` and bench_transfer_look.py
    take it (the option was a plain path, so ``--model shipped:transfer`` was a missing folder); an
    unknown kind is refused by name before any model loads."""
    bench = load_bench_transfer()
    args = bench.parse_args(["--data", str(tmp_path), "--parent", "shipped:text2world"])
    bench.check_args(args)
    assert args.model == WEIGHTS_DIR / "transfer" and args.parent == WEIGHTS_DIR / "text2world"
    with pytest.raises(SystemExit):
        bench.main(["--model", "shipped:transfr", "--data", str(tmp_path)])
    assert "--model: no shipped model 'transfr'" in capsys.readouterr().err
