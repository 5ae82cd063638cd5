"""Rasterizer throughput: fragments per second of wall time for a 512x512 view of a ~70K-triangle mesh.

    .venv/bin/python benchmarks/bench_raster.py [--repeat 5] [--scenes bunny default foliage]
                                                [--sizes 512x512 1920x1080] [--no-llvmpipe] [--numpy]

Uses the Stanford bunny (69,451 triangles, glmark2-data) when present, else a
procedural sphere of about 70K triangles. Target: at least 2 million fragments
per second on the 2-core reference machine. The baseline, measured in the same
run, is the obvious per-triangle rasterizer (a Python loop over triangles that
evaluates the same edge functions over each bounding box with numpy); the
figure of merit is printed as a ratio against it.

Then, side by side with Mesa llvmpipe on one core: for each scene and size, the
same clip-space triangles are drawn by llvmpipe (LP_NUM_THREADS=1) through the
EGL path of tests/gl_reference.py (additive counting into a float32 target, as
the agreement test does), timed from the draw call to glFinish with the shaders
compiled and the vertices uploaded beforehand, and rasterized by gpusim (clipping,
set-up, coverage, interpolation and the trace's arrays), each the best of
--repeat wall-clock runs. LP_NUM_THREADS only counts when set before Mesa loads,
so each case's llvmpipe figure comes from a fresh subprocess, run just before
gpusim's. Target: gpusim within 5x of llvmpipe's fragments per second. Without
moderngl or Mesa's EGL the comparison says so in one line and gpusim's figures
are still printed.

gpusim rasterizes with its compiled kernels (numba) when numba imports, else with
its numpy path; with the kernels, each case also times the numpy path (same
trace) for comparison, and --numpy times the numpy path only. Every timing is
taken after a warm-up call, so numba's compile time (a few seconds, once; then
loaded from its on-disk cache) is never in the rates: it is printed on its own.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from gpusim.raster import kernel, rasterize
from gpusim.raster.clip import clip_triangles
from gpusim.scene import load_scene
from gpusim.scene.build import scene_triangles

TARGET = 2_000_000  # fragments per second
LLVMPIPE_FACTOR = 5.0  # gpusim's fragments per second within this factor of llvmpipe's on one core
BUNNY = Path(os.environ.get("GPUSIM_BENCH_MESH", "/usr/share/glmark2/models/bunny.obj"))
TESTS = Path(__file__).resolve().parent.parent / "tests"


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


def best_seconds(run, repeat: int) -> tuple[float, float]:
    """Best wall time and best CPU time (all threads) of ``repeat`` calls of ``run`` after a warm-up."""
    run()
    wall, cpu = [], []
    for _ in range(repeat):
        start, start_cpu = time.perf_counter(), time.process_time()
        run()
        wall.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
    return min(wall), min(cpu)


def llvmpipe_worker(path: str, width: int, height: int, repeat: int) -> None:
    """Subprocess: draw the triangles in ``path`` (.npy, float32 clip space) with llvmpipe;
    prints one JSON line: best wall and CPU seconds and fragments drawn, or the error."""
    try:
        sys.path.insert(0, str(TESTS))
        from gl_reference import CountPass, make_context

        ctx = make_context()
        gl = CountPass(ctx, np.load(path), width, height)
        gl.clear()
        gl.draw()
        fragments = int(gl.counts().sum(dtype=np.float64))
        wall, cpu = best_seconds(gl.draw, repeat)
        print(json.dumps({"wall": wall, "cpu": cpu, "fragments": fragments,
                          "renderer": ctx.info.get("GL_RENDERER", "?")}))
    except Exception as exc:  # noqa: BLE001 - any failure means no llvmpipe here
        print(json.dumps({"error": f"{type(exc).__name__}: {exc}".splitlines()[0]}))


def llvmpipe(clip: np.ndarray, width: int, height: int, repeat: int) -> dict:
    """Time llvmpipe on one core in a fresh process (LP_NUM_THREADS is read when Mesa loads)."""
    env = dict(os.environ, LP_NUM_THREADS="1")
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "clip.npy")
        np.save(path, np.ascontiguousarray(clip, dtype=np.float32))
        try:
            done = subprocess.run([sys.executable, __file__, "--llvmpipe-worker", path, str(width),
                                   str(height), str(repeat)], env=env, capture_output=True, text=True,
                                  timeout=600)
        except subprocess.TimeoutExpired:
            return {"error": "llvmpipe worker timed out"}
    lines = done.stdout.strip().splitlines()
    if not lines:
        return {"error": (done.stderr.strip().splitlines() or [f"worker exit status {done.returncode}"])[-1]}
    return json.loads(lines[-1])


def compare_with_llvmpipe(scenes: list[str], sizes: list[tuple[int, int]], repeat: int,
                          use_llvmpipe: bool) -> bool:
    """gpusim against llvmpipe, scene by scene; True when every measured case is within the factor.

    Rates are fragments per second of wall time and of CPU time (all threads: llvmpipe's
    rasterizer thread and the thread that feeds it); the verdict uses CPU time, which other
    work on a shared machine disturbs far less than wall time.
    """
    print(f"\nside by side with Mesa llvmpipe, LP_NUM_THREADS=1, best of {repeat} runs, M fragments/s "
          f"of wall and of CPU time ({os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f})")
    both = kernel.compiled() is not None
    print(f"{'scene':9s}{'size':>11s}{'triangles':>11s}{'fragments':>12s}  {'gpusim wall/cpu':>16s}"
          + (f"  {'numpy path':>10s}" if both else "")
          + f"  {'llvmpipe wall/cpu':>18s}  {'ratio wall/cpu':>15s}  within {LLVMPIPE_FACTOR:g}x")
    all_within, missing = True, None
    for name in scenes:
        for width, height in sizes:
            scene, base = load_scene(name, size=(width, height))
            batch = scene_triangles(scene, base)
            ref = None
            if use_llvmpipe and missing is None:
                ref = llvmpipe(batch.clip, width, height, repeat)
                if "error" in ref:
                    missing, ref = ref["error"], None
                    print(f"llvmpipe unavailable ({missing}); gpusim's figures only")
            fragments = len(rasterize(batch, width, height))
            wall, cpu = best_seconds(lambda: rasterize(batch, width, height), repeat)  # noqa: B023
            rate = np.array([fragments / wall, fragments / cpu])
            line = (f"{name:9s}{f'{width}x{height}':>11s}{len(batch):>11,}{fragments:>12,}"
                    f"  {rate[0] / 1e6:8.2f}{rate[1] / 1e6:8.2f}")
            if both:   # the numpy path on the same triangles, CPU time
                with kernel.numpy_path():
                    _, cpu_numpy = best_seconds(lambda: rasterize(batch, width, height), repeat)  # noqa: B023
                line += f"  {fragments / cpu_numpy / 1e6:10.2f}"
            if ref is not None:
                ref_rate = ref["fragments"] / np.array([ref["wall"], ref["cpu"]])
                ratio = ref_rate / rate
                within = bool(ratio[1] <= LLVMPIPE_FACTOR)
                all_within &= within
                line += (f"  {ref_rate[0] / 1e6:9.2f}{ref_rate[1] / 1e6:9.2f}"
                         f"  {ratio[0]:6.1f}x{ratio[1]:7.1f}x  {'yes' if within else 'no'}")
            print(line, flush=True)
    return all_within


def parse_size(text: str) -> tuple[int, int]:
    w, _, h = text.lower().partition("x")
    return int(w), int(h)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--scenes", nargs="+", default=["bunny", "default", "foliage"])
    ap.add_argument("--sizes", nargs="+", type=parse_size, default=[(512, 512), (1920, 1080)])
    ap.add_argument("--no-llvmpipe", action="store_true", help="gpusim's figures only")
    ap.add_argument("--numpy", action="store_true", help="time the rasterizer's numpy path (no compiled kernels)")
    ap.add_argument("--llvmpipe-worker", nargs=4, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.llvmpipe_worker:
        path, width, height, repeat = args.llvmpipe_worker
        llvmpipe_worker(path, int(width), int(height), int(repeat))
        return 0
    with kernel.numpy_path() if args.numpy else contextlib.nullcontext():
        return run(args)


def run(args) -> int:
    name, scene, base = workload()
    batch = scene_triangles(scene, base)
    w, h = scene.screen.width, scene.screen.height
    start = time.perf_counter()
    compiled = kernel.compiled()
    trace = rasterize(batch, w, h)
    first = time.perf_counter() - start
    if compiled is None:
        print("rasterizer    numpy path" + ("" if args.numpy else " (numba is not installed)"))
    else:
        import numba

        stats = [f.stats for f in (compiled.setup, compiled.emit)]
        how = ("compiled" if any(s.cache_misses for s in stats) else "loaded from numba's cache at "
               + str(stats[0].cache_path))
        print(f"rasterizer    compiled kernels (numba {numba.__version__}), {how}: the first call (numba's "
              f"import, the kernels, one rasterization) took {first:.1f} s; no timing below includes it")
    best, _ = best_seconds(lambda: rasterize(batch, w, h), args.repeat)
    rate = len(trace) / best
    limit = min(len(batch), 5000)
    start = time.perf_counter()
    naive_frags = naive_rasterize(batch, w, h, limit)
    naive_rate = naive_frags / (time.perf_counter() - start)
    print(f"workload      {name}: {len(batch):,} triangles, {w}x{h}, {len(trace):,} fragments")
    print(f"gpusim        {best * 1e3:8.1f} ms best of {args.repeat}  -> {rate / 1e6:6.2f} M fragments/s")
    print(f"baseline      per-triangle loop on {limit:,} triangles -> {naive_rate / 1e6:6.2f} M fragments/s")
    print(f"ratio         {rate / naive_rate:6.1f}x the baseline; {rate / TARGET:5.2f}x the 2 M fragments/s target")
    within = compare_with_llvmpipe(args.scenes, args.sizes, args.repeat, not args.no_llvmpipe)
    return 0 if rate >= TARGET and within else 1


if __name__ == "__main__":
    sys.exit(main())
