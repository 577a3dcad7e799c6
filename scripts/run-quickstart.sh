#!/usr/bin/env bash
# Install drivewm into .venv and run the simulated end-to-end pipeline (CPU, about 10 minutes on 2 cores).
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -m venv .venv
. .venv/bin/activate
python -m pip install -q --upgrade pip
python -m pip install -q torch==2.13.0
python -m pip install -q -c constraints.txt -e ".[ray]"
drivewm quickstart --out "${1:-quickstart}"
