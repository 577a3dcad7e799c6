"""Bad input to drivewm multiverse: one ``error:`` line, exit status 2, and no output folder."""

from __future__ import annotations

import pytest
from multiverse_logs import write_test_log

from drivewm.cli import main


def _run(capsys, tmp_path, *args: str) -> str:
    code = main(["multiverse", *args, "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("error: ")
    assert not (tmp_path / "out").exists()
    return err[0]


@pytest.mark.parametrize("at", ["4.5", "-1"])
def test_a_branch_time_outside_the_log(capsys, tmp_path, at: str) -> None:
    log = write_test_log(tmp_path / "drive.mcap")
    assert "outside the log" in _run(capsys, tmp_path, "--log", str(log), "--at", at)


def test_an_unknown_plan(capsys, tmp_path) -> None:
    log = write_test_log(tmp_path / "drive.mcap")
    assert "'fly'" in _run(capsys, tmp_path, "--log", str(log), "--at", "1", "--plans", "keep,fly")


@pytest.mark.parametrize(
    "content, message",
    [
        ('{"trajectory_ego": [[1.0, 0.0, 0.0], [NaN, 0.0, 0.0]]}', "NaN"),
        ('{"trajectory_ego": [[1.0, 0.0, 0.0], [2.0, 0.0, 0.0]], "times_s": [0.5, 0.5]}', "increase"),
        ('{"trajectory_ego": [[1.0, 0.0, 0.0], [2.0, 0.0, 0.0]], "times_s": [1.0, NaN]}', "finite"),
    ],
)
def test_a_bad_waypoint_file(capsys, tmp_path, content: str, message: str) -> None:
    log = write_test_log(tmp_path / "drive.mcap")
    plan = tmp_path / "plan.json"
    plan.write_text(content)
    assert message in _run(capsys, tmp_path, "--log", str(log), "--at", "1", "--plans", f"keep,{plan}")


@pytest.mark.parametrize("missing, message", [("poses", "no ego poses"), ("agents", "no road users")])
def test_a_log_without_ego_poses_or_road_users(capsys, tmp_path, missing: str, message: str) -> None:
    log = write_test_log(tmp_path / "drive.mcap", **{missing: False})
    assert message in _run(capsys, tmp_path, "--log", str(log), "--at", "1")


def test_a_turn_on_a_recorded_log(capsys, tmp_path) -> None:
    log = write_test_log(tmp_path / "drive.mcap")
    assert "SUMO" in _run(capsys, tmp_path, "--log", str(log), "--at", "1", "--plans", "turn")


def test_the_model_renderer_needs_a_model_folder(capsys, tmp_path) -> None:
    assert "--model DIR" in _run(capsys, tmp_path, "--scenario", "highway", "--renderer", "model")
    assert "--model DIR" in _run(capsys, tmp_path, "--scenario", "highway", "--model", str(tmp_path))


def test_a_log_needs_a_branch_time(capsys, tmp_path) -> None:
    log = write_test_log(tmp_path / "drive.mcap")
    assert "--at" in _run(capsys, tmp_path, "--log", str(log))


@pytest.mark.parametrize("flags, message", [(["--at", "inf"], "at_s"), (["--horizon", "nan"], "horizon_s")])
def test_times_that_are_not_finite(capsys, tmp_path, flags: list[str], message: str) -> None:
    assert message in _run(capsys, tmp_path, "--scenario", "highway", *flags)


def test_a_turn_in_highway_env(capsys, tmp_path) -> None:
    assert "SUMO" in _run(capsys, tmp_path, "--scenario", "highway", "--plans", "keep,turn")
