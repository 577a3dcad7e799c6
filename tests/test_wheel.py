"""A wheel installed outside the checkout runs simulate, curate and eval from an empty folder.

The wheel is built from a copy of the package's sources (pyproject.toml, README.md, drivewm/) and
installed with ``pip --no-deps`` into a fresh virtual environment without system site packages.
Its third-party dependencies (PyTorch, OpenCV, highway-env, ...) come from the environment running
the tests, through a ``.pth`` file holding that environment's site-packages as a plain path entry:
the ``.pth`` hooks there (the editable install of the checkout) do not run, so ``drivewm`` can only
come from the wheel, which the test checks. Every rig, recipe, reference and table the commands use
is found through the installed package, and the outputs equal the digests recorded on main.
"""

from __future__ import annotations

import json
import os
import shutil
import site
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from test_outputs_unchanged import GOLDEN, SIMULATE, clips_digest, log_digest, metrics_digest

pytestmark = pytest.mark.slow  # builds and installs a wheel, then simulates, curates and evaluates

REPO = Path(__file__).resolve().parents[1]


def _run(cmd: list, cwd: Path, env: dict) -> str:
    proc = subprocess.run([str(c) for c in cmd], cwd=cwd, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, f"{cmd}: {proc.stderr[-2000:]}"
    return proc.stdout


def _wheel(tmp: Path) -> Path:
    """A wheel built from a copy of the sources (the build leaves nothing in the checkout)."""
    src = tmp / "src"
    shutil.copytree(REPO / "drivewm", src / "drivewm", ignore=shutil.ignore_patterns("__pycache__"))
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(REPO / name, src / name)
    pip = [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation", "-w", tmp / "dist", src]
    _run(pip, tmp, dict(os.environ))
    (wheel,) = (tmp / "dist").glob("drivewm-*.whl")
    return wheel


def _venv(tmp: Path, wheel: Path) -> tuple[Path, dict]:
    """A fresh venv with the wheel installed, its dependencies on a plain .pth path; and a clean environment."""
    venv = tmp / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", venv], tmp, dict(os.environ))
    (purelib,) = (venv / "lib").glob("python*/site-packages")
    (purelib / "dependencies.pth").write_text("\n".join(site.getsitepackages()) + "\n")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV", "DRIVEWM_RIGS")}
    env["PATH"] = f"{venv / 'bin'}{os.pathsep}{env['PATH']}"
    _run([venv / "bin" / "python", "-m", "pip", "install", "-q", "--no-deps", "--no-index", wheel], tmp, env)
    return venv, env


def test_wheel_runs_simulate_curate_eval_from_an_empty_folder(tmp_path):
    wheel = _wheel(tmp_path)
    private = [i.filename for i in zipfile.ZipFile(wheel).infolist() if (i.external_attr >> 16) & 0o444 != 0o444]
    assert not private, f"files only their owner can read once installed: {private}"  # e.g. shipped weights
    venv, env = _venv(tmp_path, wheel)
    work = tmp_path / "empty"
    work.mkdir()
    where = _run([venv / "bin" / "python", "-c", "import drivewm; print(drivewm.__file__)"], work, env)
    assert Path(where.strip()).is_relative_to(venv)  # the wheel's drivewm, not the checkout's
    drivewm = venv / "bin" / "drivewm"
    _run([drivewm, *SIMULATE, "--out", "logs"], work, env)  # the packaged nuscenes6 rig
    _run([drivewm, "curate", "logs", "--out", "clips", "--recipe", "test"], work, env)  # a packaged recipe
    _run([drivewm, "eval", "clips", "--out", "eval", "--recipe", "quick", "--no-pictures"], work, env)
    _run([drivewm, "eval", "clips", "--out", "ref", "--recipe", "quick", "--reference", "cosmos_paper"], work, env)
    golden = json.loads(GOLDEN.read_text())["cli"]
    assert {p.name: log_digest(p) for p in sorted((work / "logs").glob("*.mcap"))} == golden["logs"]
    assert clips_digest(work / "clips") == golden["clips"]
    assert metrics_digest(work / "eval") == golden["eval"]  # adherence uses the packaged classifier table
    assert "0.690" in (work / "ref" / "metrics.md").read_text()  # the packaged Cosmos reference beside ours
    assert sorted(p.name for p in work.iterdir()) == ["clips", "eval", "logs", "ref"]
