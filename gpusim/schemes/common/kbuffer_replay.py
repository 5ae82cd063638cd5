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

import numpy as np

from gpusim.schemes.base import composite_stored


def make_replay(trace, pix: np.ndarray, key: np.ndarray, k: int, blend: bool, colour_format: str,
                hazard_free: np.ndarray):
    """``replay(read_cycle, write_cycle) -> (image, stats)`` for fragment threads of ``trace``."""

    def replay(read: np.ndarray, write: np.ndarray):
        n = len(pix)
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
        order_out = np.asarray(seq, np.int64)
        image = composite_stored(trace, pix, order_out, colour_format)
        kept = np.zeros(n, bool)
        kept[order_out] = True
        lost = int(np.count_nonzero(~kept[hazard_free]))
        return image, {"lost_entries": lost, "stored_entries": int(len(order_out)),
                       "hazard_free_entries": int(len(hazard_free))}

    return replay
