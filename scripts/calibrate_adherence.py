"""Fit the adherence classifier on simulator renders and write drivewm/tables/adherence_calibration.json.

``python scripts/calibrate_adherence.py [--seeds 2] [--duration 1.0] [--out FILE]`` simulates short
nuscenes6 drives (highway-env and SUMO) for every weather x time-of-day pair, computes
:func:`drivewm.eval.adherence.condition_scores` per drive, fits the nearest-centroid tables
(:func:`drivewm.eval.adherence.fit_calibration`) and writes them, with the training accuracy, as the
JSON table the package ships (read by :func:`drivewm.eval.adherence.load_calibration`).
"""

from __future__ import annotations

import argparse
import itertools
import json
import re
import tempfile
from pathlib import Path

import numpy as np
from tqdm import tqdm

from drivewm import resources
from drivewm.atomic import write_text
from drivewm.eval.adherence import classify_condition, condition_scores, fit_calibration
from drivewm.logs.reader import read_log
from drivewm.logs.types import TIMES_OF_DAY, WEATHERS
from drivewm.sim import SimConfig, simulate

SOURCES = (("highway", "highway"), ("sumo", "grid"))


def render_scores(weather: str, time_of_day: str, seed: int, source: tuple[str, str], duration_s: float) -> dict:
    """Condition scores of one short simulated drive."""
    cfg = SimConfig(
        source=source[0],
        scenario=source[1],
        weather=weather,
        time_of_day=time_of_day,
        duration_s=duration_s,
        fps=5.0,
        seed=seed,
    )
    with tempfile.TemporaryDirectory() as tmp:
        log = read_log(simulate(cfg, Path(tmp) / "drive.mcap", progress=False))
    n = min(len(v) for v in log.images.values())
    frames = np.stack([[f.decode() for f in log.images[c][:n]] for c in log.rig.names])
    return condition_scores(frames)


def table_json(table: dict) -> str:
    """The table as JSON with every list of numbers on one line."""
    text = json.dumps(table, indent=1)
    return re.sub(r"\[\s+([^\[\]{}]*?)\s+\]", lambda m: "[" + re.sub(r"\s+", " ", m.group(1)) + "]", text) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--duration", type=float, default=1.0)
    parser.add_argument("--out", default=str(resources.package_dir("tables") / "adherence_calibration.json"))
    args = parser.parse_args(argv)
    jobs = list(itertools.product(WEATHERS, TIMES_OF_DAY, range(args.seeds), SOURCES))
    samples = [(render_scores(w, t, 100 + s, src, args.duration), w, t) for w, t, s, src in tqdm(jobs, desc="renders")]
    table = fit_calibration(samples)
    preds = [classify_condition(s, table) for s, _, _ in samples]
    acc_w = float(np.mean([p["weather"] == w for p, (_, w, _) in zip(preds, samples)]))
    acc_t = float(np.mean([p["time_of_day"] == t for p, (_, _, t) in zip(preds, samples)]))
    sources = " and ".join(f"{a} {b}" for a, b in SOURCES)
    record = {
        "source": f"scripts/calibrate_adherence.py: nearest-centroid tables fitted on {len(samples)} simulator renders "
        f"({args.seeds} seeds x weathers x times of day x sources {sources}, {args.duration} s at 5 fps)",
        "accuracy": {"weather": round(acc_w, 3), "time_of_day": round(acc_t, 3)},
        **table,
    }
    write_text(Path(args.out), table_json(record))
    print(f"wrote {args.out}: weather accuracy {acc_w:.3f}, time-of-day accuracy {acc_t:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
