#!/usr/bin/env bash
# Set up gpusim and run the main job on the bundled default scene:
# rasterize it into traces/default.npz, summarise it, write reports/default/*.png, and
# replay it through FreePipe's A-buffer scheme and the full timing model on the gtx280 preset
# (reports/default/freepipe-abuffer/), and tabulate
# LucidRaster's invalid pixels against depth-filter size (reports/lucidraster-df/foliage.md).
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x .venv/bin/python ] || python3 -m venv .venv
.venv/bin/python -m pip install -q --disable-pip-version-check -e .
.venv/bin/gpusim trace default -o traces/default.npz
.venv/bin/gpusim info traces/default.npz
.venv/bin/gpusim show traces/default.npz -o reports/default
.venv/bin/gpusim replay traces/default.npz --scheme freepipe-abuffer --fidelity full -o reports/default/freepipe-abuffer
# LucidRaster's invalid pixels against depth-filter size on the foliage scene (seed 002's table)
.venv/bin/gpusim trace foliage -o traces/foliage.npz --no-progress
.venv/bin/gpusim vary traces/foliage.npz --scheme lucidraster --vary depth_filter=3,8,12 \
    --stat invalid_pixels --stat invalid_share --stat invalid_samples -o reports/lucidraster-df/foliage.md
