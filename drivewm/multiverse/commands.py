"""``drivewm multiverse``: several futures from one moment of a drive, rendered, scored and ranked."""

from __future__ import annotations

import argparse

from drivewm.choices import output_folder, seed


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "multiverse",
        help="branch a drive into several futures (plans), render, score and rank them",
        description="From one moment of a recorded log or a simulated scenario, drive the ego along each plan "
        "(the other road users react in simulators, are replayed from logs), write each future as a drive log with "
        "cameras, score it (collision, TTC, gap, progress, lane keeping, comfort, drivewm eval) and rank them.",
    )
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--log", help="recorded drive log (MCAP) to branch from")
    src.add_argument("--scenario", help="simulator scenario name (highway, merge, grid, ...) or scenario YAML file")
    p.add_argument("--at", type=float, default=None, help="branch time, seconds after the drive's start")
    p.add_argument(
        "--plans",
        default="keep,left,right,brake,accelerate",
        help="comma-separated plans: keep, left, right, brake, accelerate, turn, turn-left, turn-right, or waypoint "
        "files (the format of drivewm generate --trajectory, optional times_s)",
    )
    p.add_argument("--horizon", type=float, default=8.0, help="seconds of each future (default 8)")
    p.add_argument("--prompt", default="", help='conditions to render, e.g. "snow at night"')
    p.add_argument("--renderer", default="sim", choices=["sim", "model"], help="camera renderer (default sim)")
    p.add_argument(
        "--model",
        default="",
        help="--renderer model: a multi-view model folder or shipped:multiview (from the ego trajectory; with the "
        "layout too where the model was trained with one)",
    )
    p.add_argument(
        "--steps", type=int, default=10, help="--renderer model: sampler steps per window (default 10; generate: 35)"
    )
    p.add_argument("--width", type=int, default=320, help="image width (default 320)")
    p.add_argument("--height", type=int, default=192, help="image height (default 192)")
    p.add_argument("--rig", default="nuscenes6", help="rig of simulated scenarios (default nuscenes6)")
    p.add_argument("--seed", type=seed, default=0, help="seed of a scenario named by name (default 0)")
    p.add_argument("--out", required=True, type=output_folder, help="output folder (written whole or not at all)")
    p.set_defaults(func=run_multiverse_command)


def run_multiverse_command(args: argparse.Namespace) -> int:
    from drivewm.config import to_dict
    from drivewm.multiverse import MultiverseConfig, run_multiverse

    cfg = MultiverseConfig(
        log=args.log or "",
        scenario=args.scenario or "",
        at_s=args.at,
        plans=[s.strip() for s in args.plans.split(",") if s.strip()],
        horizon_s=args.horizon,
        prompt=args.prompt,
        renderer=args.renderer,
        model=args.model,
        model_steps=args.steps,
        rig=args.rig,
        width=args.width,
        height=args.height,
        seed=args.seed,
    )
    print(f"multiverse: {to_dict(cfg)}")
    ranking = run_multiverse(cfg, args.out)
    for f in ranking["futures"]:
        s = f["scores"]
        hit = f" collision with {s['collision_with']['track_id']}" if s["collision"] else ""
        hit += "" if f["feasible"] else f" (infeasible: {f['infeasible']})"
        print(f"#{f['rank']} {f['plan']}: progress {s['progress_m']:.1f} m{hit}")
    print(f"{args.out}/report.html")
    return 0
