"""Seed 004: Bavoil, Callahan, Lefohn, Comba, Silva, *Multi-Fragment Effects on the GPU using the k-Buffer* (2006).

Target: Table 1 (depth peeling with the k-buffer on a GeForce 7900 GTX at
512x512): multi-pass depth peeling (MP, k passes), the single-pass k-buffer
(SP) and the single pass with the heuristics (SPwH: primitives sorted by
centroid, batches of 32 with a flush after each), on Dragon (871K triangles),
Powerplant (12.7M) and Lucy (28M), with k = 4 RGBZ and k = 16 Z-only entries;
and the RMW hazards that make the heuristics necessary (the paper's Fig. 3
shows their artifacts; gpusim's report shows its images replayed in event
order). Table 2 (geometry subdivision) needs a
volume scene and the k-nearly-sorted disorder statistic, which gpusim does not
model yet. The experiment is configs/experiments/seed-004.toml, on look-alike
scenes (configs/scenes/like-*.toml; Powerplant and Lucy scaled down) and the
``geforce7900gtx`` preset.
"""

from __future__ import annotations

import pandas as pd

from gpusim.papers.base import (NOT_MODELLED, WITHIN_1_5X, Comparison, PaperRow, fps, guarded, mark, one, select,
                                summary_row)

DATASETS = (("Dragon", "871k", "like-dragon", 1), ("Powerplant", "12.7M", "like-powerplant", 8),
            ("Lucy", "28.0M", "like-lucy-28m", 14))
#: Table 1: (k, dataset) -> (MP, SP, SPwH) frame rates
TABLE_1 = {(4, "Dragon"): (41.4, 139, 3.1), (16, "Dragon"): (10.3, 139, 2.6),
           (4, "Powerplant"): (5.1, 20.1, 0.2), (16, "Powerplant"): (1.3, 20.1, 0.2),
           (4, "Lucy"): (0.4, 1.7, 0.2), (16, "Lucy"): (0.1, 1.7, 0.1)}
MODES = {"MP": "mp", "SP": "sp", "SPwH": "spwh"}
TABLE_2 = ((1.0, "0.3M", 17), (1.5, "1.0M", 6), (6.0, "4.3M", 3), (12.0, "8.7M", 0))


def _fps(results: pd.DataFrame, scene: str, mode: str, k: int) -> float:
    params = {"max_passes": k} if mode == "MP" else {"k": k}
    return fps(results, scene=scene, variant=MODES[mode], **params)


def compare(results: pd.DataFrame, stats: pd.DataFrame) -> Comparison:
    rows: list[PaperRow] = []
    ratios: list[PaperRow] = []
    for name, tris, scene, scale in DATASETS:
        scaled = f"; the look-alike has {scale}x fewer triangles" if scale > 1 else ""
        for k in (4, 16):
            entries = "4 RGBZ" if k == 4 else "16 Z"
            z_note = "" if k == 4 else "; our entries carry colour (the Z-only format is not modelled)"
            for mode, paper in zip(("MP", "SP", "SPwH"), TABLE_1[(k, name)]):
                note = f"shader clock / full-level cycles on geforce7900gtx{scaled}{z_note}"
                if mode == "MP":
                    passes = select(results, scene=scene, variant="mp", max_passes=k)["geometry_passes"]
                    if len(passes):
                        note += (f"; our depth peeling ran {int(passes.iloc[0])} geometry passes (it stops when the "
                                 "scene's layers are peeled; the paper ran k)")
                rows.append(guarded(lambda s=scene, m=mode, k=k: _fps(results, s, m, k), f"Table 1, {name} ({tris})",
                                    f"{entries}: {mode} frame rate (fps)", paper, note))
            mp, sp, spwh = TABLE_1[(k, name)]
            ratios += [mark(guarded(lambda s=scene, k=k: _fps(results, s, "SP", k) / _fps(results, s, "MP", k),
                                    f"Table 1, {name} ({tris})", f"{entries}: SP / MP", sp / mp,
                                    "[derived] single pass against k peeling passes", "x"), WITHIN_1_5X),
                       mark(guarded(lambda s=scene, k=k: _fps(results, s, "SP", k) / _fps(results, s, "SPwH", k),
                                    f"Table 1, {name} ({tris})", f"{entries}: SP / SPwH", sp / spwh,
                                    "[derived] what the heuristics cost; our flush is a pipeline drain and a "
                                    "full-screen quad (the driver's per-batch work is not modelled)", "x"),
                            WITHIN_1_5X)]
            rows += ratios[-2:]
        rows.append(guarded(lambda s=scene: one(results, "hazards", scene=s, variant="sp", k=4, fidelity="full"),
                            f"§3.2 / Fig. 3, {name}", "RMW hazards of SP, k = 4 (fragments)", "> 0",
                            "the paper shows the artifacts (Fig. 3) without counting them"))
        rows.append(guarded(lambda s=scene: one(results, "hazards", scene=s, variant="spwh", k=4, fidelity="full")
                            / one(results, "hazards", scene=s, variant="sp", k=4, fidelity="full"),
                            f"§3.2, {name}", "RMW hazards of SPwH / of SP, k = 4", "< 1",
                            "the paper: the heuristics (sorted batches of 32, flushed) reduce the artifacts; its "
                            "Fig. 3(b) still shows some", "x"))
    rows.append(summary_row("Table 1", f"SP / MP and SP / SPwH {WITHIN_1_5X} of the paper's", ratios))
    for budget, total, error in TABLE_2:
        rows.append(PaperRow("Table 2", f"max disorder at subdivision budget {budget}x ({total} triangles)", error,
                             NOT_MODELLED, "geometry subdivision and the heart volume mesh are not modelled yet"))
    return Comparison("Seed 004: the k-buffer (Bavoil et al. 2006)", rows, [], _summary(results))


def _summary(results: pd.DataFrame) -> str:
    parts, orderings, total = [], 0, 0
    for name, _, scene, _ in DATASETS:
        for k in (4, 16):
            try:
                mp, sp, spwh = (_fps(results, scene, m, k) for m in ("MP", "SP", "SPwH"))
            except LookupError:
                continue
            total += 1
            orderings += sp > mp > spwh
            paper = TABLE_1[(k, name)]
            parts.append(f"{name} k={k}: SP/MP {sp / mp:.1f}x (paper {paper[1] / paper[0]:.1f}x), "
                         f"SP/SPwH {sp / spwh:.1f}x (paper {paper[1] / paper[2]:.0f}x)")
    if not total:
        return "The experiment ran none of Table 1's configurations."
    hazards = select(results, variant="sp")["hazards"]
    return (f"SP > MP > SPwH holds in {orderings} of {total} rows run. " + "; ".join(parts) + ". "
            + (f"The single pass has {int(hazards.min()):,}-{int(hazards.max()):,} RMW hazards; the images below "
               "show them replayed in event order." if len(hazards.dropna()) else ""))
