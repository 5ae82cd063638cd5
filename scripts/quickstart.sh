#!/usr/bin/env bash
# Set up gpusim and run the main job on the bundled default scene:
# rasterize it into traces/default.npz, summarise it, write reports/default/*.png, and
# replay it through FreePipe's A-buffer scheme (reports/default/freepipe-abuffer/).
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x .venv/bin/python ] || python3 -m venv .venv
.venv/bin/python -m pip install -q --disable-pip-version-check -e .
.venv/bin/gpusim trace default -o traces/default.npz
.venv/bin/gpusim info traces/default.npz
.venv/bin/gpusim show traces/default.npz -o reports/default
.venv/bin/gpusim replay traces/default.npz --scheme freepipe-abuffer -o reports/default/freepipe-abuffer
