"""The ``drivewm`` command: the parser builds without importing stage code, and every sub-command is there."""

from __future__ import annotations

import json
import subprocess
import sys

from drivewm.cli import build_parser

#: Not imported by the parser. (The simulator package, with OpenCV and matplotlib, is: see drivewm/sim/__init__.py.)
HEAVY = ("torch", "filterpy", "pycolmap", "highway_env", "libsumo", "rerun", "scenedetect", "ray", "transformers")
COMMANDS = (
    "simulate", "view", "curate", "import-video", "tokenizer", "pretrain", "generate", "posttrain", "rollout", "eval",
    "quickstart",
)  # fmt: skip


def test_help_imports_no_heavy_module():
    """Building the parser and ``drivewm --help`` load no PyTorch, traffic simulator, COLMAP, Rerun or Ray."""
    code = (
        "import json, sys; from drivewm.cli import build_parser; build_parser().format_help(); "
        f"print(json.dumps([m for m in {list(HEAVY)!r} if m in sys.modules]))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert json.loads(out) == []


def test_every_stage_has_its_command():
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    assert set(COMMANDS) <= set(sub.choices)
