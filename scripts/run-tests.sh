#!/usr/bin/env bash
# Install drivewm with its test extras into .venv, check lint and formatting (ruff), and run the whole
# test suite (CPU only). Arguments go to pytest, e.g. -m "not slow" for the fast tier.
# PyTorch is pinned first: a bare torch requirement would pull the CUDA build.
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -m venv .venv
. .venv/bin/activate
python -m pip install -q --upgrade pip
python -m pip install -q --no-compile torch==2.13.0
python -m pip install -q --no-compile -c constraints.txt -e ".[test]"
if ! command -v chromium >/dev/null 2>&1 && command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
  (apt-get update -qq && apt-get install -y -qq chromium >/dev/null) || echo "chromium not installed: the report browser test will say so"
fi
ruff check .
ruff format --check .
export RAY_AUTH_MODE=disabled RAY_USAGE_STATS_ENABLED=0 SDL_VIDEODRIVER=offscreen
# Bytecode for every process the tests start (CLI subprocesses, torchrun ranks, Ray and pool workers),
# compiled on first import and cached in .venv: the install above compiles nothing (--no-compile: most of
# torch is never imported), and where PYTHONDONTWRITEBYTECODE is set each process would otherwise
# compile torch, scipy and the rest from source again (~1 CPU s per process).
unset PYTHONDONTWRITEBYTECODE
export PYTHONPYCACHEPREFIX="$PWD/.venv/pycache"
# Two pytest-xdist workers, one per core of the 2-core machine CI runs on: most tests are single-threaded
# (SIFT, simulation, Python), so the suite took 17 min instead of 24.5; pass -n 0 for one process.
python -m pytest -q -n 2 --durations=15 "$@"
