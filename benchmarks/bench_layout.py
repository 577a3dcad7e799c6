"""Layout renderer speed against the simulator's own renderer on the same drive, in the same run.

One clip: the 6-camera nuscenes6 rig at 320x192, 17 frames. The simulator renders the drive's 17
ticks (its ground, textured boxes, fog); the layout renderer draws the clip's layout (built from the
same recording without pixels, drivewm.layout.layout_from_recording) into the same cameras: its
set-up (ground map, box sets, camera rays) plus the 17 frames. Rounds alternate between the two
after a warm-up round; medians of CPU time (time.process_time, OpenCV on one thread) are printed as
ms per clip and the ratio layout / simulator (below 1: the layout costs less than rendering the
drive). Pixels per clip and boxes in the layout are printed beside.

    python benchmarks/bench_layout.py                 # highway and SUMO grid, 5 rounds
    python benchmarks/bench_layout.py --rounds 9
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import cv2

os.environ.setdefault("SDL_VIDEODRIVER", "offscreen")

from drivewm.layout.recording import layout_from_recording  # noqa: E402
from drivewm.layout.render import LayoutRenderer  # noqa: E402
from drivewm.sim import SimConfig  # noqa: E402
from drivewm.sim.drives import record  # noqa: E402
from drivewm.sim.world import build_renderer, sim_rig  # noqa: E402

FRAMES = 17


def cpu_s(run) -> float:
    tic = time.process_time()
    run()
    return time.process_time() - tic


def bench(source: str, scenario: str, rounds: int) -> None:
    cfg = SimConfig(source=source, scenario=scenario, duration_s=FRAMES / 10, width=320, height=192, seed=7)
    rec = record(cfg)
    rig = sim_rig(cfg)
    simulator = build_renderer(cfg, rec, rig)
    layout = layout_from_recording(rec, cfg, 0, FRAMES)
    ticks = rec.ticks[:FRAMES]

    def simulate() -> None:
        for tick in ticks:
            simulator.render(tick.T_world_from_ego, tick.agents, tick.timestamp_ns)

    def draw_layout() -> None:
        LayoutRenderer(rig, layout).render()

    times = {"simulator": [], "layout": []}
    for r in range(rounds + 1):
        for name, run in (("simulator", simulate), ("layout", draw_layout)):
            seconds = cpu_s(run)
            if r:
                times[name].append(seconds)
    sim_ms, layout_ms = (statistics.median(times[k]) * 1000 for k in ("simulator", "layout"))
    pixels = len(rig.cameras) * FRAMES * 320 * 192
    print(
        f"{source}/{scenario:12s} boxes {layout.num_boxes:4d} lines {len(layout.line_kind):3d}  "
        f"simulator {sim_ms:7.1f} ms/clip  layout {layout_ms:7.1f} ms/clip  ratio {layout_ms / sim_ms:5.2f}  "
        f"({pixels / 1e6:.2f} Mpx per clip, {rounds} rounds, medians of CPU time)"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=5, help="timed rounds per renderer, alternating (after a warm-up)")
    args = ap.parse_args()
    cv2.setNumThreads(1)
    for source, scenario in (("highway", "highway"), ("sumo", "grid")):
        bench(source, scenario, args.rounds)


if __name__ == "__main__":
    main()
