"""``drivewm simulate`` end to end, its errors, and the dataset recipes."""

from __future__ import annotations

import numpy as np
import pytest

from drivewm import resources
from drivewm.cli import main
from drivewm.errors import DrivewmError
from drivewm.geometry import load_rig
from drivewm.logs.reader import read_log
from drivewm.logs.types import TIMES_OF_DAY, TRAFFIC_DENSITIES, WEATHERS
from drivewm.sim.config import ALL_SCENARIOS, SOURCES
from drivewm.sim.recipe import RECIPES, load_recipe


@pytest.mark.slow
def test_simulate_command_writes_logs(tmp_path) -> None:
    rc = main(
        [
            "simulate",
            "--source",
            "highway",
            "--scenario",
            "merge",
            "--weather",
            "fog",
            "--time-of-day",
            "dusk",
            "--duration",
            "0.3",
            "--width",
            "160",
            "--height",
            "96",
            "--seed",
            "4",
            "--drives",
            "2",
            "--workers",
            "2",
            "--out",
            str(tmp_path),
        ]
    )
    assert rc == 0
    paths = sorted(tmp_path.glob("*.mcap"))
    assert [p.name for p in paths] == ["highway_merge_fog_dusk_s0004.mcap", "highway_merge_fog_dusk_s0005.mcap"]
    log = read_log(paths[0])
    assert log.scene.tags["weather"] == "fog" and log.scene.tags["time_of_day"] == "dusk"
    assert log.images["CAM_FRONT"][0].decode().shape == (96, 160, 3)
    np.testing.assert_allclose(
        log.rig.camera("CAM_FRONT").K, load_rig("nuscenes6").scaled(160, 96).camera("CAM_FRONT").K
    )
    mtime = paths[0].stat().st_mtime_ns
    assert (
        main(
            [
                "simulate",
                "--scenario",
                "merge",
                "--weather",
                "fog",
                "--time-of-day",
                "dusk",
                "--duration",
                "0.3",
                "--width",
                "160",
                "--height",
                "96",
                "--seed",
                "4",
                "--out",
                str(tmp_path),
            ]
        )
        == 0
    )
    assert paths[0].stat().st_mtime_ns == mtime  # an existing drive is kept: reruns resume


@pytest.mark.parametrize(
    "argv",
    [
        ["--scenario", "grid"],
        ["--source", "sumo", "--scenario", "highway"],
        ["--duration", "-1"],
        ["--width", "100"],
        ["--rig", "no_such_rig"],
        ["--set", "jpeg_qualty=80"],
        ["--recipe", "no_such_recipe"],
    ],
)
def test_bad_input_is_one_clear_error(tmp_path, capsys, argv) -> None:
    assert main(["simulate", *argv, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ")
    assert not list(tmp_path.glob("*.mcap"))


def test_recipes_are_valid() -> None:
    assert resources.names(RECIPES) == [
        "default",
        "layout",
        "layout_heldout",
        "quickstart",
        "smoke",
        "transfer",
        "transfer_heldout",
        "transfer_validation",
        "turns",
        "weather_finetune",
        "worldmodel",
        "worldmodel_heldout",
    ]
    for name in resources.names(RECIPES):
        plan = load_recipe(name)
        assert plan and all(count >= 1 for _, count in plan)
    default = load_recipe("default")
    assert {c.source for c, _ in default} == {"highway", "sumo"}
    assert {c.scenario for c, _ in default} == {
        "highway",
        "merge",
        "roundabout",
        "intersection",
        "grid",
        "spider",
        "random",
    }
    assert {c.weather for c, _ in default} == {"clear", "overcast", "rain", "snow", "fog"}
    assert {c.time_of_day for c, _ in default} == {"day", "dusk", "night"}


def test_worldmodel_heldout_drives_share_no_seed_with_training() -> None:
    train, heldout = load_recipe("worldmodel"), load_recipe("worldmodel_heldout")
    train_seeds = {c.seed + i for c, count in train for i in range(count)}
    heldout_seeds = {c.seed + i for c, count in heldout for i in range(count)}
    assert len(heldout_seeds) >= 12 and not train_seeds & heldout_seeds
    assert {c.weather for c, _ in heldout} == {c.weather for c, _ in train}
    drive = lambda c: (c.source, c.scenario, c.weather, c.time_of_day, c.seed)  # noqa: E731
    finetune = {drive(c) for c, _ in load_recipe("weather_finetune")}
    assert not {d[-1] for d in finetune} & heldout_seeds  # the benchmark's held-out drives stay unseen
    # a fine-tune drive on a worldmodel seed is that recipe's drive, not another one on its seed
    assert {d for d in finetune if d[-1] in train_seeds} <= {drive(c) for c, _ in train}


def test_transfer_validation_drives_are_neither_trained_on_nor_benchmarked() -> None:
    used = {c.seed + i for name in ("transfer", "transfer_heldout") for c, n in load_recipe(name) for i in range(n)}
    validation = load_recipe("transfer_validation")
    assert len(validation) == 24 and not {c.seed + i for c, n in validation for i in range(n)} & used


def test_turns_recipe_turns_in_every_weather_on_seeds_of_its_own() -> None:
    turns = load_recipe("turns")
    assert {c.weather for c, _ in turns} == {"clear", "overcast", "rain", "snow", "fog"}
    assert {c.time_of_day for c, _ in turns} == {"day", "dusk", "night"}
    assert {c.scenario for c, _ in turns} == {"roundabout", "intersection", "grid", "spider"}
    other_recipes = [load_recipe(name) for name in resources.names(RECIPES) if name != "turns"]
    others = {c.seed + i for plan in other_recipes for c, n in plan for i in range(n)}
    seeds = {c.seed + i for c, n in turns for i in range(n)}
    assert not seeds & others  # new drives (the held-out ones included), not another recipe's seeds re-rendered


def test_bad_recipe_names_the_file(tmp_path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("drives:\n  - {source: highway, wheather: snow}\n")
    with pytest.raises(DrivewmError, match="bad.yaml.*wheather"):
        load_recipe(bad)


def test_flags_and_set_apply_to_every_drive_of_a_recipe(tmp_path, capsys) -> None:
    argv = ["simulate", "--recipe", "smoke", "--weather", "fog", "--set", "jpeg_quality=80", "--dry-run"]
    assert main([*argv, "--out", str(tmp_path)]) == 0
    lines = [line for line in capsys.readouterr().out.splitlines() if line.startswith("simulate ")]
    assert len(lines) == 2 and all("'weather': 'fog'" in line and "'jpeg_quality': 80" in line for line in lines)
    assert "'source': 'highway'" in lines[0] and "'source': 'sumo'" in lines[1]
    assert not list(tmp_path.iterdir())  # a dry run writes nothing


def test_choices_are_the_registries(capsys) -> None:
    assert main(["simulate", "--help"]) == 0
    page = " ".join(capsys.readouterr().out.split())
    for names in (SOURCES, ALL_SCENARIOS, WEATHERS, TIMES_OF_DAY, TRAFFIC_DENSITIES, resources.names("rigs")):
        assert ", ".join(names) in page
    assert main(["simulate", "--weather", "hail", "--out", "x"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "invalid choice: 'hail'" in err[0]


def test_drive_seeds_past_the_largest_seed_are_refused_before_any_drive(tmp_path, capsys) -> None:
    """Drive i uses seed + i: ``--seed 2147483647 --drives 2`` had written the first drive, then failed
    on the second's seed."""
    argv = ["simulate", "--seed", "2147483647", "--drives", "2", "--duration", "0.5", "--rig", "front1"]
    assert main([*argv, "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    message = "2 drives from seed 2147483647 use seeds up to 2147483648, past the largest seed 2147483647"
    assert err == f"error: drivewm simulate: {message}"
    assert not (tmp_path / "out").exists() or not list((tmp_path / "out").iterdir())
    (tmp_path / "r.yaml").write_text("drives:\n  - {seed: 2147483640, count: 9}\n")
    with pytest.raises(
        DrivewmError, match=r"r.yaml: drives\[0\]: 9 drives from seed 2147483640 use seeds up to 2147483648"
    ):
        load_recipe(tmp_path / "r.yaml")
    assert main(["simulate", "--seed", "2147483646", "--drives", "2", "--dry-run", "--out", str(tmp_path)]) == 0


def test_empty_conditions_are_an_error_not_ignored(tmp_path, capsys) -> None:
    """``conditions: []`` in a recipe and ``--conditions ''`` had been taken as "no conditions" and
    rendered the default weather, while ``--conditions ,`` was refused."""
    (tmp_path / "r.yaml").write_text("drives:\n  - {conditions: []}\n")
    with pytest.raises(DrivewmError, match=r"r.yaml: drives\[0\].conditions: conditions \[\]: name at least one"):
        load_recipe(tmp_path / "r.yaml")
    for recipe in ([], ["--recipe", "smoke"]):
        assert main(["simulate", *recipe, "--conditions", "", "--dry-run", "--out", str(tmp_path / "o")]) == 2
        assert capsys.readouterr().err.strip().endswith("conditions '': name at least one WEATHER:TIME")


@pytest.mark.slow
def test_a_recipe_is_one_batch_of_drives_and_a_drive_named_twice_is_simulated_once(tmp_path, capsys) -> None:
    """Every entry of a recipe goes into one pool of --workers processes (entries of one drive each
    had run one after another), and two entries naming the same drive write it once."""
    from drivewm.sim import simulate_many

    (tmp_path / "r.yaml").write_text(
        "common: {source: highway, duration_s: 0.3, width: 160, height: 96, rig: front3}\n"
        "drives:\n"
        "  - {scenario: merge, weather: fog, seed: 4}\n"
        "  - {scenario: highway, weather: snow, seed: 7, count: 2}\n"
        "  - {scenario: merge, weather: fog, seed: 3, count: 2}\n"  # seeds 3 and 4: s0004 again
    )
    plan = load_recipe(tmp_path / "r.yaml")
    paths = simulate_many(plan, tmp_path / "logs", progress=False, workers=2)
    names = ["highway_merge_fog_day_s0004", "highway_highway_snow_day_s0007", "highway_highway_snow_day_s0008"]
    assert [p.stem for p in paths] == [*names, "highway_merge_fog_day_s0003"]
    assert sorted(p.stem for p in (tmp_path / "logs").glob("*.mcap")) == sorted(p.stem for p in paths)
    assert (
        main(["simulate", "--recipe", str(tmp_path / "r.yaml"), "--workers", "2", "--out", str(tmp_path / "logs")]) == 0
    )
    assert capsys.readouterr().out.count(".mcap") == 4  # the rerun finds every drive written: none twice
