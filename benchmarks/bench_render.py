"""Render throughput of drivewm.sim against the traffic simulators' own step rate.

Prints camera-frames/s of the renderer for the 6-camera nuscenes6 rig at 320x192 (the rigs'
demo size) and at 640x360, the simulators' logged ticks/s (highway-env highway, SUMO grid), and
the ratio render-time-per-tick / sim-step-time-per-tick (below 1: the renderer is not the
bottleneck). All times are CPU seconds of this process with OpenCV on one thread, so the
figures mean "one core" even on a shared, busy machine. Also writes a contact sheet of the six
views under every condition (--sheet).

    python benchmarks/bench_render.py            # 4 s drives
    python benchmarks/bench_render.py --full     # 10 s drives and 1280x720 as well
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time
from pathlib import Path

import cv2
import numpy as np

os.environ.setdefault("SDL_VIDEODRIVER", "offscreen")

from drivewm.sim import SimConfig  # noqa: E402
from drivewm.sim.conditions import condition_for  # noqa: E402
from drivewm.sim.drives import record  # noqa: E402
from drivewm.sim.render import Renderer  # noqa: E402
from drivewm.sim.world import TEXTURE_MARGIN_M, build_renderer, sim_rig  # noqa: E402

SHEET_ORDER = ["CAM_FRONT_LEFT", "CAM_FRONT", "CAM_FRONT_RIGHT", "CAM_BACK_LEFT", "CAM_BACK", "CAM_BACK_RIGHT"]
CONDITIONS = [
    ("clear", "day"),
    ("overcast", "day"),
    ("rain", "day"),
    ("snow", "day"),
    ("fog", "day"),
    ("clear", "dusk"),
    ("clear", "night"),
    ("snow", "night"),
]


def render_cpu_s_per_tick(renderer, rec, ticks: int) -> float:
    """Best of two passes over ``ticks`` ticks: CPU seconds per tick (all cameras)."""
    best = float("inf")
    for _ in range(2):
        t0 = time.process_time()
        for tick in rec.ticks[:ticks]:
            renderer.render(tick.T_world_from_ego, tick.agents, tick.timestamp_ns)
        best = min(best, (time.process_time() - t0) / ticks)
    return best


def contact_sheet(cfg: SimConfig, rec, out: Path) -> None:
    """Rows: conditions; columns: the six views of one tick. Written as PNG."""
    tick = rec.ticks[len(rec.ticks) // 2]
    xy = rec.ego_xy()
    lo, hi = xy.min(axis=0) - TEXTURE_MARGIN_M, xy.max(axis=0) + TEXTURE_MARGIN_M
    rows = []
    for weather, tod in CONDITIONS:
        r = Renderer(sim_rig(cfg), rec.road, condition_for(weather, tod), cfg.seed, lo, hi, cfg.source == "sumo")
        images = r.render(tick.T_world_from_ego, tick.agents, tick.timestamp_ns)
        row = np.concatenate([images[n] for n in SHEET_ORDER], axis=1)
        cv2.putText(row, f"{weather}/{tod}", (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (255, 255, 0), 1, cv2.LINE_AA)
        rows.append(row)
    cv2.imwrite(str(out), cv2.cvtColor(np.concatenate(rows, axis=0), cv2.COLOR_RGB2BGR))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--full", action="store_true", help="10 s drives and 1280x720 too")
    ap.add_argument(
        "--sheet", default="/tmp/drivewm_render_contact_sheet", help="contact sheet path prefix (.png per source)"
    )
    args = ap.parse_args()
    cv2.setNumThreads(1)
    duration = 10.0 if args.full else 4.0
    sizes = [(320, 192), (640, 360)] + ([(1280, 720)] if args.full else [])
    for source, scenario in (("highway", "highway"), ("sumo", "grid")):
        base = SimConfig(source=source, scenario=scenario, duration_s=duration, seed=1)
        rec = record(base)
        step_s = rec.step_cpu_s / len(rec.ticks)
        agents = np.mean([len(t.agents) for t in rec.ticks])
        print(
            f"{source}/{scenario}: simulator {1 / step_s:8.1f} ticks/s ({step_s * 1e3:.2f} ms/tick, {agents:.0f} "
            "vehicles)"
        )
        for w, h in sizes:
            cfg = dataclasses.replace(base, width=w, height=h)
            renderer = build_renderer(cfg, rec, sim_rig(cfg))
            per_tick = render_cpu_s_per_tick(renderer, rec, min(len(rec.ticks), 20))
            cams = len(renderer.views)
            print(
                f"  render {w}x{h}: {cams / per_tick:7.1f} camera-frames/s ({per_tick * 1e3:6.1f} ms per {cams}-camera "
                "tick); "
                f"render/sim step time ratio {per_tick / step_s:6.2f}"
            )
        sheet = Path(f"{args.sheet}_{source}.png")
        contact_sheet(base, rec, sheet)
        print(f"  contact sheet: {sheet}")


if __name__ == "__main__":
    main()
