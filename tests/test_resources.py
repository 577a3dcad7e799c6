"""Package data: found by name through the package, the user's folders first, paths as given, all of it shipped."""

from __future__ import annotations

import ast
import fnmatch
import re
from pathlib import Path

import pytest

from drivewm import resources
from drivewm.errors import DrivewmError
from drivewm.eval.report import load_reference
from drivewm.geometry import load_rig
from drivewm.logs.topicmap import load_topic_map
from drivewm.product.quickstart import RECIPE, load_profile

REPO = Path(__file__).resolve().parents[1]


def test_every_packaged_file_loads():
    assert resources.names("rigs") == ["cosmos7", "front1", "front3", "nuscenes6", "nuscenes6_calib"]
    assert [len(load_rig(n).cameras) for n in resources.names("rigs")] == [7, 1, 3, 6, 6]
    assert {load_topic_map(n).source for n in resources.names("topicmaps")} == {
        str(resources.package_dir("topicmaps") / f"{n}.yaml") for n in resources.names("topicmaps")
    }
    assert load_reference("cosmos_paper")["metrics"]["tse"] == 0.69
    assert load_reference("sim_clips")["metrics"]["tse"] > 0
    assert [load_profile(name).rig for name in ("full", "smoke")] == ["nuscenes6", "nuscenes6"]
    assert RECIPE.is_relative_to(resources.package_dir(""))


def test_user_folders_come_first_and_paths_work(tmp_path, monkeypatch):
    mine = tmp_path / "rigs"
    mine.mkdir()
    (mine / "nuscenes6.yaml").write_text(
        "name: mine\ncameras:\n  - {name: C, width: 64, height: 32, hfov_deg: 90, xyz: [0, 0, 1]}\n"
    )
    assert load_rig("nuscenes6").names[0] == "CAM_FRONT"
    monkeypatch.setenv("DRIVEWM_RIGS", f"{tmp_path / 'missing'}:{mine}")
    assert load_rig("nuscenes6").names == ["C"]  # the user's rig of that name wins
    assert load_rig("front3").names[1] == "CAM_FRONT"  # names the user lacks still come from the package
    assert load_rig(mine / "nuscenes6.yaml").name == "mine"
    with pytest.raises(
        DrivewmError, match=r"rig 'nope': no such file .*packaged: cosmos7, front1, front3, nuscenes6, nuscenes6_calib"
    ):
        load_rig("nope")


def test_every_data_file_of_the_package_is_declared_for_the_wheel():
    """A data file added under drivewm/ without a package-data pattern would be missing from wheels."""
    section = (REPO / "pyproject.toml").read_text().split("[tool.setuptools.package-data]")[1]
    patterns = ast.literal_eval(re.search(r"^drivewm = (\[.*\])$", section, re.M).group(1))  # no tomllib on 3.10
    package = REPO / "drivewm"
    data = [
        p.relative_to(package).as_posix() for p in package.rglob("*") if p.is_file() and p.suffix not in (".py", ".pyc")
    ]
    assert len(data) > 20
    assert [f for f in data if not any(fnmatch.fnmatch(f, pat) for pat in patterns)] == []
