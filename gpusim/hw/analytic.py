"""The ``analytic`` fidelity level: cycle bounds from operation counts and unit throughputs.

Works on the scheme's OpPlan groups ("these threads issue ``count`` operations
``op`` on ``structure``"), never expanding the OpStream, so it costs
O(threads) where the event model costs O(operations). Per pass it takes the
largest of

* issue: warp instructions (per warp, the most operations any of its lanes
  issues in the group, so divergence counts) x issue cycles, over the SMs;
* latency: each lane's dependent chain (an operation that waits for a result
  adds that unit's round trip), the slowest warp, or the SM's warps' chains
  divided by the resident warps that hide each other;
* dram: requests (lanes of a warp on one ``memory.segment_bytes`` segment, as
  at the first operation of each lane) x bytes, over all channels;
* atomic: operations over all atomic units, and the hottest address
  (operations on one word serialize at ``same_address_cycles``);
* rop: ROP service cycles of the busiest unit;
* raster: every triangle through the fixed-function rasterizer (graphics
  pipeline geometry passes), or software setup on the SMs (triangle mapping);

plus one round trip of the slowest unit the pass uses. Imbalance across
partitions beyond the hottest address, queueing and L2 hits are not modelled
(the L2, when present, is assumed to catch re-use: DRAM bytes are those of the
first touch). These are estimates: ``gpusim`` reports them beside the full
model in the fidelity report.
"""

from __future__ import annotations

import numpy as np

from gpusim.hw.lower import ATOMIC, MEM, OP_CLASS, OP_PRODUCES, ROP, SCOREBOARD, thread_mapping
from gpusim.hw.machine import flush_cycles
from gpusim.hw.memory import SECTOR
from gpusim.schemes.opstream import OPS, _Range


def _uniq_inv(a: np.ndarray):
    """Sorted distinct values and the inverse (fast when ``a`` is already sorted, as thread lists are)."""
    if len(a) and np.any(a[1:] < a[:-1]):
        order = np.argsort(a, kind="stable")
        s = a[order]
        new = np.r_[True, s[1:] != s[:-1]]
        inv = np.empty(len(a), np.int64)
        inv[order] = np.cumsum(new) - 1
        return s[new], inv
    new = np.r_[True, a[1:] != a[:-1]] if len(a) else np.zeros(0, bool)
    return a[new], np.cumsum(new) - 1


def _run_lengths(a: np.ndarray) -> np.ndarray:
    """How often each distinct value occurs."""
    s = np.sort(a)
    edges = np.flatnonzero(np.r_[True, s[1:] != s[:-1], True]) if len(s) else np.zeros(1, np.int64)
    return np.diff(edges)


def _expand_pass(g, n):
    """(pass, lane index into g.thread, ops) per (pass, thread) of a group spanning passes."""
    i = np.repeat(np.arange(n), g.count)
    first = np.cumsum(g.count) - g.count
    seq = np.arange(len(i)) - np.repeat(first, g.count)
    p = np.asarray(g.pass_fn(i, seq), np.int64)
    key, inv = _uniq_inv(p * n + i)
    return key // n, key % n, np.bincount(inv)


def analytic_timing(result, work, gpu) -> dict:
    plan, bases = result.plan, result.bases()
    c, m = gpu.core, gpu.memory
    ws, cost = c.warp_size, c.issue_cycles * (1 + c.instructions_per_op)
    icn = m.interconnect_latency
    lat = {MEM: 2 * icn + gpu.dram.latency + (gpu.l2.latency if gpu.l2.size_bytes else 0),
           ATOMIC: 2 * icn + gpu.atomic.latency, ROP: 2 * icn + gpu.rop.latency, SCOREBOARD: 0}
    n_pass = len(plan.passes)
    wis = np.zeros(n_pass)
    dram_bytes = np.zeros(n_pass)
    atomic_ops = np.zeros(n_pass)
    hottest = np.zeros(n_pass)
    rop_unit = np.zeros((n_pass, gpu.rop.units))
    used: list[set] = [set() for _ in range(n_pass)]
    chains: dict[int, list] = {}          # pass -> (lanes, chain cycles) per group
    last_producer: dict[int, int | None] = {}
    waited: dict[int, bool] = {}
    for g in plan.groups:
        n = len(g.thread)
        thread = np.arange(n) if isinstance(g.thread, _Range) else g.thread
        op = OPS.index(g.op)
        cls, produces = int(OP_CLASS[op]), bool(OP_PRODUCES[op])
        if g.pass_fn is not None:
            gp, li, cnt = _expand_pass(g, n)
        else:
            gp = np.broadcast_to(np.asarray(g.pass_index, np.int64), (n,))
            li, cnt = np.arange(n), g.count
        nb = g.bytes if not callable(g.bytes) else None
        for p in np.unique(gp).tolist():
            sel = gp == p
            lanes, counts = thread[li[sel]], cnt[sel]
            lanes_sel = li[sel]
            used[p].add(cls)
            if thread_mapping(gpu, plan.passes[p]) == "triangle":
                lanes = work.frag_prim[lanes]
            # warp instructions: lanes in order, each warp issues its busiest lane's count
            ul, inv = _uniq_inv(lanes)
            per_lane = np.bincount(inv, weights=counts, minlength=len(ul))
            warp = np.arange(len(ul)) // ws
            wmax = np.zeros(int(warp[-1]) + 1 if len(warp) else 0)
            np.maximum.at(wmax, warp, per_lane)
            wis[p] += wmax.sum()
            ops = float(counts.sum())
            # first operation of each lane: coalescing and the hottest address
            addr = bases[g.structure] + np.asarray(g.offset(lanes_sel, np.zeros(len(lanes_sel), np.int64)), np.int64)
            if cls == MEM:
                bytes_ = float(nb) if nb is not None else float(np.mean(
                    g.bytes(lanes_sel, np.zeros(len(lanes_sel), np.int64))))
                seg = addr // m.segment_bytes
                wkey = (np.arange(len(seg)) // ws) * (1 << 36) + seg
                requests_per_lane = len(_run_lengths(wkey)) / max(1, len(seg))
                req_bytes = min(max(m.segment_bytes, SECTOR),
                                -(-bytes_ / requests_per_lane // SECTOR) * SECTOR)
                dram_bytes[p] += ops * requests_per_lane * req_bytes
            elif cls == ATOMIC:
                atomic_ops[p] += ops
                hot = _run_lengths(addr)
                hottest[p] = max(hottest[p], float(hot.max()) if len(hot) else 0.0)
            elif cls == ROP:
                unit = (addr // m.interleave_bytes) % gpu.rop.units
                svc = (gpu.blender.cycles_per_op + (nb or 0) / gpu.blender.bytes_per_cycle
                       if g.op == "program_blend" else 1.0 / gpu.rop.ops_per_cycle)
                rop_unit[p] += np.bincount(unit, weights=counts * svc, minlength=gpu.rop.units)
            # dependent chains per lane
            add = per_lane * cost
            lp = last_producer.get(p)
            if g.dep and produces:
                add = add + per_lane * lat[cls]
            elif g.dep and lp is not None and not waited.get(p, False):
                add = add + lat[lp]
            chains.setdefault(p, []).append((ul, add))
            if produces:
                last_producer[p], waited[p] = cls, False
            elif g.dep:
                waited[p] = True
    passes, total = [], 0
    for p, pk in enumerate(plan.passes):
        if pk.kind == "flush":
            cyc = flush_cycles(gpu, -(-work.width * work.height // ws))
            passes.append({"name": pk.name, "kind": pk.kind, "cycles": cyc, "warps": 0, "bound": "flush"})
            total += cyc
            continue
        if p not in chains:
            passes.append({"name": pk.name, "kind": pk.kind, "cycles": 0, "warps": 0, "bound": "empty"})
            continue
        keys = chains[p]
        allk = np.concatenate([k for k, _ in keys])
        ul, inv = _uniq_inv(allk)
        lane_chain = np.bincount(inv, weights=np.concatenate([a for _, a in keys]), minlength=len(ul))
        warp = np.arange(len(ul)) // ws
        n_warps = int(warp[-1]) + 1
        wchain = np.zeros(n_warps)
        np.maximum.at(wchain, warp, lane_chain)
        sm = np.arange(n_warps) % c.sms
        per_sm = np.bincount(sm, weights=wchain, minlength=c.sms)
        n_sm = np.bincount(sm, minlength=c.sms)
        bounds = {
            "issue": float(np.ceil(wis[p] / min(c.sms, n_warps)) * cost),
            "latency": float(max(wchain.max(), (per_sm / np.maximum(1, np.minimum(n_sm, c.warps_per_sm))).max())),
            "dram": dram_bytes[p] / (gpu.dram.bytes_per_cycle * m.partitions),
            "atomic": atomic_ops[p] / (gpu.atomic.ops_per_cycle * m.partitions),
            "atomic_address": hottest[p] * gpu.atomic.same_address_cycles,
            "rop": float(rop_unit[p].max()),
        }
        mapping = thread_mapping(gpu, pk)
        if mapping == "fragment":          # the fixed-function rasterizer sees every triangle
            bounds["raster"] = work.triangles / gpu.raster.triangles_per_cycle
        elif mapping == "triangle":        # software setup on the SMs
            bounds["issue"] += np.ceil(n_warps / min(c.sms, n_warps)) * gpu.raster.setup_instructions * c.issue_cycles
        limit = max(bounds, key=bounds.get)
        cyc = int(np.ceil(bounds[limit])) + max(lat[u] for u in used[p])
        passes.append({"name": pk.name, "kind": pk.kind, "cycles": cyc, "warps": n_warps, "bound": limit})
        total += cyc
    units_built = [name for name, cls in (("dram", MEM), ("atomic", ATOMIC), ("rop", ROP), ("scoreboard", SCOREBOARD))
                   if any(cls in u for u in used)]
    busy = {"dram": dram_bytes.sum() / gpu.dram.bytes_per_cycle, "atomic": atomic_ops.sum() / gpu.atomic.ops_per_cycle,
            "rop": rop_unit.sum()}
    inst = {"dram": m.partitions, "atomic": m.partitions, "rop": gpu.rop.units}
    units = {u: {"busy_cycles": float(busy[u]), "utilisation_mean": float(busy[u]) / (total * inst[u]) if total else 0.0}
             for u in units_built if u in busy}
    return {"fidelity": "analytic", "gpu": gpu.name, "instructions": int(wis.sum()),
            "operations": int(plan.total_ops()), "passes": passes, "units_built": units_built, "units": units,
            "rmw_hazards": None, "total": int(total)}
