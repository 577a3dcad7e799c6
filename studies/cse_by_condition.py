"""Where do generated clips lose the camera pairs CSE counts: in which weathers, and which pairs?

The CSE must-hold asks the generated clips to keep the protocol's minimum of verified cross-view
matches as often as the held-out clips do (docs/eval-protocol.md). Over a whole benchmark that is
one fraction, and the two sides need not share a mix of conditions: the benchmark's prompts name
their weather in the sample folder (``fog_left/sample_000``), the held-out clips in their key
(``highway_roundabout_fog_night_s5190-...``). This reads two ``drivewm eval`` metrics.json files
(the generated clips', then the held-out clips') and prints, per weather, the share of camera pairs
counted on each side, and per camera pair the mean distinct verified matches and the share counted.

    python studies/cse_by_condition.py RUN/eval/generated/metrics.json RUN/eval/heldout/metrics.json

Numbers: git show a88b7a4:docs/quality-vs-compute.md, "Cameras that disagree where they overlap".
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

import numpy as np

WEATHERS = ("clear", "overcast", "rain", "snow", "fog", "night")
"""The conditions a generated sample's folder or a held-out clip's key names; night is its own
condition for the benchmark's prompts (a clear night), as the held-out keys' time of day."""


def condition(key: str) -> str:
    """The condition a clip's key names: its time of day if night, else its weather ("?" if none)."""
    words = set(re.split(r"[_/:\-]", key))
    if "night" in words:
        return "night"
    return next((w for w in WEATHERS if w in words), "?")


def per_clip(metrics: dict) -> list[tuple[str, list[str], list[int], list[bool]]]:
    """(condition, camera pairs, distinct verified matches per pair, whether each pair counted) per
    clip; a pair counts where the eval scored it (a median), not where it fell short of the
    protocol's minimum of matches."""
    rows = []
    for key, clip in metrics["clips"].items():
        if "cse_pairs" not in clip:
            continue
        matches = [m or 0 for m in clip["cse_calibrated_pair_matches"]]
        counted = [m is not None for m in clip["cse_calibrated_pair_medians"]]
        rows.append((condition(key), clip["cse_pairs"], matches, counted))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("generated", type=Path, help="drivewm eval metrics.json of the generated clips")
    parser.add_argument("heldout", type=Path, help="drivewm eval metrics.json of the held-out clips")
    args = parser.parse_args()
    sides = {name: per_clip(json.loads(path.read_text())) for name, path in vars(args).items()}
    print(f"{'condition':10s} | " + " | ".join(f"{s}: clips, pairs counted" for s in sides))
    for w in (*WEATHERS, "?"):
        cells = []
        for rows in sides.values():
            counted = [np.mean(c) for cond, _, _, c in rows if cond == w]
            cells.append(f"{len(counted):3d}, {np.mean(counted):6.1%}" if counted else "  -")
        if any(c.strip() != "-" for c in cells):
            print(f"{w:10s} | " + " | ".join(f"{c:24s}" for c in cells))
    overall = [f"{len(r):3d}, {np.mean([np.mean(c) for *_, c in r]):6.1%}" for r in sides.values()]
    print(f"{'all':10s} | " + " | ".join(f"{c:24s}" for c in overall))
    print(f"\n{'camera pair':32s} | " + " | ".join(f"{s}: matches, counted" for s in sides))
    pairs = sides["generated"][0][1] if sides["generated"] else []
    for i, pair in enumerate(pairs):
        cells = []
        for rows in sides.values():
            m = [matches[i] for _, _, matches, _ in rows]
            cells.append(f"{np.mean(m):5.1f}, {np.mean([c[i] for *_, c in rows]):6.1%}")
        print(f"{pair:32s} | " + " | ".join(f"{c:24s}" for c in cells))


if __name__ == "__main__":
    main()
