"""``drivewm simulate``: simulated multi-camera drives written as MCAP drive logs."""

from __future__ import annotations

import argparse


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "simulate", help="simulate drives (highway-env or SUMO) into MCAP drive logs", description=__doc__
    )
    p.add_argument("--source", choices=["highway", "sumo"], default=None, help="traffic simulator (default highway)")
    p.add_argument(
        "--scenario", default=None, help="highway|merge|roundabout|intersection (highway) or grid|spider|random (sumo)"
    )
    p.add_argument("--rig", default=None, help="rig name (multiview/rigs/) or YAML path (default nuscenes6)")
    p.add_argument("--weather", choices=["clear", "overcast", "rain", "snow", "fog"], default=None)
    p.add_argument("--time-of-day", choices=["day", "dusk", "night"], default=None)
    p.add_argument(
        "--conditions",
        default=None,
        help="render every drive once per WEATHER:TIME (e.g. clear:day,snow:day,clear:night): same traffic, geometry",
    )
    p.add_argument("--traffic", choices=["low", "medium", "high"], default=None, help="traffic density")
    p.add_argument("--duration", type=float, default=None, help="seconds per drive (default 10)")
    p.add_argument("--fps", type=float, default=None, help="frames per second (default 10)")
    p.add_argument("--width", type=int, default=None, help="image width (default: the rig's)")
    p.add_argument("--height", type=int, default=None, help="image height (default: the rig's)")
    p.add_argument("--seed", type=int, default=None, help="first seed (drive i uses seed + i)")
    p.add_argument(
        "--drives",
        type=int,
        default=1,
        help="number of drives (seeds seed, seed+1, ...); recipes give their own counts",
    )
    p.add_argument("--workers", type=int, default=1, help="drives simulated in parallel processes (default 1)")
    p.add_argument("--recipe", default=None, help="dataset recipe YAML (datasets/scenarios/); flags given override it")
    p.add_argument("--out", required=True, help="output folder for the .mcap logs")
    p.set_defaults(func=run_simulate)


FLAG_FIELDS = {
    "source": "source",
    "scenario": "scenario",
    "rig": "rig",
    "weather": "weather",
    "time_of_day": "time_of_day",
    "traffic": "traffic_density",
    "duration": "duration_s",
    "fps": "fps",
    "width": "width",
    "height": "height",
    "seed": "seed",
}


def run_simulate(args: argparse.Namespace) -> int:
    from drivewm.config import from_dict, to_dict
    from drivewm.sim import SimConfig, simulate_many
    from drivewm.sim.paired import in_conditions, parse_conditions
    from drivewm.sim.recipe import load_recipe
    from drivewm.sim.world import sim_rig

    given = {field: getattr(args, flag) for flag, field in FLAG_FIELDS.items() if getattr(args, flag) is not None}
    if args.recipe:
        plan = load_recipe(args.recipe, given | ({"conditions": args.conditions} if args.conditions else {}))
    else:
        cfg = from_dict(SimConfig, given, "drivewm simulate")
        configs = in_conditions(cfg, parse_conditions(args.conditions)) if args.conditions else [cfg]
        plan = [(c, args.drives) for c in configs]
    for cfg, _ in plan:
        sim_rig(cfg)  # every rig loads before the first drive starts
    paths = []
    for cfg, count in plan:
        print(f"simulate {count} drive(s): {to_dict(cfg)}")
        paths += simulate_many(cfg, count, args.out, workers=args.workers)
    for p in paths:
        print(p)
    return 0
