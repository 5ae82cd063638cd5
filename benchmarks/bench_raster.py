"""Rasterizer throughput: fragments per second of wall time for a 512x512 view of a ~70K-triangle mesh.

    .venv/bin/python benchmarks/bench_raster.py [--repeat 5]

Uses the Stanford bunny (69,451 triangles, glmark2-data) when present, else a
procedural sphere of about 70K triangles. Target: at least 2 million fragments
per second on the 2-core reference machine. The baseline, measured in the same
run, is the obvious per-triangle rasterizer (a Python loop over triangles that
evaluates the same edge functions over each bounding box with numpy); the
figure of merit is printed as a ratio against it.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

from gpusim.raster import rasterize
from gpusim.raster.clip import clip_triangles
from gpusim.scene import load_scene
from gpusim.scene.build import scene_triangles

TARGET = 2_000_000  # fragments per second
BUNNY = Path(os.environ.get("GPUSIM_BENCH_MESH", "/usr/share/glmark2/models/bunny.obj"))


def workload():
    if BUNNY.is_file():
        scene, base = load_scene("bunny", ["objects.0.opaque=false"])
        return "bunny.obj + wall", scene, base
    scene, base = load_scene("default", ["objects=[{kind='sphere', segments=264, rings=134, alpha=0.4}]",
                                         "camera.eye=[0, 0, 3.2]"])
    return "procedural sphere", scene, base


def naive_rasterize(batch, width, height, limit):
    """Baseline: per-triangle loop, edge functions evaluated over the whole bounding box."""
    batch = clip_triangles(batch)
    w = batch.clip[..., 3]
    xy = np.stack([(batch.clip[..., 0] / w + 1) * width / 2, (batch.clip[..., 1] / w + 1) * height / 2], -1)
    count = 0
    for tri in xy[:limit]:
        lo = np.maximum(np.floor(tri.min(0)).astype(int), 0)
        hi = np.minimum(np.ceil(tri.max(0)).astype(int), [width - 1, height - 1])
        if (hi < lo).any():
            continue
        px, py = np.meshgrid(np.arange(lo[0], hi[0] + 1) + 0.5, np.arange(lo[1], hi[1] + 1) + 0.5)
        d1, d2 = tri[1] - tri[0], tri[2] - tri[0]
        area = d1[0] * d2[1] - d1[1] * d2[0]
        inside = np.ones(px.shape, bool)
        for i in range(3):
            a, b = tri[i], tri[(i + 1) % 3]
            e = (b[0] - a[0]) * (py - a[1]) - (b[1] - a[1]) * (px - a[0])
            inside &= (e * np.sign(area)) >= 0
        count += int(inside.sum())
    return count


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    name, scene, base = workload()
    batch = scene_triangles(scene, base)
    w, h = scene.screen.width, scene.screen.height
    rasterize(batch, w, h)  # warm-up
    times = []
    for _ in range(args.repeat):
        start = time.perf_counter()
        trace = rasterize(batch, w, h)
        times.append(time.perf_counter() - start)
    best = min(times)
    rate = len(trace) / best
    limit = min(len(batch), 5000)
    start = time.perf_counter()
    naive_frags = naive_rasterize(batch, w, h, limit)
    naive_rate = naive_frags / (time.perf_counter() - start)
    print(f"workload      {name}: {len(batch):,} triangles, {w}x{h}, {len(trace):,} fragments")
    print(f"gpusim        {best * 1e3:8.1f} ms best of {args.repeat}  -> {rate / 1e6:6.2f} M fragments/s")
    print(f"baseline      per-triangle loop on {limit:,} triangles -> {naive_rate / 1e6:6.2f} M fragments/s")
    print(f"ratio         {rate / naive_rate:6.1f}x the baseline; {rate / TARGET:5.2f}x the 2 M fragments/s target")
    return 0 if rate >= TARGET else 1


if __name__ == "__main__":
    sys.exit(main())
