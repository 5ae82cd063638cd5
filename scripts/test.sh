#!/usr/bin/env bash
# Set up everything the test suite needs, from this repository's own files, and run it.
#   bash scripts/test.sh [pytest args]
# System packages (Debian/Ubuntu): Mesa's EGL/GL (the OpenGL reference in the rasterizer
# agreement test) and glmark2-data (the Stanford bunny, the real-mesh case).
set -euo pipefail
cd "$(dirname "$0")/.."

PKGS="libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri glmark2-data"
if command -v dpkg >/dev/null 2>&1; then
  missing=""
  for p in $PKGS; do dpkg -s "$p" >/dev/null 2>&1 || missing="$missing $p"; done
  if [ -n "$missing" ]; then
    if [ "$(id -u)" = 0 ]; then sudo=""; elif command -v sudo >/dev/null 2>&1; then sudo="sudo -n"; else sudo="none"; fi
    if [ "$sudo" = none ]; then
      echo "scripts/test.sh: cannot install$missing (not root, no sudo): the Mesa agreement tests will skip" >&2
    else
      export DEBIAN_FRONTEND=noninteractive
      $sudo apt-get install -y -qq $missing >/dev/null 2>&1 \
        || { $sudo apt-get update -qq >/dev/null && $sudo apt-get install -y -qq $missing >/dev/null; }
    fi
  fi
fi

[ -x .venv/bin/python ] || python3 -m venv .venv
.venv/bin/python -m pip install -q --disable-pip-version-check -e '.[test]'
exec .venv/bin/python -m pytest -q -n auto --dist loadfile --no-loadscope-reorder "$@"
