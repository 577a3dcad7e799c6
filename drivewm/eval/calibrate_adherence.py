"""Fit the adherence classifier on simulator renders and write adherence_calibration.py.

``python -m drivewm.eval.calibrate_adherence [--seeds 2] [--duration 1.5] [--out FILE]`` simulates
short nuscenes6 drives (highway-env and SUMO) for every weather x time-of-day pair, computes
:func:`drivewm.eval.adherence.condition_scores` per drive, fits the nearest-centroid tables and
writes them, with the training accuracy, as a Python module (no data file to ship).
"""

from __future__ import annotations

import argparse
import itertools
import pprint
import tempfile
from pathlib import Path

import numpy as np

from drivewm.atomic import write_text
from drivewm.eval.adherence import FEATURES, classify_condition, condition_scores, fit_calibration

SOURCES = (("highway", "highway"), ("sumo", "grid"))


def render_scores(weather: str, time_of_day: str, seed: int, source: tuple[str, str], duration_s: float) -> dict:
    """Condition scores of one short simulated drive."""
    from drivewm.logs.reader import read_log
    from drivewm.sim import SimConfig, simulate

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


def main(argv: list[str] | None = None) -> int:
    from tqdm import tqdm

    from drivewm.logs.types import TIMES_OF_DAY, WEATHERS

    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--duration", type=float, default=1.5)
    parser.add_argument("--out", default=str(Path(__file__).with_name("adherence_calibration.py")))
    args = parser.parse_args(argv)
    jobs = list(itertools.product(WEATHERS, TIMES_OF_DAY, range(args.seeds), SOURCES))
    samples = [(render_scores(w, t, 100 + s, src, args.duration), w, t) for w, t, s, src in tqdm(jobs, desc="renders")]
    table = fit_calibration(samples)
    preds = [classify_condition(s, table) for s, _, _ in samples]
    acc_w = float(np.mean([p["weather"] == w for p, (_, w, _) in zip(preds, samples)]))
    acc_t = float(np.mean([p["time_of_day"] == t for p, (_, _, t) in zip(preds, samples)]))
    header = (
        f'"""Adherence classifier tables fitted by drivewm.eval.calibrate_adherence on {len(samples)} simulator\n'
        f"renders ({args.seeds} seeds x weathers x times of day x sources {SOURCES}, {args.duration} s at 5 fps).\n"
        f'Training accuracy: weather {acc_w:.3f}, time of day {acc_t:.3f}. Regenerate; do not edit by hand."""\n\n'
    )
    rows = [[w, t] + [round(s[k], 6) for k in FEATURES] for s, w, t in samples]
    write_text(
        args.out,
        header
        + "CALIBRATION = "
        + pprint.pformat(table, width=110, sort_dicts=False)
        + "\n\n"
        + "#: The renders' scores [weather, time_of_day, *FEATURES], kept so the tables can be refitted.\n"
        + "SAMPLES = "
        + pprint.pformat(rows, width=110)
        + "\n",
    )
    print(f"wrote {args.out}: weather accuracy {acc_w:.3f}, time-of-day accuracy {acc_t:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
