"""Fit the adherence classifier on simulator renders and write drivewm/tables/adherence_calibration.json.

``python scripts/calibrate_adherence.py [--seeds 2] [--duration 1.0] [--tokenizer shipped:tokenizer]
[--coded-size 160x96] [--out FILE]`` simulates short nuscenes6 drives (highway-env and SUMO) for
every weather x time-of-day pair, computes :func:`drivewm.eval.adherence.condition_scores` per drive,
fits the nearest-centroid tables (:func:`fit_calibration`) and writes them,
with the training accuracy per domain, as the JSON table the package ships (read by
:func:`drivewm.eval.adherence.load_calibration`). With ``--tokenizer``, every pair is rendered once
more as a clip is curated (17 frames at 10 fps), resized to ``--coded-size`` and coded by that
tokenizer (encode, decode): the ``coded`` domain, what generated and transferred clips look like.
"""

from __future__ import annotations

import argparse
import itertools
import json
import re
import tempfile
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from drivewm import resources
from drivewm.atomic import write_text
from drivewm.choices import model_folder
from drivewm.eval.adherence import FEATURES, classify_condition, condition_scores
from drivewm.logs.reader import read_log
from drivewm.logs.types import TIMES_OF_DAY, WEATHERS
from drivewm.multiview.coding import code_views
from drivewm.sim import SimConfig, simulate
from drivewm.tokenizer import Tokenizer

SOURCES = (("highway", "highway"), ("sumo", "grid"))
CODED_FRAMES, CODED_FPS = 17, 10.0  # a curated clip's length and rate (curate recipes worldmodel, transfer)


def fit_calibration(samples: list[tuple]) -> dict:
    """Fit the classifier tables from (scores, weather, time_of_day[, domain]) samples of labelled
    renders; a sample with a domain (say ``coded``) adds to that domain's centroid of its class."""
    X = np.array([[s[0][k] for k in FEATURES] for s in samples])
    mean, std = X.mean(0), X.std(0) + 1e-6
    Z = (X - mean) / std
    labels = np.array(["/".join(s[1:3]) + (f"/{s[3]}" if len(s) > 3 and s[3] else "") for s in samples])
    cents = {str(c): Z[labels == c].mean(0).round(6).tolist() for c in sorted(set(labels))}
    return {
        "features": list(FEATURES),
        "mean": mean.round(8).tolist(),
        "std": std.round(8).tolist(),
        "centroids": cents,
    }


def render(weather: str, time_of_day: str, seed: int, source: tuple[str, str], duration_s: float, fps: float):
    """uint8 frames (V, T, H, W, 3) of one short simulated drive."""
    cfg = SimConfig(
        source=source[0],
        scenario=source[1],
        weather=weather,
        time_of_day=time_of_day,
        duration_s=duration_s,
        fps=fps,
        seed=seed,
    )
    with tempfile.TemporaryDirectory() as tmp:
        log = read_log(simulate(cfg, Path(tmp) / "drive.mcap", progress=False))
    n = min(len(v) for v in log.images.values())
    return np.stack([[f.decode() for f in log.images[c][:n]] for c in log.rig.names])


def table_json(table: dict) -> str:
    """The table as JSON with every list of numbers on one line."""
    text = json.dumps(table, indent=1)
    return re.sub(r"\[\s+([^\[\]{}]*?)\s+\]", lambda m: "[" + re.sub(r"\s+", " ", m.group(1)) + "]", text) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--duration", type=float, default=1.0)
    parser.add_argument(
        "--tokenizer", type=model_folder, help="add the coded domain: tokenizer folder or shipped:tokenizer"
    )
    parser.add_argument("--coded-size", default="160x96", help="WIDTHxHEIGHT the coded renders are resized to")
    parser.add_argument("--out", default=str(resources.package_dir("tables") / "adherence_calibration.json"))
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    jobs = list(itertools.product(WEATHERS, TIMES_OF_DAY, range(args.seeds), SOURCES))
    samples = [
        (condition_scores(render(w, t, 100 + s, src, args.duration, 5.0)), w, t, "")
        for w, t, s, src in tqdm(jobs, desc="renders")
    ]
    sources = " and ".join(f"{a} {b}" for a, b in SOURCES)
    what = f"{args.seeds} seeds x weathers x times of day x sources {sources}, {args.duration} s at 5 fps"
    if args.tokenizer:
        tok, (w, h) = Tokenizer.from_pretrained(args.tokenizer), (int(v) for v in args.coded_size.split("x"))
        duration = CODED_FRAMES / CODED_FPS
        for wx, t, s, src in tqdm(jobs, desc="coded renders"):
            frames = code_views(tok, render(wx, t, 100 + s, src, duration, CODED_FPS), (h, w))
            samples.append((condition_scores(frames), wx, t, "coded"))
        what += (
            f"; the same pairs as {CODED_FRAMES}-frame {CODED_FPS:g} fps clips at {args.coded_size} coded by the "
            f"tokenizer {Path(args.tokenizer).name} (domain coded)"
        )
    table = fit_calibration(samples)
    accuracy = {}
    for domain in sorted({d for *_, d in samples}):
        part = [(classify_condition(x, table), w, t) for x, w, t, d in samples if d == domain]
        accuracy[domain or "rendered"] = {
            "weather": round(float(np.mean([p["weather"] == w for p, w, _ in part])), 3),
            "time_of_day": round(float(np.mean([p["time_of_day"] == t for p, _, t in part])), 3),
        }
    record = {
        "source": f"scripts/calibrate_adherence.py: nearest-centroid tables fitted on {len(samples)} simulator "
        f"renders ({what})",
        "accuracy": accuracy,
        **table,
    }
    write_text(Path(args.out), table_json(record))
    print(f"wrote {args.out}: training accuracy {accuracy}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
