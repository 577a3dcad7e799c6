"""``drivewm simulate`` end to end, its errors, and the dataset recipes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from drivewm.cli import main
from drivewm.errors import DrivewmError
from drivewm.geometry import load_rig
from drivewm.logs.reader import read_log
from drivewm.sim.recipe import load_recipe

RECIPES = Path(__file__).resolve().parents[2] / "datasets" / "scenarios"


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
    ],
)
def test_bad_input_is_one_clear_error(tmp_path, capsys, argv) -> None:
    assert main(["simulate", *argv, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ")
    assert not list(tmp_path.glob("*.mcap"))


def test_recipes_are_valid() -> None:
    for path in sorted(RECIPES.glob("*.yaml")):
        plan = load_recipe(path)
        assert plan and all(count >= 1 for _, count in plan)
    default = load_recipe(RECIPES / "default.yaml")
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


def test_bad_recipe_names_the_file(tmp_path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("drives:\n  - {source: highway, wheather: snow}\n")
    with pytest.raises(DrivewmError, match="bad.yaml.*wheather"):
        load_recipe(bad)
