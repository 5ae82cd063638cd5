#!/usr/bin/env bash
# Set up gpusim and run the main job on the bundled default scene:
# rasterize it into traces/default.npz, summarise it, and write reports/default/*.png.
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x .venv/bin/python ] || python3 -m venv .venv
.venv/bin/python -m pip install -q --disable-pip-version-check -e .
.venv/bin/gpusim trace default -o traces/default.npz
.venv/bin/gpusim info traces/default.npz
.venv/bin/gpusim show traces/default.npz -o reports/default
