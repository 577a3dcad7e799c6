"""``drivewm simulate``: simulated multi-camera drives written as MCAP drive logs.

The simulator is imported inside the handler, so ``drivewm --help`` stays fast.
"""

from __future__ import annotations

import argparse

from drivewm import resources
from drivewm.choices import add_registry_argument, at_least_one, output_folder, seed
from drivewm.recipe import add_override_arguments


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "simulate",
        help="simulate drives (highway-env or SUMO) into MCAP drive logs",
        description="Simulated multi-camera drives (highway-env or SUMO traffic, a calibrated rig) as MCAP drive logs.",
    )
    add_registry_argument(p, "--source", "drivewm.sim.config:SOURCES", "traffic simulator (default highway)")
    add_registry_argument(
        p, "--scenario", "drivewm.sim.config:ALL_SCENARIOS", "scenario of the source (default: its first)"
    )
    p.add_argument(
        "--rig",
        default=None,
        help="rig name or YAML path (default nuscenes6); names are looked up in $DRIVEWM_RIGS, then packaged: "
        + ", ".join(resources.names("rigs")),
    )
    add_registry_argument(p, "--weather", "drivewm.logs.types:WEATHERS", "weather (default clear)")
    add_registry_argument(p, "--time-of-day", "drivewm.logs.types:TIMES_OF_DAY", "time of day (default day)")
    add_registry_argument(p, "--traffic", "drivewm.logs.types:TRAFFIC_DENSITIES", "traffic density (default medium)")
    p.add_argument(
        "--conditions",
        default=None,
        help="render every drive once per WEATHER:TIME (e.g. clear:day,snow:day,clear:night): same traffic, geometry",
    )
    p.add_argument("--duration", type=float, default=None, help="seconds per drive (default 10)")
    p.add_argument("--fps", type=float, default=None, help="frames per second (default 10)")
    p.add_argument("--width", type=int, default=None, help="image width (default: the rig's)")
    p.add_argument("--height", type=int, default=None, help="image height (default: the rig's)")
    p.add_argument(
        "--exposure-stagger-ms",
        type=float,
        default=None,
        help="camera i exposes at tick + i x this (ms), like rigs that fire cameras in turn (default 0: together)",
    )
    p.add_argument(
        "--labels",
        action="store_true",
        default=None,
        help="also log every image's exact label map (road, lane paint, vehicle, building, vegetation, sky, ...) "
        "as a lossless PNG on /CAMERA/labels",
    )
    p.add_argument("--seed", type=seed, default=None, help="first seed (drive i uses seed + i)")
    p.add_argument(
        "--drives",
        type=at_least_one,
        default=1,
        help="number of drives (seeds seed, seed+1, ...); recipes give their own counts",
    )
    p.add_argument("--workers", type=at_least_one, default=1, help="drives simulated in parallel processes (default 1)")
    p.add_argument(
        "--recipe",
        default=None,
        help="dataset recipe: a YAML path or a packaged name "
        f"({', '.join(resources.names('recipes/simulate'))}); flags and --set apply to every drive",
    )
    add_override_arguments(p, "a SimConfig field in every drive, e.g. jpeg_quality=80", "drives")
    p.add_argument("--out", required=True, type=output_folder, help="output folder for the .mcap logs")
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
    "exposure_stagger_ms": "exposure_stagger_ms",
    "labels": "labels",
}


def run_simulate(args: argparse.Namespace) -> int:
    from drivewm.config import to_dict
    from drivewm.sim import simulate_many
    from drivewm.sim.recipe import load_recipe, plan_drives
    from drivewm.sim.world import sim_rig

    given = {field: getattr(args, flag) for flag, field in FLAG_FIELDS.items() if getattr(args, flag) is not None}
    if args.recipe:
        plan = load_recipe(
            args.recipe,
            given | ({"conditions": args.conditions} if args.conditions is not None else {}),
            args.overrides,
        )
    else:
        plan = plan_drives(given, args.overrides, args.drives, args.conditions)
    for cfg, _ in plan:
        sim_rig(cfg)  # every rig loads before the first drive starts
    for cfg, count in plan:
        print(f"simulate {count} drive(s): {to_dict(cfg)}")
    if args.dry_run:
        return 0
    paths = simulate_many(plan, args.out, workers=args.workers)  # one pool over every entry's drives
    for p in paths:
        print(p)
    return 0
