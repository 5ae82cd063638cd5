"""Seed 003: Lin, *Transparent Fragment Storage System for Order-Independent Transparency in GPU* (NCTU 2007).

Targets: Table 4-1 (the eight QUAKE4 frames), Table 4-2 (memory formulas),
Figures 4-3 to 4-7 (memory per frame and L_num with and without leading-0s
elimination; execution time), the headline reductions of sections 4.3 and 5,
and section 4.3.2's execution-time model. The experiment is
configs/experiments/seed-003.toml; its memory figures are the schemes'
``storage_system_bytes`` (Table 4-2's totals) and its times the ``thesis`` level.

The thesis states no fragment size S_f, address size S_A or depth size, and
only one L_num value (3): the comparison sweeps them and shows every
reduction across that range (the sensitivity section), naming the assumption
that comes closest to the thesis's averages.
"""

from __future__ import annotations

import math

import pandas as pd

from gpusim.papers.base import (Comparison, Missing, PaperRow, Section, Target, guarded, mark, mean, one, order_row,
                                select, summary_row)

FRAMES = (60, 120, 180, 240, 300, 360, 420, 480)
W, H = 640, 480
#: Table 4-1: frame -> (all fragments, transparent fragments, pixels with exactly 1..5 transparent fragments)
TABLE_4_1 = {60: (2377518, 37684, (5812, 956, 6633, 2279, 189)), 120: (746943, 37594, (5723, 956, 6634, 2278, 189)),
             180: (516464, 40584, (8713, 956, 6634, 2278, 189)), 240: (488112, 88434, (32588, 12040, 7235, 2279, 189)),
             300: (623531, 60769, (26082, 2729, 6636, 2179, 121)), 360: (587617, 69768, (27421, 7094, 7006, 1569, 173)),
             420: (530258, 47877, (15728, 3290, 6770, 1296, 15)), 480: (605927, 135475, (95226, 8716, 6711, 671, 0))}
#: section 4.3.2's execution-time model evaluated on Table 4-1 (cycles): frame -> (R-buffer, Weight-Factor)
TIME_4_3_2 = {60: (259993, 89972), 120: (259624, 89790), 180: (271584, 95770), 240: (501663, 192074),
              300: (353839, 135437), 360: (396840, 152287), 420: (286086, 106502), 480: (640525, 279674)}
#: the thesis's headline figures (Fig. 4-4, Fig. 4-6, sections 5.1 and 5.2)
REDUCTION_RB = (0.29, 0.18, 0.41)          # TFSS vs R-buffer: mean, lowest, highest
REDUCTION_WF = (0.67, 0.40, 0.81)          # TFSS vs Weight-Factor
LZE_REDUCTION_RB = (0.23, 0.29)            # with leading-0s elimination, vs R-buffer: lowest, highest
LZE_REDUCTION_WF = (0.44, 0.79)
LZE_VS_WF_MEAN = 0.72                      # section 5.1
LZE_SAVING = 0.05                          # section 5.2: leading-0s elimination saves 5% of TFSS's memory
TIME_REDUCTION_RB = 0.45                   # section 5.1: TFSS's execution time vs R-buffer's
TIME_ORDER = ["R-buffer", "TFSS", "Weight-Factor"]   # Fig. 4-7: slowest first
#: the configurations the execution-time rows compare
TIMED = {"R-buffer": ("r-buffer", {"fragment_bytes": 16, "depth_bytes": 4}),
         "TFSS": ("tfss", {"l_num": 2, "address_bytes": 4}),
         "Weight-Factor": ("weight-factor", {"d_avg": 2, "address_bytes": 4})}
LZE_NOTE = ("fixed-length leading-0s elimination (section 3.3), each L_num at its smallest section size that "
            "drops no fragment")
LNUMS = (1, 2, 3)


def frame_scene(frame: int) -> str:
    return f"thesis-frame{frame}"


def memory(results: pd.DataFrame, frame: int, variant: str, **params) -> float:
    return one(results, "stat.storage_system_bytes", scene=frame_scene(frame), variant=variant, **params)


def tfss(results, frame, l_num, address_bytes=4):
    return memory(results, frame, "tfss", l_num=l_num, address_bytes=address_bytes)


def wf(results, frame, d_avg, address_bytes=4):
    return memory(results, frame, "weight-factor", d_avg=d_avg, address_bytes=address_bytes)


def rbuf(results, frame, fragment_bytes=16, depth_bytes=4):
    return memory(results, frame, "r-buffer", fragment_bytes=fragment_bytes, depth_bytes=depth_bytes)


def cycles(results: pd.DataFrame, frame: int, system: str) -> float:
    """The thesis-model cycles of one of :data:`TIMED`'s configurations on ``frame``."""
    variant, params = TIMED[system]
    return one(results, "cycles", scene=frame_scene(frame), variant=variant, **params)


def lowest(values: list[float]) -> float:
    return min(values) if values else mean(values)      # mean raises Missing on none


def highest(values: list[float]) -> float:
    return max(values) if values else mean(values)


def lze_best(results: pd.DataFrame, frame: int, l_num: int) -> float:
    """TFSS with leading-0s elimination at L_num: the smallest memory over the section sizes run that keep
    every fragment (a section too small for a compressed fragment drops it: less memory, a wrong image)."""
    rows = select(results, scene=frame_scene(frame), variant=f"tfss-lze-{l_num}")
    rows = rows[rows["dropped_fragments"] == 0]
    if rows.empty:
        raise Missing(f"no tfss-lze-{l_num} run on frame {frame}")
    return float(rows["stat.storage_system_bytes"].min())


def reductions(results, frames, sa=4, sf=16, z=4) -> tuple[list[float], list[float]]:
    """1 - TFSS/R-buffer and 1 - TFSS/WF (D_avg = L_num) for every frame and L_num run."""
    rb, w = [], []
    for f in frames:
        for lnum in LNUMS:
            try:
                t = tfss(results, f, lnum, sa)
                rb.append(1 - t / rbuf(results, f, sf, z))
                w.append(1 - t / wf(results, f, lnum, sa))
            except Missing:
                continue
    return rb, w


def _frames_run(results: pd.DataFrame) -> list[int]:
    return [f for f in FRAMES if (results["scene"] == frame_scene(f)).any()]


def table_4_2(frame: int, l_num: int = 2, d_avg: int = 2, sa: int = 4, sf: int = 16, z: int = 4) -> dict[str, int]:
    """Table 4-2's memory formulas evaluated on Table 4-1's row for ``frame`` (bytes)."""
    _, transparent, hist = TABLE_4_1[frame]
    counts = {i + 1: c for i, c in enumerate(hist)}
    n_s = sum(c * math.ceil(i / l_num) for i, c in counts.items())
    n_a = sum(c * (math.ceil(i / d_avg) - 1) for i, c in counts.items())
    return {"tfss": l_num * 8 * n_s + sa * W * H + sa * n_s,
            "weight-factor": (W * H + n_a) * d_avg * 8 + sa * (W * H + n_a),
            "r-buffer": transparent * sf + W * H * z + math.ceil(3 * W * H / 8)}


def compare(results: pd.DataFrame, stats: pd.DataFrame) -> Comparison:
    frames = _frames_run(results)
    rows: list[PaperRow] = []
    for f in FRAMES:
        total, transparent, _ = TABLE_4_1[f]
        rows.append(guarded(lambda f=f: one(results, "fragments", scene=frame_scene(f), variant="r-buffer"),
                            f"Table 4-1, Frame{f}", "fragments", total,
                            "the bundled histogram scene is built to have exactly the table's counts"))
        rows.append(guarded(lambda f=f: _stored(results, stats, f), f"Table 4-1, Frame{f}",
                            "transparent fragments (R-buffer FIFO entries)", transparent,
                            "every transparent fragment lies before the opaque ones, so none is culled"))
    for f in FRAMES:
        for scheme, params in (("tfss", {"l_num": 2, "address_bytes": 4}), ("weight-factor", {"d_avg": 2,
                                                                                             "address_bytes": 4}),
                               ("r-buffer", {"fragment_bytes": 16, "depth_bytes": 4})):
            rows.append(guarded(lambda f=f, s=scheme, p=params: memory(results, f, s, **p), f"Table 4-2, Frame{f}",
                                f"{scheme} memory ({', '.join(f'{k}={v}' for k, v in params.items())})",
                                table_4_2(f)[scheme], "[derived] the table's formula evaluated on Table 4-1's "
                                "histogram with these sizes", "bytes"))
    for f in FRAMES:
        t_rb, t_wf = TIME_4_3_2[f]
        rows.append(guarded(lambda f=f: one(results, "cycles", scene=frame_scene(f), variant="r-buffer",
                                            fragment_bytes=16, depth_bytes=4),
                            f"§4.3.2, Frame{f}", "R-buffer execution time (cycles)", t_rb,
                            "the section's access and compute counts, evaluated on Table 4-1 [derived]"))
        rows.append(guarded(lambda f=f: one(results, "cycles", scene=frame_scene(f), variant="weight-factor",
                                            d_avg=2, address_bytes=4),
                            f"§4.3.2, Frame{f}", "Weight-Factor execution time (cycles)", t_wf,
                            "as above; the pointer memory is read in parallel and not counted [derived]"))
    orders = [order_row(f"Fig. 4-7, Frame{f}", "execution time, slowest first", TIME_ORDER,
                        lambda name, f=f: cycles(results, f, name)) for f in frames]
    rows += [*orders, summary_row("Fig. 4-7", "frames in the thesis's order of execution time", orders)]
    rows.append(mark(guarded(lambda: mean([1 - cycles(results, f, "TFSS") / cycles(results, f, "R-buffer")
                                           for f in frames]),
                             "§5.1", "TFSS execution-time reduction vs R-buffer, mean over frames", TIME_REDUCTION_RB,
                             "TFSS pays one SSA look-up per transparent pixel; one per transparent fragment would give "
                             "about 46% (the thesis does not count them)", "share"), Target(points=0.10)))
    rb, w = reductions(results, frames)
    for label, values, paper in (("vs R-buffer", rb, REDUCTION_RB), ("vs Weight-Factor (D_avg = L_num)", w,
                                                                      REDUCTION_WF)):
        note = ("S_f = 16 B (x, y, z 32-bit, RGBA 8-bit), S_A = 4 B, Z = 4 B, L_num 1-3 on every frame; the thesis "
                "states none of these (see the sensitivity section)")
        rows.append(guarded(lambda v=values: mean(v), "§5.1", f"TFSS memory reduction {label}, mean", paper[0],
                            note, "share"))
        rows.append(guarded(lambda v=values: lowest(v), "Fig. 4-4",
                            f"TFSS memory reduction {label}, lowest", paper[1], "over frames and L_num", "share"))
        rows.append(guarded(lambda v=values: highest(v), "Fig. 4-4",
                            f"TFSS memory reduction {label}, highest", paper[2], "over frames and L_num", "share"))
    rows.append(guarded(lambda: tfss(results, 480, 3) / rbuf(results, 480), "Fig. 4-3, Frame480",
                        "TFSS(L_num=3) memory / R-buffer memory", "> 1",
                        "frame480 has mostly single-fragment pixels, which waste two of three slots", "x"))
    rows.append(guarded(lambda: max(tfss(results, f, 3) / rbuf(results, f) for f in frames if f != 480),
                        "Fig. 4-3, other frames", "TFSS(L_num=3) memory / R-buffer memory, highest", "< 1",
                        "the thesis finds TFSS below R-buffer on every other frame", "x"))
    lze = _lze(results, frames)
    rows.append(guarded(lambda: mean(lze["saving"]), "§5.2", "memory leading-0s elimination saves (TFSS, mean)",
                        LZE_SAVING, "best section size run for each L_num; colours uniform in [0, 0.078] as the "
                        "bundled frames draw them (Table 4-1 gives none)", "share"))
    rows.append(guarded(lambda: lowest(lze["rb"]), "Fig. 4-6", "TFSS+LZE memory reduction vs R-buffer, lowest",
                        LZE_REDUCTION_RB[0], LZE_NOTE, "share"))
    rows.append(guarded(lambda: highest(lze["rb"]), "Fig. 4-6", "TFSS+LZE memory reduction vs R-buffer, highest",
                        LZE_REDUCTION_RB[1], LZE_NOTE, "share"))
    rows.append(guarded(lambda: lowest(lze["wf"]), "Fig. 4-6", "TFSS+LZE memory reduction vs Weight-Factor, lowest",
                        LZE_REDUCTION_WF[0], LZE_NOTE, "share"))
    rows.append(guarded(lambda: highest(lze["wf"]), "Fig. 4-6", "TFSS+LZE memory reduction vs Weight-Factor, highest",
                        LZE_REDUCTION_WF[1], LZE_NOTE, "share"))
    rows.append(guarded(lambda: mean(lze["wf"]), "§5.1", "TFSS+LZE memory reduction vs Weight-Factor, mean",
                        LZE_VS_WF_MEAN, LZE_NOTE, "share"))
    return Comparison("Seed 003: Transparent Fragment Storage System (Lin 2007)", rows,
                      _sections(results, stats, frames), _summary(results, frames))


def _stored(results: pd.DataFrame, stats: pd.DataFrame, frame: int) -> float:
    run = select(results, scene=frame_scene(frame), variant="r-buffer", fragment_bytes=16, depth_bytes=4)
    if run.empty:
        raise Missing("no r-buffer run")
    rid = run["run"].iloc[0]
    size = stats[(stats["run"] == rid) & (stats["stat"] == "footprint_bytes")
                 & (stats["labels"] == "structure=r_buffer")]
    if size.empty:
        raise Missing("no r_buffer structure")
    return float(size["value"].iloc[0]) / 16


def _lze(results: pd.DataFrame, frames: list[int]) -> dict[str, list[float]]:
    out = {"saving": [], "rb": [], "wf": []}
    for f in frames:
        for lnum in LNUMS:
            try:
                best = lze_best(results, f, lnum)
                out["saving"].append(1 - best / tfss(results, f, lnum))
                out["rb"].append(1 - best / rbuf(results, f))
                out["wf"].append(1 - best / wf(results, f, lnum))
            except Missing:
                continue
    return out


def _sensitivity(results: pd.DataFrame, frames: list[int]) -> pd.DataFrame:
    rows = []
    for sa in sorted(select(results, variant="tfss")["address_bytes"].dropna().unique()):
        for sf in sorted(select(results, variant="r-buffer")["fragment_bytes"].dropna().unique()):
            for z in sorted(select(results, variant="r-buffer")["depth_bytes"].dropna().unique()):
                rb, w = reductions(results, frames, int(sa), int(sf), int(z))
                if not rb:
                    continue
                distance = abs(mean(rb) - REDUCTION_RB[0]) + abs(mean(w) - REDUCTION_WF[0])
                rows.append({"S_A (B)": int(sa), "S_f (B)": int(sf), "Z (B)": int(z),
                             "vs R-buffer mean": mean(rb), "lowest": min(rb), "highest": max(rb),
                             "vs WF mean": mean(w), "WF lowest": min(w), "WF highest": max(w),
                             "distance to the thesis": distance})
    return pd.DataFrame(rows)


def _lze_explained(results: pd.DataFrame, stats: pd.DataFrame, frames: list[int]) -> str:
    """Where leading-0s elimination's saving goes, measured on L_num = 2: the compressed size, the T-buffer's
    shrinkage, and the T-buffer's share of TFSS's memory."""
    bits, shrink, share, saving = [], [], [], []
    for f in frames:
        plain = select(results, scene=frame_scene(f), variant="tfss", l_num=2, address_bytes=4)
        packed = select(results, scene=frame_scene(f), variant="tfss-lze-2")
        packed = packed[packed["dropped_fragments"] == 0]
        if plain.empty or packed.empty:
            continue
        packed = packed.loc[[packed["stat.storage_system_bytes"].idxmin()]]

        def t_buffer(run_id):
            rows = stats[(stats["run"] == run_id) & (stats["labels"] == "structure=t_buffer")
                         & (stats["stat"] == "footprint_bytes")]
            return float(rows["value"].iloc[0])
        t_plain, t_packed = t_buffer(plain["run"].iloc[0]), t_buffer(packed["run"].iloc[0])
        total = float(plain["stat.storage_system_bytes"].iloc[0])
        bits.append(float(packed["stat.stored_bits_per_fragment"].iloc[0]))
        shrink.append(1 - t_packed / t_plain)
        share.append(t_plain / total)
        saving.append(1 - float(packed["stat.storage_system_bytes"].iloc[0]) / total)
    if not bits:
        return ""
    return (f"At L_num = 2 and the best section size run, a compressed fragment averages {mean(bits):.1f} of 64 bits "
            f"and the T-buffer shrinks by {mean(shrink):.0%}, but the T-buffer is only {mean(share):.0%} of TFSS's "
            f"memory with S_A = 4 B (the SSA table, W x H x S_A, is most of the rest), and the Length Table adds "
            f"its own bytes: TFSS saves {mean(saving):.1%} in all (the thesis: 5%). This is a difference of the "
            "unstated sizes and of the colours, not of the method: with S_A = 2 B the SSA table would halve and "
            "the T-buffer's share, and so the saving, would grow; the bundled frames draw colours uniformly in "
            "[0, 0.078] "
            "(Table 4-1 gives none).")


def _sections(results: pd.DataFrame, stats: pd.DataFrame, frames: list[int]) -> list[Section]:
    sections = []
    sens = _sensitivity(results, frames)
    if not sens.empty:
        best = sens.loc[sens["distance to the thesis"].idxmin()]
        shares = {c: "share" for c in sens.columns if c not in ("S_A (B)", "S_f (B)", "Z (B)")}
        text = ("Table 4-2's memory depends on sizes the thesis does not give: the address size S_A (SSA, NSA and WF "
                "pointers), the R-buffer's fragment size S_f and the depth size Z of its second z-buffer. Each row is "
                "the reduction of TFSS's memory over the frames and L_num = D_avg = 1-3 for one choice. Closest to "
                f"the thesis's averages (29% and 67%): S_A = {int(best['S_A (B)'])} B, S_f = {int(best['S_f (B)'])} B, "
                f"Z = {int(best['Z (B)'])} B, giving {best['vs R-buffer mean']:.0%} and {best['vs WF mean']:.0%}.")
        sections_needed = select(results, variant="tfss")["stat.sections"].max()
        if best["S_A (B)"] < 4 and pd.notna(sections_needed):
            address = int(best["S_A (B)"])
            text += (f" A {address}-byte address reaches {256 ** address:,} sections; the runs need "
                     f"up to {sections_needed:,.0f}.")
        if (sens["lowest"] < 0).all():
            text += (" Under every choice the lowest reduction against R-buffer is negative: on some frame and "
                     "L_num TFSS needs more memory than R-buffer (Figure 4-3 reports it for frame480 at L_num = 3).")
        sections.append(Section("Sensitivity: what the thesis leaves unstated", text, sens, shares))
    lze = _lze_explained(results, stats, frames)
    if lze:
        sections.append(Section("Leading-0s elimination: why it saves less here", lze))
    mem = _chart(frames, [("R-buffer", lambda f: rbuf(results, f) / 2**20),
                          *[(f"WF({d})", lambda f, d=d: wf(results, f, d) / 2**20) for d in LNUMS],
                          *[(f"TFSS({n})", lambda f, n=n: tfss(results, f, n) / 2**20) for n in LNUMS],
                          *[(f"TFSS+LZE({n})", lambda f, n=n: lze_best(results, f, n) / 2**20) for n in LNUMS]])
    if mem:
        sections.append(Section("Figures 4-3 and 4-5: memory per frame",
                                "Table 4-2's totals per frame (S_A = 4 B, S_f = 16 B, Z = 4 B); TFSS+LZE is the "
                                "smallest section size run for its L_num that drops no fragment.",
                                chart=pd.DataFrame(mem),
                                chart_ylabel="memory (MiB)"))
    reduction = _chart(frames, [*[(f"vs R-buffer, TFSS({n})", lambda f, n=n: 100 * (1 - tfss(results, f, n)
                                                                               / rbuf(results, f))) for n in LNUMS],
                                *[(f"vs WF({n}), TFSS({n})", lambda f, n=n: 100 * (1 - tfss(results, f, n)
                                                                                  / wf(results, f, n))) for n in LNUMS],
                                *[(f"vs R-buffer, TFSS+LZE({n})", lambda f, n=n: 100 * (1 - lze_best(results, f, n)
                                                                                       / rbuf(results, f)))
                                  for n in LNUMS]])
    if reduction:
        sections.append(Section("Figures 4-4 and 4-6: memory reduction per frame",
                                "1 - TFSS's memory / the other system's, per frame (S_A = 4 B, S_f = 16 B, Z = 4 B); "
                                "below zero TFSS needs more.", chart=pd.DataFrame(reduction),
                                chart_ylabel="memory reduction (%)"))
    time = _chart(frames, [(label, lambda f, v=variant, p=params: one(results, "cycles", scene=frame_scene(f),
                                                                      variant=v, **p))
                           for label, variant, params in (
                               ("R-buffer", "r-buffer", {"fragment_bytes": 16, "depth_bytes": 4}),
                               ("WF(2)", "weight-factor", {"d_avg": 2, "address_bytes": 4}),
                               ("TFSS(2)", "tfss", {"l_num": 2, "address_bytes": 4}))])
    if time:
        sections.append(Section("Figure 4-7: execution time per frame",
                                "Section 4.3.2's model (`fidelity = thesis`): one cycle per counted memory access "
                                "plus the per-pixel compute of [Amor06].", chart=pd.DataFrame(time),
                                chart_ylabel="cycles (thesis model)"))
    return sections


def _chart(frames: list[int], series) -> list[dict]:
    """Long-form chart rows (x = frame, group = series label) for the (label, value of a frame) series."""
    rows = []
    for f in frames:
        for label, value in series:
            try:
                rows.append({"x": f"frame{f}", "group": label, "value": value(f)})
            except Missing:
                continue
    return rows


def _summary(results: pd.DataFrame, frames: list[int]) -> str:
    rb, w = reductions(results, frames)
    if not rb:
        return "The experiment ran none of the comparison's default configurations."
    text = (f"On the {len(frames)} frames run, with S_A = 4 B, S_f = 16 B and Z = 4 B, TFSS saves {mean(rb):.0%} of "
            f"R-buffer's memory on average (thesis 29%) and {mean(w):.0%} of Weight-Factor's (thesis 67%).")
    exact, checked = 0, 0
    for f in frames:
        for variant, params, paper in (("r-buffer", {"fragment_bytes": 16, "depth_bytes": 4}, TIME_4_3_2[f][0]),
                                       ("weight-factor", {"d_avg": 2, "address_bytes": 4}, TIME_4_3_2[f][1])):
            try:
                exact += one(results, "cycles", scene=frame_scene(f), variant=variant, **params) == paper
                checked += 1
            except Missing:
                continue
    if checked:
        text += (f" Section 4.3.2's execution times, evaluated on Table 4-1, are reproduced exactly in {exact} of "
                 f"{checked} cases.")
    return text + " The memory gaps depend on sizes the thesis does not state (see the sensitivity section)."
