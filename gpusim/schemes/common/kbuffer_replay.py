"""The k-buffer program replayed in event order: what RMW hazards do to the image (seed 004 section 3.2).

On current hardware each fragment reads the pixel's k entries (and, in
sort-and-blend mode, the off-screen framebuffer), modifies them and writes them
all back, with nothing ordering two fragments of one pixel. The timing model
says when each fragment's reads were served and when its writes landed; this
replays the program on those times: a read sees the state of the last write
landed before it (writes first at equal cycles), and a write replaces the
pixel's state with the writer's own result. A fragment that read before an
earlier reader's write landed overwrites that write: its entry is lost (the
artifacts of the paper's Figure 3).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from gpusim.schemes.common.arrays import lex_order

#: the image of the fragments the entries hold (grouped by pixel, in compositing order), as the entries store them
ImageOf = Callable[[np.ndarray], np.ndarray]


def make_replay(pix: np.ndarray, key: np.ndarray, k: int, blend: bool, image_of: ImageOf, hazard_free: np.ndarray):
    """``replay(read_cycle, write_cycle) -> (image, stats)`` for the fragment threads (``pix``, ``key``: their
    pixels and depth keys; ``hazard_free``: what the entries hold without hazards)."""

    def replay(read: np.ndarray, write: np.ndarray):
        return replayed_image(len(pix), replay_entries(pix, key, k, blend, read, write), image_of, hazard_free)

    return replay


def make_multipass_replay(pixel_count: int, pix: np.ndarray, key: np.ndarray, k: int, image_of: ImageOf,
                          hazard_free: np.ndarray):
    """The same for a multi-pass k-buffer (peel mode, one peel per geometry pass): ``read`` and ``write`` hold
    one row per pass with RMW operations (or are one row), replayed one after the other (passes are
    barriers); a pixel composites its entries pass by pass. A pass's fragments are the hazard-free run's,
    less those not behind the depth the replayed previous pass ended at: a fragment a hazard loses is not
    looked for again, and none is composited twice."""

    def replay(read: np.ndarray, write: np.ndarray):
        end = np.full(pixel_count, -1, np.int64)     # depth key the pixel's replayed passes ended at
        got = []
        for r, w in zip(np.atleast_2d(read), np.atleast_2d(write)):
            behind = key.astype(np.int64) > end[pix]
            entries = replay_entries(pix, key, k, False, np.where(behind, r, -1), np.where(behind, w, -1))
            got.append(entries)
            pe = pix[entries]
            last = entries[np.r_[pe[1:] != pe[:-1], True]] if len(entries) else entries
            end[pix[last]] = key[last]
        seq = np.concatenate(got) if got else np.zeros(0, np.int64)
        rank = np.repeat(np.arange(len(got)), [len(o) for o in got])
        return replayed_image(len(pix), seq[lex_order(pix[seq], rank)], image_of, hazard_free)

    return replay


def replayed_image(n: int, order_out: np.ndarray, image_of: ImageOf, hazard_free: np.ndarray):
    """The image of the entries a replay left (grouped by pixel, in compositing order; ``n`` fragments in all)
    and its stats."""
    image = image_of(order_out)
    kept = np.zeros(n, bool)
    kept[order_out] = True
    lost = int(np.count_nonzero(~kept[hazard_free]))
    return image, {"lost_entries": lost, "stored_entries": int(len(order_out)),
                   "hazard_free_entries": int(len(hazard_free))}


def replay_entries(pix: np.ndarray, key: np.ndarray, k: int, blend: bool, read: np.ndarray,
                   write: np.ndarray) -> np.ndarray:
    """The fragments the k entries (and, blending, the framebuffer) hold once the fragment threads with a read
    and a write cycle have run in event order: grouped by pixel ascending, in compositing order."""
    f = np.flatnonzero((read >= 0) & (write >= 0))
    times = np.concatenate([read[f], write[f]])
    kind = np.concatenate([np.ones(len(f), np.int8), np.zeros(len(f), np.int8)])   # writes first
    frag = np.concatenate([f, f])
    order = np.lexsort((frag, kind, times, pix[frag]))
    state: dict[int, tuple] = {}       # pixel -> (entries sorted by (key, index), emitted in order)
    snap: dict[int, tuple] = {}
    keys = key.tolist()
    pix_l = pix.tolist()
    for e in order.tolist():
        fr = int(frag[e])
        p = pix_l[fr]
        if kind[e]:
            snap[fr] = state.get(p, ((), ()))
            continue
        entries, emitted = snap.pop(fr)
        merged = sorted(entries + ((keys[fr], fr),))
        if len(merged) > k:
            if blend:                  # the nearest leaves and is blended into the framebuffer
                emitted = emitted + (merged[0][1],)
                merged = merged[1:]
            else:                      # peel: keep the k nearest
                merged = merged[:k]
        state[p] = (tuple(merged), emitted)
    seq = []
    for p in sorted(state):
        entries, emitted = state[p]
        seq.extend(emitted)
        seq.extend(fr for _, fr in entries)
    return np.asarray(seq, np.int64)
