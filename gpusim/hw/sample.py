"""The ``sampled`` fidelity level: replicate stratified samples of the work, each on a scaled-down GPU.

The method, its assumptions and its measured error are in docs/timing-model.md ("The sampled level").

* The machine. A replicate runs ``m = max(1, round(sample.fraction x core.sms))``
  SMs, or on a run whose fragments lie in ``T`` screen tiles fewer than
  ``sample.min_tiles / (m / core.sms)``, enough SMs to sample ``min_tiles`` of
  them (``ceil(min_tiles x core.sms / T)``; all of them, the run itself,
  when the replicates would then take at least the run's SMs between them,
  ``T <= replicates x min_tiles``): a smaller sample is too coarse to stand
  for the run (on
  the fidelity corpus a replicate of fewer than 5 tiles missed the full level
  by over 5% in 31% of cases, one of 30 or more in 2%). That is a share
  ``s = m / core.sms`` of the GPU, on a share ``s`` of the work (a
  replicate that keeps more of the work, as one of a trace whose fragments lie in
  fewer tiles than the sample has strata, runs on as large a share of the SMs:
  :func:`replicate_sms`). The SMs are whole (each with the GPU's warp slots and lanes: latency hiding
  per SM as in the run). Every other unit keeps all its instances (memory
  partitions, atomic units, ROPs: the same address interleaving, so the same
  hot partitions) and its latencies, and the rest of the GPU's traffic on it
  (the run's load on each instance in each pass less the sample's,
  ``Program.occupancy`` and ``Program.own_load``; on the memory partitions the
  run's coalesced bytes less the sample's, ``sample.run_traffic``, estimated from
  a sample of the run's own warps, ``sample.traffic_share``, :func:`coalesced_load`) holds an L2 slice, atomic
  unit or ROP right after the instruction that came with it, and is pooled
  over every DRAM channel in the run's mix as the sample's requests come, each
  channel taking its share ahead of the sample's next request there
  (gpusim.hw.background); the quad rasterizer runs at ``s`` of its rate, the
  scoreboard ``s`` of its cells.
  The L2 (functional warming, gpusim.hw.memory.warming): the whole run's
  requests go through an LRU model of the slices in about the full level's
  issue order, and each request of a sample misses with the share of those
  misses its lanes carry; the slices' tags decide nothing the run decided. The geometry front end is the GPU's: every
  pass submits all its triangles and a warp starts when its own are out.
  Operations on an atomic word of which the sample keeps only some hold it as
  long as all of them (``Program.hold_scale``): a global counter's chain is as
  long as in the run, a pixel's (kept whole) unchanged.
* The sample. Sampling units: screen tiles (``sample.tile`` pixels square) for
  the fragment threads of the graphics pipeline and for pixel threads; blocks
  of ``warp_size`` consecutive triangles for a software rasterizer's triangle
  threads (whole triangles and whole warps, so its loads coalesce as in the
  run); blocks of ``warp_size`` consecutive threads for the others (memory
  entries). Tiles and triangle blocks are stratified by their fragments: ranked,
  cut into ``round(s x units)`` strata of equal count, and each replicate takes
  one unit of each stratum at random, each replicate another one while the
  stratum has enough: the ``sample.replicates`` replicates are disjoint
  stratified samples of one design. Warps of threads that fill them in order
  are stratified the same way, by their pixels' fragments (pixel threads) or
  by their operations (others). The deepest pixel's tile and warp, the largest
  triangle's block and the warp with the most operations are in every
  replicate: the longest chain of dependent operations decides a pass of few
  warps (LucidRaster's bins: without its heaviest warp the sample ran its
  raster passes 10-40% short). A pass of which a replicate keeps no thread
  keeps one unit's threads (its latency chain is the pass's floor).
* The estimate. Each replicate's pass cycles estimate the run's: the level
  reports their mean, per pass and in all, and from the replicates' totals
  ``T_1..T_R`` the standard error ``SE = sd(T) / sqrt(R)``. The replicates
  share their machine's bias (a pass ends with the latest of fewer SMs than
  the run's), which their spread does not show, so the scale check
  (``sample.scale_check``) runs replicates 0 and 1's samples together on their
  SMs together and takes the growth of a pass's end with the SMs from it
  (:func:`scale_check`): the bias ``b``. The 95% confidence interval is
  ``mean +- (t(0.975, nu) x SE + |b|)`` (``cycles_ci95_low``,
  ``cycles_ci95_high``; ``nu = R - 1``, or with thinning the
  Welch-Satterthwaite degrees of freedom of the spread and the work checks'
  slope, :func:`welch_dof`) and ``cycle_error_estimate = hypot(SE, b) / mean``;
  the estimate itself is not corrected by ``b`` (on the fidelity corpus it
  overshoots the error, and the corrected figures were further off). The corpus (configs/experiments/fidelity.toml) measures how
  often the interval holds the full level's cycles.
* Thinning (``sample.thin`` below 1; 0.25 by default). A replicate keeps only
  that share of its SMs' share of the tiles (:func:`thinning`: raised to keep
  ``sample.thin_min_tiles`` tiles, as many triangle blocks in a software
  rasterizer's run) and stands for
  the whole GPU on a frame thinned to it (:func:`thinned`: the rest of the GPU's
  load on the shared units, the atomic chains and the front end at the share
  each pass keeps). A pass's cycles are taken to grow linearly with its work,
  and the work checks (replicates 0 and 1's samples together on the same SMs,
  twice the share, and 2 and 3's) give each pass's slope, by which every
  replicate's pass (and the scale check's) is extrapolated to the whole work
  (:func:`work_check`); the slope's standard error joins the replicates' in
  ``SE``, with its one degree of freedom.
* Hazards, requests and busy cycles: each replicate's over the share of the
  work it kept (RMW fragments for hazards, at most the run's reads; operations
  for the units), averaged; the block of a software rasterizer's largest
  triangle counted once (:func:`certain_figures`). Except: the shared units'
  and the front end's busy cycles are the run's load on each instance in each
  pass over the share of it on the instances the sample reaches and over the
  pass's thinning (gpusim.hw.unit.run_held); the atomic units' and ROPs'
  requests the census's count of the run's operations; with an L2, the DRAM's
  requests and busy cycles and the L2's misses its warming's of the whole run
  (:meth:`Outcomes.next_level`).

A fraction of 1 makes the machine the GPU and every replicate the whole run:
the full level's figures, and an interval of zero width. A run over
``runner.max_operations`` is sampled a chunk of passes at a time, the chunks the
full level streams (gpusim.hw.stream), each replicate on the SMs its sample of
the whole run takes: the figures of the run lowered at once.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from gpusim.hw.lower import (Census, Pieces, Workload, lower, memory_load, pass_operations, plan_pieces,
                             reached_share, sample_masks, share_pieces, split_by, submission_warps, thread_mapping,
                             unit_load)
from gpusim.hw.memory.coalescer import memory_bytes
from gpusim.hw.memory.warming import Outcomes
from gpusim.hw.parallel import fork_map, fork_workers
from gpusim.hw.program import Program
from gpusim.hw.raster import per_triangle_cycles
from gpusim.hw.stream import StreamedRun, carried_state, plan_chunks
from gpusim.opplan import OPS

#: operations a replicate keeps (about) from which ``runner.workers = 0`` replays the replicates in processes of
#: their own: a fork costs 10-50 ms, a replicate of 100K operations about 0.1 s of event work
MIN_REPLICATE_OPERATIONS = 100_000
#: unit figures that add up over the work (a sample's are scaled up by its share); the others are kept as they are
ADDITIVE = ("requests", "busy_cycles", "bytes", "hits", "misses", "stalls", "overflows", "addresses")


def t_quantile(p: float, dof: int) -> float:
    """The ``p`` quantile (0.5 < p < 1) of Student's t distribution with ``dof`` >= 1 degrees of freedom:
    bisection on its closed-form distribution function for integer degrees of freedom (Abramowitz and Stegun
    26.7.3-4)."""
    if not 0.5 < p < 1 or dof < 1:
        raise ValueError(f"t_quantile: p must lie in (0.5, 1) and dof be >= 1, got p={p}, dof={dof}")

    def central(t: float) -> float:          # P(|T| <= t)
        theta = math.atan(t / math.sqrt(dof))
        c2, s = math.cos(theta) ** 2, math.sin(theta)
        if dof % 2:
            term, total = math.cos(theta), 0.0
            for k in range(1, (dof - 1) // 2 + 1):
                total += term
                term *= c2 * (2 * k) / (2 * k + 1)
            return 2 / math.pi * (theta + s * total)
        term, total = 1.0, 0.0
        for k in range(1, dof // 2 + 1):
            total += term
            term *= c2 * (2 * k - 1) / (2 * k)
        return s * total

    target, lo, hi = 2 * p - 1, 0.0, 1.0
    while central(hi) < target:
        hi *= 2
    for _ in range(100):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if central(mid) < target else (lo, mid)
    return (lo + hi) / 2


def sampled_sms(gpu, tiles: int | None = None) -> int:
    """SMs a replicate of the sampled level simulates: ``sample.fraction`` of the GPU's, rounded (at least one),
    or, on a run whose fragments lie in ``tiles`` screen tiles, enough for the replicate to sample
    ``sample.min_tiles`` of them; all the SMs (the run itself, once) where the replicates would then cost
    as much as the run, on at most ``replicates x min_tiles`` tiles."""
    c, sms = gpu.sample, gpu.core.sms
    m = max(1, min(sms, round(c.fraction * sms)))
    if tiles is not None and m * tiles < c.min_tiles * sms:
        m = min(sms, -(-c.min_tiles * sms // max(tiles, 1)))
        if m * c.replicates >= sms:      # the replicates would cost at least the run: the run itself
            m = sms
    return m


def thinning(gpu, tiles: int, sms: int, blocks: int | None = None) -> float:
    """The share of its SMs' work a replicate on ``sms`` SMs keeps, on a run whose fragments lie in ``tiles``
    screen tiles (and, where a software rasterizer's passes sample triangle blocks, of ``blocks`` such
    blocks): ``sample.thin``, raised until the replicate keeps ``sample.thin_min_tiles`` tiles (and as many
    triangle blocks: a replicate of fewer holds little more than the largest triangle's block, which every
    replicate holds, so their spread shows nothing of its error); 1 (no thinning) where that is over 0.5 (the
    work checks, at twice the share, would cost about what it saves) or the replicate is the run."""
    c = gpu.sample
    units = tiles if blocks is None else min(tiles, blocks)
    if c.thin >= 1 or sms >= gpu.core.sms or not units:
        return 1.0
    theta = max(c.thin, c.thin_min_tiles / (units * sms / gpu.core.sms))
    return theta if theta <= 0.5 else 1.0


def welch_dof(a: float, dof_a: int, b: float, dof_b: int) -> int:
    """Degrees of freedom of the standard error ``hypot(a, b)`` of a sum of two independent estimates whose own
    standard errors ``a`` and ``b`` come with ``dof_a`` and ``dof_b`` degrees of freedom (Welch-Satterthwaite),
    rounded down (the wider interval); the other's where one of them is 0."""
    if b <= 0 or a <= 0:
        return dof_a if b <= 0 else dof_b
    return max(1, int((a * a + b * b) ** 2 / (a ** 4 / dof_a + b ** 4 / dof_b)))


def replicate_sms(gpu, program: Program, floor: int) -> int:
    """SMs for a replicate whose lowered ``program`` keeps a share of the run's operations: that share of the
    GPU's SMs, at least ``floor`` (a sample that keeps more of the work than its share of the tiles, as one
    of a trace whose fragments lie in fewer tiles than the sample has strata, runs on as much more of the GPU;
    all of it, the run itself)."""
    return fitted_sms(gpu, sum(p.operations for p in program.passes), sum(p.operations_total for p in program.passes),
                      floor)


def fitted_sms(gpu, kept: int, total: int, floor: int) -> int:
    """:func:`replicate_sms` of a sample that keeps ``kept`` of the run's ``total`` operations."""
    if not total:
        return floor
    return max(floor, min(gpu.core.sms, round(kept / total * gpu.core.sms)))


def scaled_gpu(gpu, sms: int):
    """``gpu`` cut down to ``sms`` of its SMs: the quad rasterizer's rate and the scoreboard's cells in the same
    share (the other units' share is ``Program.share``; the L2's hits and misses are the run's:
    gpusim.hw.memory.warming)."""
    s = sms / gpu.core.sms
    if sms == gpu.core.sms:
        return gpu
    r = dataclasses.replace
    return gpu.replace(core=r(gpu.core, sms=sms), raster=r(gpu.raster, quads_per_cycle=gpu.raster.quads_per_cycle * s),
                       scoreboard=r(gpu.scoreboard, entries=max(gpu.core.warp_size, round(gpu.scoreboard.entries * s))))


def _stratified(weight: np.ndarray, present: np.ndarray, share: float, replicates: int,
                rng: np.random.Generator, certain: int) -> np.ndarray:
    """``(replicates, units)`` masks: the present units ranked by ``weight`` (ties at random) and cut into
    ``round(share x units)`` strata of equal count (at least one); replicate ``r`` takes the stratum's ``r``-th
    unit in a random order (cycling when the stratum has fewer), except that every replicate takes unit
    ``certain`` (-1: none) in its stratum."""
    units = np.flatnonzero(present)
    n = len(units)
    out = np.zeros((replicates, len(present)), bool)
    if not n:
        return out
    k = max(1, min(n, round(share * n)))
    ranked = units[np.lexsort((rng.random(n), weight[units]))]
    stratum = np.arange(n) * k // n
    first_key = np.where(ranked == certain, -1.0, rng.random(n))     # the certain unit first in its stratum
    ranked = ranked[np.lexsort((first_key, stratum))]               # a random order within each stratum
    first = np.searchsorted(stratum, np.arange(k))
    size = np.diff(np.append(first, n))
    for r in range(replicates):
        out[r, ranked[np.where(ranked[first] == certain, first, first + r % size)]] = True
    return out


class Replicates:
    """The sampling units of a run and the replicates' choice of them (see the module docstring)."""

    def __init__(self, work: Workload, gpu, share: float | None = None):
        """``share``: of the GPU and the work each replicate takes; by default the SMs :func:`sampled_sms` gives
        for the tiles the run's fragments lie in (``sms``)."""
        c, ws = gpu.sample, gpu.core.warp_size
        self.work, self.gpu, self.count, self.seed = work, gpu, c.replicates, c.seed
        self.tiles_x = -(-work.width // c.tile)
        rng = np.random.default_rng(c.seed)
        pixel, prims = work.frag_pixel, work.frag_prim
        self.depth = np.bincount(pixel, minlength=work.width * work.height)
        # the deepest pixel's tile and the largest triangle's block are in every replicate: the longest chains of
        # dependent operations (a pixel's list, a triangle thread's loop) decide a latency-bound pass
        self.deepest = int(self.depth.argmax()) if len(pixel) else -1
        self.frag_tile = self.tile_of(pixel)
        frag_tiles = np.bincount(self.frag_tile, minlength=self.tiles_x * -(-work.height // c.tile))
        occupied = int((frag_tiles > 0).sum())
        triangles = max(work.triangles, int(prims.max()) + 1 if len(prims) else 0)
        per_triangle = np.bincount(prims, minlength=triangles)
        blocks = -(-triangles // ws)
        software = any(thread_mapping(gpu, pk) == "triangle" for pk in work.plan.passes)
        self.theta = 1.0                         # the share of its SMs' work a replicate keeps (thinning)
        if share is None:
            self.sms = sampled_sms(gpu, occupied)
            self.theta = thinning(gpu, occupied, self.sms, blocks if software else None)
            share = self.sms / gpu.core.sms * self.theta
        self.share = share
        self.tiles = _stratified(frag_tiles, frag_tiles > 0, share, self.count, rng,
                                 int(self.tile_of(self.deepest)) if len(pixel) else -1)
        self.certain_block = int(per_triangle.argmax()) // ws if len(prims) else -1
        self.triangles = _stratified(np.bincount(np.arange(triangles) // ws, weights=per_triangle,
                                                 minlength=blocks), np.ones(blocks, bool), share, self.count, rng,
                                     self.certain_block)
        self.codes = None                        # per pass: its index in _MODES (candidate_rows)
        self.seen = np.zeros(len(work.plan.passes), np.int64)   # per pass: the replicates holding one of its rows
        self.lanes: dict[int, tuple] = {}        # pass -> its lanes and the replicates' choice of their warps
        self.units: dict[int, list] = {}         # pass -> the sampling unit of each thread of each group
        self.keepers: dict[int, list] = {}       # pass -> the replicates keeping each thread of each group (bits)
        self.info = {"tiles": occupied, "tiles_per_replicate": int(self.tiles[0].sum()),
                     "triangle_blocks": int(blocks), "triangle_blocks_per_replicate": int(self.triangles[0].sum())}

    def candidate_rows(self, pass_index: int, threads: np.ndarray) -> np.ndarray | None:
        """Of operations of ``threads`` in pass ``pass_index``, those some replicate may keep: a fragment
        thread's in a tile, a triangle thread's in a triangle block, that a replicate holds; every one of a pass
        whose threads fill warps in order (its warps are chosen from all of them). None: all of them. The pass's
        replicates that hold one of its operations are noted in :attr:`seen` (:func:`_candidate_pieces`)."""
        if self.codes is None:
            modes = [thread_mapping(self.gpu, pk) for pk in self.work.plan.passes]
            self.codes = np.array([_MODES.index(m) for m in modes], np.int8)
            # per fragment: the replicates that hold its tile (bit r), and its triangle's block
            bits = (1 << np.arange(self.count, dtype=np.int64))[:, None]
            self.held = (None, (self.tiles * bits).sum(axis=0)[self.frag_tile],
                         (self.triangles * bits).sum(axis=0)[self.work.frag_prim // self.gpu.core.warp_size])
        code = int(self.codes[pass_index])
        if code == 0:                              # warps of the pass's threads: all of them
            return None
        held = self.held[code][threads]
        self.seen[pass_index] |= int(np.bitwise_or.reduce(held[held > 0])) if len(held) else 0
        return held != 0

    def prepare(self, pieces) -> None:
        """Each pass's sampling units (:meth:`units_of`) of the threads of ``pieces`` (of the whole run) and the
        replicates keeping them (:meth:`keepers_of`), as :class:`Keep` asks for them: made now, before the
        replicates are lowered in processes of their own."""
        for p, js in split_by(np.array([pc.pass_index for pc in pieces], np.int64)):
            self.keepers_of(p, [pieces[j].thread for j in js])

    def tile_of(self, pixel):
        tile = self.gpu.sample.tile
        return (pixel // self.work.width // tile) * self.tiles_x + (pixel % self.work.width) // tile

    def units_of(self, p: int, threads: list[np.ndarray], mapping: str) -> list[np.ndarray]:
        """The sampling unit of each thread of each group of pass ``p`` (the same for every replicate)."""
        if p not in self.units:
            ws = self.gpu.core.warp_size
            if mapping == "triangle":
                self.units[p] = [self.work.frag_prim[t] // ws for t in threads]
            elif mapping == "fragment":
                self.units[p] = [self.frag_tile[t] for t in threads]
            else:
                lanes = self.warps(p, threads)[0]
                rank = _ranks(lanes)
                self.units[p] = [rank(t) // ws for t in threads]
        return self.units[p]

    def keepers_of(self, p: int, threads: list[np.ndarray]) -> list[np.ndarray]:
        """For each thread of each group of pass ``p``, the replicates that keep it (:class:`Keep`), as bits (bit
        ``r``: replicate ``r``): made once per pass for every sample of the run (a sample's rows are then a test
        of its bits, not a gather per replicate). A replicate that would keep none of the pass's units keeps
        one of them, at random (the unit of a row drawn from all of them)."""
        if p not in self.keepers:
            mapping = thread_mapping(self.gpu, self.work.plan.passes[p])
            units = self.units_of(p, threads, mapping)
            chosen = (self.triangles if mapping == "triangle" else self.tiles if mapping == "fragment"
                      else self.lanes[p][1])
            present = np.zeros(chosen.shape[1], bool)
            for u in units:
                present[u] = True
            dtype = np.dtype(f"uint{max(8, 1 << (self.count - 1).bit_length())}")
            code = np.zeros(chosen.shape[1], dtype)
            ends = np.cumsum([len(u) for u in units], dtype=np.int64)
            total = int(ends[-1]) if len(ends) else 0
            for r in range(self.count):
                mine = chosen[r]
                if not (mine & present).any() and total:      # none kept: one of the pass's units
                    i = int(np.random.default_rng([self.seed, r, p]).integers(total))
                    g = int(np.searchsorted(ends, i, side="right"))
                    mine = np.zeros(len(present), bool)
                    mine[units[g][i - (int(ends[g - 1]) if g else 0)]] = True
                code |= mine.astype(dtype) << dtype.type(r)
            self.keepers[p] = [code[u] for u in units]
        return self.keepers[p]

    def warps(self, p: int, threads: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """A pass whose threads fill warps in order: its lanes (sorted) and the replicates' choice of its warps,
        stratified by their fragments (pixel threads) or their operations (others), the deepest pixel's warp
        or the warp with the most operations in every replicate (the longest chain of a latency-bound pass:
        a pass of few warps ends with its heaviest)."""
        if p not in self.lanes:
            lanes = _distinct(threads)
            ws = self.gpu.core.warp_size
            n = -(-len(lanes) // ws)
            pixels = self.work.plan.passes[p].threads == "pixel"
            if pixels:
                weight = np.bincount(np.arange(len(lanes)) // ws, weights=self.depth[lanes], minlength=n)
                certain = int(np.searchsorted(lanes, self.deepest)) // ws if self.deepest in lanes else -1
            else:                      # a thread's rows: its memory operations and compute steps in the pass
                rank = _ranks(lanes)
                weight = np.zeros(n)
                for t in threads:
                    weight += np.bincount(rank(t) // ws, minlength=n)
                certain = int(weight.argmax()) if n else -1
            self.lanes[p] = lanes, _stratified(weight, np.ones(n, bool), self.share, self.count,
                                               np.random.default_rng([self.seed, p]), certain)
        return self.lanes[p]


#: the replicates whose samples together are the scale check's (run on their SMs together)
SCALE_CHECK = (0, 1)
#: the pairs of replicates whose samples together are the work checks of thinned replicates (each on the same SMs),
#: those of them a run's replicates hold
WORK_CHECKS = ((0, 1), (2, 3))
#: how a pass's threads become lanes (gpusim.hw.lower.thread_mapping), as candidate_rows numbers them
_MODES = ("thread", "fragment", "triangle")


class Keep:
    """Replicate ``r``'s choice of threads, as :func:`gpusim.hw.lower.lower` asks for it: per pass, whole
    screen tiles (graphics-pipeline fragment threads), whole blocks of triangles (a software rasterizer's), or
    whole warps of the run (threads that fill warps in order); a pass it would keep none of keeps one such
    unit. ``r`` a tuple of replicates: the union of their choices (the scale check's sample)."""

    def __init__(self, reps: Replicates, r: int | tuple[int, ...]):
        self.reps, self.r = reps, r
        self.members = _members(r)

    def __call__(self, p: int, threads: list[np.ndarray]) -> list[np.ndarray]:
        bits = sum(1 << r for r in self.members)
        return [(code & bits) != 0 for code in self.reps.keepers_of(p, threads)]

    def triangles(self, ids: np.ndarray) -> np.ndarray:
        """A software rasterizer's triangles (covering a pixel or not) in the replicate's triangle blocks."""
        return self.reps.triangles[list(self.members)].any(axis=0)[ids // self.reps.gpu.core.warp_size]


class KeepCertain:
    """The block of a software rasterizer's triangle threads every replicate keeps whole (the largest triangle's),
    as :func:`gpusim.hw.lower.lower` asks for it. Its figures stand for themselves alone in the replicates'
    estimate (:func:`certain_figures`): a screen-wide triangle's thread loops over its pixels with the warp's
    other lanes idle, an outlier no other block is like. The other units every replicate keeps (the deepest
    pixel's tile and warp, a pass's heaviest warp) stand for their stratum as the others do: the heaviest
    of a stratum of heavy units (a linked list's deepest pixels, whose resolve sorts grow faster than their
    fragments), taken for itself alone, put the rest of its stratum at the light strata's cost per
    operation (the linked list's SM busy cycles 18-50% short on nested spheres at 64x64)."""

    def __init__(self, reps: Replicates):
        self.reps = reps

    def __call__(self, p: int, threads: list[np.ndarray]) -> list[np.ndarray]:
        reps = self.reps
        if thread_mapping(reps.gpu, reps.work.plan.passes[p]) != "triangle" or reps.certain_block < 0:
            return [np.zeros(len(t), bool) for t in threads]
        return [u == reps.certain_block for u in reps.units_of(p, threads, "triangle")]

    def triangles(self, ids: np.ndarray) -> np.ndarray:
        return ids // self.reps.gpu.core.warp_size == self.reps.certain_block


def _members(r: int | tuple[int, ...]) -> tuple[int, ...]:
    """The replicates a sample ``r`` is made of: itself, or the tuple's (the scale check's union)."""
    return r if isinstance(r, tuple) else (r,)


def _distinct(values: np.ndarray | list[np.ndarray]) -> np.ndarray:
    """The distinct values of a non-negative integer array (or of several together), ascending (a mask over
    their range when it is small, as thread ids are: far faster than hashing, and several arrays are marked
    one at a time, not joined first: a pass's pieces hold each thread once per operation)."""
    parts = [v for v in ([values] if isinstance(values, np.ndarray) else values) if len(v)]
    if not parts:
        return values if isinstance(values, np.ndarray) else np.zeros(0, np.int64)
    lo, hi = min(int(v.min()) for v in parts), max(int(v.max()) for v in parts)
    if hi - lo > 8 * sum(len(v) for v in parts):
        return np.unique(np.concatenate(parts))
    seen = np.zeros(hi - lo + 1, bool)
    for v in parts:
        seen[v - lo if lo else v] = True
    return np.flatnonzero(seen) + lo


def _ranks(lanes: np.ndarray):
    """For ascending distinct non-negative ``lanes``: a function giving each of an array of them its position
    (``np.searchsorted(lanes, values)``), by a table over their range where that is small."""
    if not len(lanes) or int(lanes[-1]) > 8 * len(lanes):
        return lambda values: np.searchsorted(lanes, values)
    table = np.zeros(int(lanes[-1]) + 1, np.int64)
    table[lanes] = np.arange(len(lanes), dtype=np.int64)
    return lambda values: table[values]


def rmw_threads(source, work: Workload) -> tuple[int, int]:
    """Fragment threads with an ``rmw_read``, and their pixels: of an OpPlan, of a lowered (sampled)
    Program, or the ids of such threads (the chunks' of a run sampled a chunk of passes at a time)."""
    if isinstance(source, np.ndarray):
        threads = source
    elif isinstance(source, Program):
        threads = _rmw_readers(source)
    else:
        threads = [g.thread_ids() for g in source.groups if g.op == "rmw_read"]
    threads = _distinct(threads)
    return len(threads), len(_distinct(work.frag_pixel[threads])) if len(threads) else 0


def _rmw_readers(program: Program) -> np.ndarray:
    """The threads of a lowered program's ``rmw_read`` rows."""
    rows = program.rows_of("coalescer")
    return rows.thread[rows.op == OPS.index("rmw_read")] if len(rows) else np.zeros(0, np.int64)


def _replicate(work: Workload, rec: dict, passes: list[tuple[int, int]], rmw_kept: tuple[int, int],
               rmw_all: tuple[int, int], theta: np.ndarray, certain: dict | None = None) -> dict:
    """One replicate's figures, each scaled up to the whole run: from the event model's record ``rec`` of its
    sample, each pass's (operations kept, operations of the run) ``passes``, the RMW threads (and pixels)
    it kept, ``rmw_kept``, of the run's ``rmw_all``, and each pass's thinning ``theta`` (:func:`thinned`;
    its cycles are the thinned frame's, extrapolated by :func:`work_check`); ``certain``: the figures of the
    units every replicate keeps whole (:func:`certain_figures`), which stand for themselves alone."""
    kept = sum(k for k, _ in passes)
    total = sum(t for _, t in passes)
    w = kept / total if total else 1.0
    thin = float(np.dot(theta, [t for _, t in passes]) / total) if total else 1.0    # over the run's operations
    out = {"cycles": [p["cycles"] for p in rec["passes"]], "theta": list(theta), "thinning": thin,
           "instructions": rec["instructions"] / w,
           "warps": [p["warps"] * (t / k if k else 1) for p, (k, t) in zip(rec["passes"], passes)],
           "operations_sampled": kept, "operations": total, "units_built": rec["units_built"], "units": {}}
    for name, u in rec["units"].items():
        scale = 1.0 if name == "raster" else 1 / w    # the front end takes every triangle
        out["units"][name] = {k: v * scale if k in ADDITIVE else v for k, v in u.items()}
        if "run_busy_cycles" in u:    # a shared unit (or a thinned sample's front end): the run's, from its load
            out["units"][name]["busy_cycles"] = out["units"][name].pop("run_busy_cycles")
    c = certain["operations"] if certain else 0
    if c and kept > c and total > c:            # the units kept whole once, the rest scaled up
        for name, keys in CERTAIN_FIGURES.items():
            for key in keys:
                mine, whole = rec["units"].get(name, {}).get(key), certain[f"{name}.{key}"]
                if mine is not None:
                    out["units"][name][key] = whole + (mine - whole) * (total - c) / (kept - c)
    # at most every read of the run (a multi-pass scheme's fragment reads its pixel in each pass) and every pixel
    reads = sum(int(g.total) for g in work.plan.groups if g.op == "rmw_read")
    for key, every, mine, most in zip(("rmw_hazards", "rmw_hazard_pixels"), rmw_all, rmw_kept, (reads, rmw_all[1])):
        out[key] = min(most, rec.get(key, 0) * every / mine) if mine else 0
    return out


def certain_figures(work: Workload, gpu, reps: Replicates, pieces, passes: tuple[int, int] | None = None) -> dict:
    """The static figures of the units every replicate keeps whole (:class:`KeepCertain`) of the run (of its
    passes ``passes``, from their ``pieces``), as a machine built for them alone counts them before it runs:
    ``operations``, and per ``unit.key`` of :data:`CERTAIN_FIGURES` the value. A replicate's figures are its
    sample's scaled up by its share of the operations, and a unit it keeps whole stands for itself alone
    (:func:`_replicate`): FreePipe's largest triangles' block, whose warp loops over a screen-wide triangle's
    pixels with most lanes idle, put its SMs' busy cycles at 2.8-4.5 times the run's on `foliage` at 384x384."""
    from gpusim.hw.machine import Machine
    machine = scaled_gpu(gpu, reps.sms)
    program = lower(work, machine, KeepCertain(reps), passes=passes, pieces=pieces)
    units = Machine(machine, program, work.width).unit_summaries(1)
    out = {"operations": sum(p.operations for p in program.passes)}
    for name, keys in CERTAIN_FIGURES.items():
        for key in keys:
            out[f"{name}.{key}"] = float(units.get(name, {}).get(key, 0.0))
    return out


#: the figures a unit counts before it runs (the ones :func:`certain_figures` corrects): the SMs' issue-port
#: cycles and instructions, the coalesced requests and their bytes, the DRAM's requests (with an L2, its misses,
#: counted as the run goes; the sampled record takes them from the L2's warming instead: :func:`_warmed_units`)
CERTAIN_FIGURES = {"core": ("busy_cycles", "requests"), "coalescer": ("requests", "bytes"), "dram": ("requests",)}


def _add_figures(total: dict | None, more: dict) -> dict:
    return dict(more) if total is None else {k: total[k] + more[k] for k in total}


def _floor(reps: Replicates, r: int | tuple[int, ...]) -> int:
    """The fewest SMs replicate ``r`` (a tuple: the union of those replicates) runs on."""
    return min(reps.gpu.core.sms, reps.sms * len(_members(r)))


def _replicate_program(work: Workload, gpu, reps: Replicates, r, pieces, passes=None, outcomes=None,
                       front=None, sms: int | None = None, floor: int | None = None, run_bytes=None):
    """Replicate ``r``'s sample of the run (a tuple: the union of those replicates'; of its passes ``passes``,
    from ``pieces``), lowered for the share of the GPU it takes (``sms`` where it is known, else at least
    ``floor``): (the machine's GPU, the program, each pass's thinning: :func:`thinned`)."""
    keep = Keep(reps, r)
    mine = floor if sms is None else sms
    machine = scaled_gpu(gpu, mine)
    program = lower(work, machine, keep, passes=passes, pieces=pieces)
    fit = mine if sms is not None else replicate_sms(gpu, program, mine)    # the share the kept work takes
    if fit != mine:
        mine, machine = fit, scaled_gpu(gpu, fit)
        program = lower(work, machine, keep, passes=passes, pieces=pieces)
    program = dataclasses.replace(program, front_end_cycles=front, l2_outcomes=outcomes)
    if run_bytes is not None:
        program = coalesced_load(program, machine, run_bytes)
    if reps.theta >= 1:
        return machine, program, np.ones(len(program.passes))
    return machine, *thinned(program, gpu, mine)


def run_traffic(work: Workload, gpu, passes: tuple[int, int] | None = None, program: Program | None = None,
                pieces: list | None = None, census: Census | None = None) -> np.ndarray | None:
    """The run's coalesced memory traffic (:func:`memory_bytes`, (passes, partitions)) in those of its passes
    ``passes`` (all by default) whose fragment threads a replicate packs into warps of its own (the graphics
    pipeline's fragment shaders, ``thread_mapping`` "fragment"); NaN in the others, whose samples keep the
    run's warps (a software rasterizer's triangle blocks, threads that fill warps in order) and coalesce as it
    does. From ``program``, the run's (or those passes') lowering where it is at hand (the L2's warming), else
    by lowering each stretch of such passes, from ``pieces`` (:func:`plan_pieces` of ``passes``) where they are
    at hand: in a pass of enough warps, from a sample of the run's own warps (:func:`_traffic_warps`,
    ``sample.traffic_share``), each partition's bytes the run's memory load on it times the sample's coalesced
    bytes per unit of its load there (``census``, the run's census of ``passes``, gives the run's load where it
    is at hand). None where there are none."""
    first, end = passes if passes is not None else (0, len(work.plan.passes))
    fragment = np.array([thread_mapping(gpu, pk) == "fragment" for pk in work.plan.passes[first:end]], bool)
    if not fragment.any():
        return None
    out = np.full((end - first, gpu.memory.partitions), np.nan)
    if program is not None:
        out[fragment] = memory_bytes(program, gpu)[fragment]
        return out
    edges = np.flatnonzero(np.diff(np.concatenate(([0], fragment.astype(np.int8), [0]))))
    for a, b in zip(edges[::2].tolist(), edges[1::2].tolist()):      # each stretch [a, b) of fragment passes
        mine = (plan_pieces(work, (first + a, first + b)) if pieces is None else
                Pieces(dataclasses.replace(pc, pass_index=pc.pass_index - a) for pc in pieces if a <= pc.pass_index < b))
        warps = scale = None
        if gpu.sample.traffic_share < 1 and gpu.raster.warp_packing == "submission":
            load = (None if census is None or "memory" not in census.every else
                    census.every["memory"].reshape(-1, gpu.memory.partitions)[a:b])
            mine, warps, scale = _traffic_warps(work, gpu, mine, first + a, b - a, load)
        got = memory_bytes(lower(work, gpu, passes=(first + a, first + b), pieces=mine, warps=warps), gpu)
        out[a:b] = got if scale is None else got * scale
    return out


#: warps a pass's traffic sample keeps at least (:func:`_traffic_warps`): a pass with fewer than this many times
#: ``1 / sample.traffic_share`` is lowered whole (with 256, a partition's bytes were up to 7% off on the
#: 193K-fragment default scene at 256x256, and the quick-start report's median sampled error doubled; with 1024,
#: TFSS's capture pass on foliage at 160x160, 9,100 warps, came out 1.0% longer than with the whole traffic)
MIN_TRAFFIC_WARPS = 2048


def _traffic_warps(work: Workload, gpu, pieces: list, p0: int, n_pass: int, load: np.ndarray | None = None
                   ) -> tuple[Pieces, object, np.ndarray]:
    """The run's traffic sample of the ``pieces`` of ``n_pass`` fragment passes from the plan's ``p0``: in each pass
    of enough warps (and no scoreboard, which packs its own), one of the run's warps at random in each block of
    ``round(1 / sample.traffic_share)`` consecutive ones (none where that is 1), whole (their bytes are the run's
    own). (The pieces of those warps' rows, every row of the other passes; the ``warps``
    :func:`gpusim.hw.lower.lower` keeps them in; per pass and partition, the run's memory load on it (``load``,
    where the census has counted it) over the sample's, 1 where the pass is left whole.) Each partition is
    scaled by its own ratio: one ratio for the pass (its coalescing taken to be the same on every partition)
    put the stencil-routed A-buffer's partitions up to 9% off on 32x32 pixels, whose stencil and sample arrays,
    which coalesce differently, lie on the partitions in different mixes (its cycles 7.6% short)."""
    c = gpu.sample
    stride = max(1, round(1 / c.traffic_share))
    parts = gpu.memory.partitions
    ops = [g.op for g in work.plan.groups]
    masks: list = [None] * len(pieces)
    scale = np.ones((n_pass, parts))
    chosen: dict[int, np.ndarray] = {}
    last = None                   # the last pass's lanes and their warps
    for p, js in ([] if stride == 1 else split_by(np.array([pc.pass_index for pc in pieces], np.int64))):
        ps = [pieces[j] for j in js]
        if any(work.plan.groups[pc.group].op == "scoreboard" for pc in ps):
            continue
        lanes = _distinct([pc.thread for pc in ps])
        if last is None or not np.array_equal(lanes, last[0]):   # a multi-pass scheme's passes share their lanes
            last = lanes, submission_warps(work, gpu, lanes)[0]
        warp = last[1]
        if int(warp[-1]) + 1 < MIN_TRAFFIC_WARPS * stride:
            continue
        # one warp at random of each block of stride consecutive ones: spread over the pass as systematic
        # sampling is, without its period (one in every stride picked the same memory partitions' addresses)
        pick = np.random.default_rng([c.seed, p0 + int(p)]).integers(stride, size=int(warp[-1]) // stride + 1)
        kept = warp % stride == pick[warp // stride]
        keep = np.zeros(int(lanes[-1]) + 1, bool)
        keep[lanes[kept]] = True
        total = np.zeros(parts) if load is None else load[p]
        sampled = np.zeros(parts)
        mine = [keep[pieces[j].thread] for j in js]
        for j, m in zip(js, mine):
            pc = pieces[j]
            if pc.instructions is not None:
                continue
            if load is None:
                got = memory_load(ops[pc.group], pc.address, pc.nbytes, gpu)
                if got is not None:
                    total += unit_load(got[0], got[1], parts)
            if m.any():
                got = memory_load(ops[pc.group], pc.address[m], pc.nbytes if np.isscalar(pc.nbytes) else pc.nbytes[m],
                                  gpu)
                if got is not None:
                    sampled += unit_load(got[0], got[1], parts)
        if ((total > 0) & (sampled <= 0)).any():     # a partition the sample does not reach: the pass whole
            continue
        for j, m in zip(js, mine):
            masks[j] = m
        scale[p] = np.where(total > 0, total / np.where(sampled > 0, sampled, 1.0), 1.0)
        chosen[int(p)] = warp[kept] // stride
    out = Pieces()
    for pc, m in zip(pieces, masks):
        if m is None or m.all():
            out.append(pc)
        elif m.any():
            out.append(pc.take(np.flatnonzero(m)))

    def warps(p: int, lane_keys: np.ndarray) -> np.ndarray | None:
        got = chosen.get(p)
        if got is not None and len(got) != len(lane_keys):
            raise RuntimeError(f"traffic sample of pass {p0 + p}: {len(got)} warps chosen for {len(lane_keys)} lanes")
        return got

    return out, warps, scale


def coalesced_load(program: Program, gpu, run_bytes: np.ndarray) -> Program:
    """A sample's ``program`` on ``gpu`` whose memory partitions are as busy as the run's coalesced traffic makes
    them in the passes ``run_bytes`` gives (:func:`run_traffic`; NaN rows: passes left as they are): there the
    "memory" occupancy is the run's bytes over the sample's own coalesced bytes (at least 1), and the sample's
    own load those bytes. A replicate packs into a warp the fragments of tiles that lie far apart, so its warps
    coalesce worse than the run's; scaled by the operations' bytes, its DRAM was up to 8% busier than the
    run's."""
    if program.occupancy is None or "memory" not in program.occupancy:
        return program
    mine = memory_bytes(program, gpu)
    known = ~np.isnan(run_bytes)
    ratio = np.where(mine > 0, np.maximum(np.nan_to_num(run_bytes) / np.maximum(mine, 1e-9), 1.0), 1.0)
    factor = np.where(known, ratio, program.occupancy["memory"])
    own = np.where(known, mine, program.own_load["memory"])
    rows = known.all(axis=1)
    reached = program.reached["memory"].copy()
    reached[rows] = reached_share(np.nan_to_num(run_bytes[rows]), mine[rows])
    return dataclasses.replace(program, occupancy=program.occupancy | {"memory": factor},
                               own_load=program.own_load | {"memory": own},
                               reached=program.reached | {"memory": reached})


def thinned(program: Program, gpu, sms: int) -> tuple[Program, np.ndarray]:
    """A thinned replicate's ``program`` on ``sms`` of the GPU's SMs, as the whole GPU on a frame thinned to
    the share of the work each SM keeps: per pass ``theta = min(1, kept / run operations x SMs / sms)``; the
    shared units' load from the rest of the GPU (``Program.occupancy``), the atomic words' chains
    (``Program.hold_scale``) and the front end's cycles per triangle are ``theta`` of the run's (a request
    never holds a unit less than its own service). (The program, ``theta`` per pass.)"""
    n = gpu.core.sms / sms
    theta = np.array([min(1.0, p.operations / p.operations_total * n) if p.operations_total else 1.0
                      for p in program.passes])
    occupancy = None if program.occupancy is None else {
        name: np.maximum(f * theta[:, None], 1.0) for name, f in program.occupancy.items()}
    hold = program.hold_scale
    if hold is not None:
        hold = np.maximum(hold * theta[program.wi_pass[program.storage("atomic")[2]]], 1.0)
    front = program.front_end_cycles if program.front_end_cycles is not None else per_triangle_cycles(gpu)
    return dataclasses.replace(program, occupancy=occupancy, hold_scale=hold,
                               front_end_cycles=(front * theta).tolist(), thinning=theta), theta


def work_check(per_pass: np.ndarray, theta: np.ndarray, checks: list[tuple[np.ndarray, np.ndarray]]
               ) -> tuple[np.ndarray, float, dict | None]:
    """The slope per pass of the cycles with the work, from the replicates' pass cycles ``per_pass``
    (replicates, passes) at the thinning ``theta`` of each and the work checks' (cycles, thinning) per pass,
    ``checks`` (the samples of a pair of :data:`WORK_CHECKS` together on the same SMs): a pass's cycles taken
    to grow linearly with its work, ``a + b x theta`` (a latency floor and a throughput term), ``b`` from each
    check against its pair's mean, and the checks' mean, so that a sample's ``T + b x (1 - theta)`` are its
    cycles on the whole work. Also the standard error the slope adds to a replicate total: from two checks,
    that of their mean slope (half their difference); from one, half the difference of the slopes it gives
    against each member alone; and the checks' figures. No check: slopes of 0."""
    if not checks:
        return np.zeros(per_pass.shape[1]), 0.0, None

    def slope(t, x, cycles, th):
        gap = th - x
        return np.where(gap > 1e-9, (cycles - t) / np.where(gap > 1e-9, gap, 1.0), 0.0)

    pairs = [list(p) for p in WORK_CHECKS[:len(checks)]]
    slopes = [slope(per_pass[p].mean(axis=0), theta[p].mean(axis=0), *c) for p, c in zip(pairs, checks)]
    b = np.mean(slopes, axis=0)
    if len(slopes) > 1:
        spread = np.std(slopes, axis=0, ddof=1) / math.sqrt(len(slopes))
    else:
        (i, j), c = pairs[0], checks[0]
        spread = np.abs(slope(per_pass[i], theta[i], *c) - slope(per_pass[j], theta[j], *c)) / 2
    se = float((spread * (1 - theta.mean(axis=0))).sum())
    info = {"pairs": pairs, "cycles": [int(round(float(c[0].sum()))) for c in checks],
            "pair_cycles": [float(per_pass[p].sum(axis=1).mean()) for p in pairs], "slope_std_error": se}
    return b, se, info


def _units(runs: list[dict], gpu, cycles: int) -> dict:
    """The replicates' unit figures averaged; utilisation from the averaged busy cycles over the GPU's
    instances (the SMs: all of them), the busiest instance's as the replicates' busiest over their mean."""
    out = {}
    for name in dict.fromkeys(n for run in runs for n in run["units"]):
        have = [run["units"][name] for run in runs if name in run["units"]]
        u = {}
        for key in have[0]:
            values = [h[key] for h in have if isinstance(h.get(key), (int, float))]
            if key.startswith("utilisation") or len(values) < len(have):
                continue
            mean = sum(values) / len(values)
            u[key] = mean if key in ("busy_cycles", "hit_rate") else round(mean)
        if name == "core":
            u["instances"] = gpu.core.sms
        if "busy_cycles" in u:
            u["utilisation_mean"] = u["busy_cycles"] / (u["instances"] * cycles) if cycles else 0.0
            spread = [h["utilisation_max"] / h["utilisation_mean"] for h in have if h.get("utilisation_mean")]
            u["utilisation_max"] = u["utilisation_mean"] * (sum(spread) / len(spread) if spread else 1.0)
        out[name] = u
    return out


def _count(counted: dict, census: Census | None) -> None:
    """Add the operations on the atomic units and ROPs the census of the run (or of a chunk of its passes)
    counted to ``counted``: their requests are the run's operations there, not a sample's scaled up (a
    replicate keeps the largest triangle's block, the heaviest warp, whole, so its share of those operations
    can be far from its share of the run's: FreePipe's atomics were 1.5-2.5 times the run's, LucidRaster's
    up to 9 times, on the fidelity corpus)."""
    if census is None:
        return
    for name in ("atomic", "rop"):
        if name in census.every:
            counted[name] = counted.get(name, 0.0) + float(np.sum(census.every[name]))


def _warmed_units(units: dict, dram: dict, cycles: int) -> None:
    """With an L2, the DRAM's requests and busy cycles and the L2's misses in ``units`` are the run's, as the
    functional warming of the L2 gives them (``dram``: :meth:`Outcomes.next_level`), in place of the samples'
    scaled up: a sample's requests take the run's misses only as far as its lanes find the run's, and its
    DRAM requests, scaled by its share of the run's bytes, were 50% over to 80% under the full level's on the
    fidelity corpus (where its cycles were within 1%)."""
    misses = int(round(float(dram["requests"].sum())))
    if "dram" in units:
        busy = dram["busy_cycles"]
        u = units["dram"]
        u["requests"], u["busy_cycles"] = misses, float(busy.sum())
        u["utilisation_mean"] = float(busy.mean()) / cycles if cycles else 0.0
        u["utilisation_max"] = float(busy.max()) / cycles if cycles else 0.0
    if "l2" in units and "misses" in units["l2"]:
        u = units["l2"]
        u["misses"] = misses
        u["hits"] = max(0, int(u["requests"]) - u["misses"])
        u["hit_rate"] = u["hits"] / u["requests"] if u["requests"] else 0.0


def _pieces(work: Workload, gpu, reps: Replicates, passes: tuple[int, int] | None):
    """:func:`gpusim.hw.lower.plan_pieces` of the run (of its passes ``passes``) for its replicates: (only the rows
    some replicate may keep (:meth:`Replicates.candidate_rows`), a census of every operation, the pieces of every
    row); the pieces of every row twice, and no census, where a replicate is the run. The run's pieces are made
    once, for the census, the candidates and the run's own lowering (its traffic, the L2's warming)."""
    every = plan_pieces(work, passes)
    if reps.share >= 1:
        return every, None, every
    first = passes[0] if passes is not None else 0
    census = Census(work.plan, gpu, passes)
    for pc in every:
        if pc.instructions is None:
            census.add(work.plan.groups[pc.group].op, pc.pass_index + first, pc.address, pc.nbytes)
    return _candidate_pieces(work, reps, passes, every, census), census, every


def _candidate_pieces(work: Workload, reps: Replicates, passes: tuple[int, int] | None, every: list, census: Census):
    """The pieces of the rows some replicate may keep (:meth:`Replicates.candidate_rows`), and every row of a
    graphics or software-rasterizer pass in which a replicate holds none: :class:`Keep` gives that replicate
    one unit of the pass's, drawn from all of its rows (as from the pieces of every row). Taken from ``every``,
    the pieces of every row (a replicate keeps or leaves a thread whole, so a kept row's iteration is the one it
    has there), with ``census``, the census of every operation, for the samples' lowering."""
    first, end = passes if passes is not None else (0, len(work.plan.passes))
    reps.seen[first:end] = 0
    totals = pass_operations(work.plan)[first:end]
    pieces = Pieces()
    for pc in every:
        m = reps.candidate_rows(pc.pass_index + first, pc.thread)
        if m is None or m.all():
            pieces.append(pc)
        elif m.any():
            pieces.append(pc.take(np.flatnonzero(m)))
    pieces.census, pieces.totals = census, totals
    if reps.codes is None:                        # no operation asked about: nothing to keep
        return pieces
    held_by_all = (1 << reps.count) - 1
    short = np.flatnonzero((totals > 0) & (reps.codes[first:end] != 0) & (reps.seen[first:end] != held_by_all))
    short += first
    if not len(short):
        return pieces
    whole = np.zeros(len(work.plan.passes), bool)
    whole[short] = True
    merged = sorted([pc for pc in pieces if not whole[pc.pass_index + first]]
                    + [pc for pc in every if whole[pc.pass_index + first]], key=lambda pc: (pc.group, pc.pass_index))
    out = Pieces(merged)
    out.census, out.totals = census, totals
    return out


def _chunk_samples(work: Workload, gpu, reps: Replicates, members: list, first: int, end: int):
    """The pieces of a chunk of passes (``first`` to ``end - 1``) that its samples are lowered from (:func:`_pieces`:
    the rows some replicate may keep, with the census of every operation) and the run's coalesced traffic in
    them (:func:`run_traffic`), with the operations each of ``members`` keeps of the chunk."""
    pieces, _, every = _pieces(work, gpu, reps, (first, end))
    run_bytes = (run_traffic(work, gpu, (first, end), pieces=every, census=pieces.census)
                 if reps.share < 1 and gpu.sample.run_traffic else None)
    del every
    kept = [sum(int(np.count_nonzero(m)) for pc, m in zip(pieces, sample_masks(pieces, Keep(reps, r), first))
                if pc.instructions is None) for r, _ in members]
    return pieces, run_bytes, kept


def _members_of(reps: Replicates, gpu) -> tuple[list, int, list]:
    """The samples the level runs, each (sample, fewest SMs): the replicates; where they are thinned, the work
    checks (pairs of replicates' samples together on the same SMs: twice the work); the scale check (replicates
    0 and 1 on their SMs together). Also the replicates run (one where each would be the whole run) and the
    work checks."""
    count = 1 if reps.share >= 1 else reps.count          # every replicate the whole run: the same figures
    members = [(r, _floor(reps, r)) for r in range(count)]
    work_checks = [p for p in WORK_CHECKS if max(p) < count] if reps.theta < 1 else []
    members += [(p, reps.sms) for p in work_checks]
    if count > 1 and gpu.sample.scale_check:
        members.append((SCALE_CHECK, _floor(reps, SCALE_CHECK)))
    return members, count, work_checks


def scale_check(totals: np.ndarray, machines: list[int], check_run: tuple[dict, int] | None,
                sms: int) -> dict | None:
    """The scale check's figures: from the replicates' cycles ``totals`` on their SMs ``machines`` and the
    check's (record, SMs) ``check_run`` (None: no check) on a GPU of ``sms`` SMs, the bias of a replicate's
    machine size. A pass ends with its last SM, and the latest of ``m`` SMs' finishing times grows as
    ``beta x ln m`` (the extreme-value law of tails no heavier than exponential), so the members' mean
    cycles ``T_p`` on ``m_p`` SMs and the check's ``T_u`` on ``m_u`` give ``beta = (T_u - T_p) / ln(m_u /
    m_p)`` and the replicates' bias against the run on all the SMs ``-beta x ln(sms / m_p)``."""
    if check_run is None:
        return None
    rec, mu = check_run
    pair = list(SCALE_CHECK)
    tp, mp = float(np.mean(totals[pair])), float(np.mean([machines[i] for i in pair]))
    tu = float(sum(rec["cycles"]))
    bias = (tp - tu) * math.log(sms / mp) / math.log(mu / mp) if mu > mp else 0.0
    return {"replicates": pair, "sms": int(mu), "cycles": int(round(tu)), "pair_cycles": tp,
            "pair_sms": mp, "bias_estimate": bias}


def run_sampled(work: Workload, gpu, result=None, reference=None) -> tuple[dict, None]:
    """The sampled level on ``work``: (record, None); see the module docstring."""
    from gpusim.hw.timing import run_full, streamed_record
    start = time.perf_counter()
    reps = Replicates(work, gpu)
    sms, share = reps.sms, reps.share
    front = per_triangle_cycles(gpu)
    # a run over runner.max_operations is sampled a chunk of passes at a time, as the full level replays it
    # (refused where the full level refuses it), before the pieces, which hold every operation of a chunk
    chunks = plan_chunks(work, gpu)
    if chunks is not None and gpu.l2.size_bytes:       # refused before the chunks are counted, not at the first
        raise carried_state(work, gpu)
    rmw_all = rmw_threads(work.plan, work)
    pieces = outcomes = run_bytes = None
    members, count, work_checks = _members_of(reps, gpu)
    spent = {"run": 0.0, "programs": 0.0, "events": 0.0}     # the level's wall time, by what it went to
    counted: dict[str, float] = {}            # the run's operations on the atomic units and ROPs (the census's)
    certain = None                            # the SMs' figures of the units every replicate keeps whole
    whole_units = share < 1 and any(thread_mapping(gpu, pk) == "triangle" for pk in work.plan.passes)
    if chunks is None:
        pieces, _, every = _pieces(work, gpu, reps, None)
        _count(counted, pieces.census)
        certain = certain_figures(work, gpu, reps, pieces) if whole_units else None
        warm = share < 1 and gpu.l2.size_bytes and "l2" in gpu.memory.levels
        run = lower(work, gpu, pieces=every) if warm else None    # the run's L2 outcomes (warming)
        outcomes = Outcomes(run, gpu) if warm else None
        run_bytes = (run_traffic(work, gpu, None, run, every, pieces.census)
                     if share < 1 and gpu.sample.run_traffic else None)
        del run, every
        spent["run"] = time.perf_counter() - start

        def replicate(member, gpu=gpu) -> tuple[dict, int, float, float]:
            r, floor = member
            t0 = time.perf_counter()
            machine, program, theta = _replicate_program(work, gpu, reps, r, pieces, outcomes=outcomes,
                                                         front=front, floor=floor, run_bytes=run_bytes)
            t1 = time.perf_counter()
            rec, _ = run_full(work, machine, program=program)
            return (_replicate(work, rec, [(p.operations, p.operations_total) for p in program.passes],
                               rmw_threads(program, work), rmw_all, theta, certain), machine.core.sms,
                    t1 - t0, time.perf_counter() - t1)

        # the replicates are independent: one per process where the CPUs and their size allow (each then
        # replays its passes serially); the figures are the same
        workers = fork_workers(gpu.runner.workers, len(members), share * work.plan.total_ops(),
                               MIN_REPLICATE_OPERATIONS)
        done = None
        if workers > 1:                          # what the replicates share, counted once before the fork
            t0 = time.perf_counter()
            share_pieces(pieces, work.plan, gpu, len(work.plan.passes))
            reps.prepare(pieces)
            spent["run"] += time.perf_counter() - t0
            serial = gpu.replace(runner=dataclasses.replace(gpu.runner, workers=1))
            done = fork_map(lambda m: replicate(m, serial), members, workers)
        if done is None:
            done = [replicate(m) for m in members]
        runs, machines = [d[0] for d in done], [d[1] for d in done]
        spent["programs"], spent["events"] = sum(d[2] for d in done), sum(d[3] for d in done)
    else:                                    # a chunk of passes at a time, each replicate's sample of each
        # every member runs on one machine size for all the chunks (as when the run is lowered at once), the one
        # its sample of the whole run takes: counted from each chunk's pieces, which are kept for its replay (the
        # rows some replicate may keep: a small share of the run's), so each chunk is expanded once; where a
        # replicate is the whole run, on every SM, and the chunk's pieces are made when it is replayed
        prepared = ([_chunk_samples(work, gpu, reps, members, first, end) for first, end in chunks]
                    if reps.share < 1 else None)
        if prepared is not None:
            total = int(pass_operations(work.plan)[chunks[0][0]:chunks[-1][1]].sum())
            fit = [fitted_sms(gpu, sum(p[2][i] for p in prepared), total, floor)
                   for i, (_, floor) in enumerate(members)]
        else:
            fit = [fitted_sms(gpu, 1, 1, floor) for _, floor in members]
        spent["run"] = time.perf_counter() - start
        streams = [StreamedRun(work, gpu.runner.max_cycles, sampled=True) for _ in members]
        ops: list[list] = [[] for _ in members]
        readers: list[list] = [[] for _ in members]
        thetas: list[list] = [[] for _ in members]
        for c, (first, end) in enumerate(chunks):
            t0 = time.perf_counter()
            if prepared is not None:
                pieces, run_bytes, _ = prepared[c]
                prepared[c] = None
            else:
                pieces, run_bytes, _ = _chunk_samples(work, gpu, reps, [], first, end)
            _count(counted, pieces.census)
            if whole_units:
                certain = _add_figures(certain, certain_figures(work, gpu, reps, pieces, (first, end)))
            spent["run"] += time.perf_counter() - t0
            for i, (r, _) in enumerate(members):
                t0 = time.perf_counter()
                machine, program, theta = _replicate_program(work, gpu, reps, r, pieces, (first, end), front=front,
                                                             sms=fit[i], run_bytes=run_bytes)
                t1 = time.perf_counter()
                streams[i].replay(machine, program, first)
                spent["programs"] += t1 - t0
                spent["events"] += time.perf_counter() - t1
                ops[i] += [(p.operations, p.operations_total) for p in program.passes]
                readers[i].append(_rmw_readers(program))
                thetas[i].append(theta)
                del program
            del pieces
        runs, machines = [], list(fit)
        for i in range(len(members)):
            rec, _ = streamed_record(work, gpu, streams[i])
            runs.append(_replicate(work, rec, ops[i], rmw_threads(np.concatenate(readers[i]), work), rmw_all,
                                   np.concatenate(thetas[i]), certain))
    work_runs = runs[count:count + len(work_checks)]
    check_run = (runs[-1], machines[-1]) if len(runs) > count + len(work_checks) else None
    runs, machines = runs[:count], machines[:count]
    runs += runs[:1] * (reps.count - count)
    machines += machines[:1] * (reps.count - count)
    n = len(runs)
    thin = np.array([run["theta"] for run in runs], np.float64)             # (replicates, passes)
    # a thinned frame's pass cycles extrapolated to the whole work (as they are where nothing is thinned)
    raw = np.array([run["cycles"] for run in runs], np.float64)
    slope, slope_se, work_info = work_check(raw, thin, [(np.array(w["cycles"], np.float64), np.array(w["theta"]))
                                                        for w in work_runs])
    per_pass = raw + slope * (1 - thin)
    if check_run is not None:                 # the scale check's cycles on the whole work, as the replicates'
        rec_u, sms_u = check_run
        check_run = ({"cycles": np.array(rec_u["cycles"]) + slope * (1 - np.array(rec_u["theta"]))}, sms_u)
    totals = per_pass.sum(axis=1)
    mean = float(totals.mean())
    spread = float(totals.std(ddof=1) / math.sqrt(n))
    se = math.hypot(spread, slope_se)
    # the work checks' slope comes from two slopes (one degree of freedom): where it weighs, so does its doubt
    t = t_quantile(0.975, welch_dof(spread, n - 1, slope_se, 1))
    warps = np.mean([run["warps"] for run in runs], axis=0)
    passes = [{"name": p.name, "kind": p.kind, "cycles": int(round(c)), "warps": int(round(wp)),
               "replicate_cycles": [int(x) for x in per_pass[:, i]]}
              for i, (p, c, wp) in enumerate(zip(work.plan.passes, per_pass.mean(axis=0), warps))]
    cycles = sum(p["cycles"] for p in passes)
    rec = {"fidelity": "sampled", "gpu": gpu.name,
           "instructions": int(round(np.mean([run["instructions"] for run in runs]))),
           "operations": int(runs[0]["operations"]), "passes": passes,
           "units_built": list(dict.fromkeys(u for run in runs for u in run["units_built"])),
           "units": _units(runs, gpu, cycles)}
    for name, ops in counted.items():         # the run's operations on a unit, counted: its requests
        if name in rec["units"]:
            rec["units"][name]["requests"] = int(ops)
    if outcomes is not None:
        _warmed_units(rec["units"], outcomes.next_level(gpu), cycles)
    for key in ("rmw_hazards", "rmw_hazard_pixels"):
        rec[key] = int(round(np.mean([run[key] for run in runs])))
    check = scale_check(totals, machines, check_run, gpu.core.sms)
    bias = abs(check["bias_estimate"]) if check else 0.0
    rec["cycles_ci95_low"] = int(math.floor(min(cycles, mean - t * se - bias)))
    rec["cycles_ci95_high"] = int(math.ceil(max(cycles, mean + t * se + bias)))
    rec["cycles_std_error"] = se
    rec["cycle_error_estimate"] = math.hypot(se, bias) / mean if mean else 0.0
    if chunks is not None:
        rec["streamed"] = {"chunks": len(chunks), "passes": [list(c) for c in chunks]}
    rec["sample"] = {"tile": gpu.sample.tile, "fraction": gpu.sample.fraction, "min_tiles": gpu.sample.min_tiles,
                     "seed": gpu.sample.seed,
                     "replicates": n, "sms": sms, "replicate_sms": machines, "share": share, "t_quantile": t,
                     **reps.info,
                     "operations_sampled": [int(run["operations_sampled"]) for run in runs],
                     "replicate_cycles": [int(x) for x in totals], "scale_check": check,
                     "thin": reps.theta, "replicate_thinning": [run["thinning"] for run in runs],
                     "work_check": work_info}
    rec["event_seconds"] = time.perf_counter() - start
    # where the wall time went: counting and lowering the whole run (which a smaller sample does not shorten),
    # lowering the samples and replaying them (summed over the processes that ran them), and the rest
    rec["sample"]["wall_seconds"] = {**{k: round(v, 4) for k, v in spent.items()},
                                     "other": round(max(0.0, rec["event_seconds"] - sum(spent.values())), 4)}
    rec["cycles"] = int(cycles)
    rec["microseconds"] = cycles / gpu.core.clock_mhz
    return rec, None
