"""Geometry subdivision for centroid sorting (seed 004 section 4.3, Figure 9, Table 2).

The k-buffer blends a nearly sorted fragment stream; the primitives are put in
order by the depth of their centroids. A long, skinny triangle's centroid says
little about the depth of its fragments, so the paper splits triangles,
prioritised by "how long and skinny they are", until a triangle budget is
reached, with a scheme that keeps the mesh's vertices and surface and "reduces
the total area of triangles with bad aspect ratios":

    Given a triangle, find the longest edge e_max (length l_max) and the
    shortest edge e_min (length l_min). Add a new vertex on e_max at distance
    min(l_min, l_max / 2) from the vertex e_max and e_min share. Recurse.

Each split (:func:`split`) replaces a triangle by two that keep its winding:
the one at the shared vertex (isosceles when l_min <= l_max / 2) and the rest.

Priority (:func:`priority`): the aspect ratio times the longest edge. The
aspect ratio (:func:`aspect_ratio`) is the longest edge over the shortest
altitude, 1 for an equilateral triangle. The paper names the aspect ratio
alone, but on a needle (two long edges, a short base) its scheme cuts an
isosceles piece off the base and leaves a needle similar to the first, of the
same aspect ratio: a queue keyed on the ratio alone would cut the worst needle
for ever, the whole budget going into ever smaller pieces of one triangle.
Weighted by the longest edge, the remainder ranks lower after each cut, long
and skinny triangles still come first, and the key is what the paper says the
ratio stands for, the error a triangle causes in centroid sorting (its depth
extent is at most its longest edge). A triangle with an aspect ratio above
``MAX_ASPECT`` is never split: it is a line rather than a triangle (under 2
pixels wide even across a 16384-pixel screen) and the scheme, cutting a piece
of its width at a time, would spend about that many splits, one after
another, on it and on the needles its first cut leaves.

The priority queue runs in rounds (:func:`subdivide`), vectorised with numpy:
a round lowers a threshold by the factor 1 + ``ROUND_STEP`` and splits every
triangle above it, then every piece still above it, until none is. Where the
budget runs out inside a round, the last step splits the highest of those
still above the threshold. No triangle left ranks above 1 + ROUND_STEP times
where a one-at-a-time queue would have stopped. 360K triangles to 4.3M take
seconds.
"""

from __future__ import annotations

import math

import numpy as np

#: each round of the batched priority queue lowers its threshold by the factor 1 + ROUND_STEP
ROUND_STEP = 1.0 / 16.0
#: a triangle whose aspect ratio is above this is never split (a line, not a triangle)
MAX_ASPECT = 1e4
_SQRT3_4 = math.sqrt(3.0) / 4.0


def _edges(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The edge vectors opposite corners 0, 1 and 2 of (T, 3, D) triangles (edge i joins corners i+1, i+2)."""
    c0, c1, c2 = corners[:, 0], corners[:, 1], corners[:, 2]
    return c2 - c1, c0 - c2, c1 - c0


def edge_lengths(corners: np.ndarray) -> np.ndarray:
    """(T, 3) lengths of the edge opposite each corner of (T, 3, D) triangles: edge i joins corners i+1, i+2."""
    return np.sqrt(np.stack([(e * e).sum(axis=1) for e in _edges(corners)], axis=1))


def _measure(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(edge lengths (T, 3) as :func:`edge_lengths`, areas (T,)) of (T, 3, 3) triangles."""
    e0, e1, e2 = _edges(corners)
    lengths = np.sqrt(np.stack([(e0 * e0).sum(axis=1), (e1 * e1).sum(axis=1), (e2 * e2).sum(axis=1)], axis=1))
    cross = np.stack([e2[:, 1] * e1[:, 2] - e2[:, 2] * e1[:, 1], e2[:, 2] * e1[:, 0] - e2[:, 0] * e1[:, 2],
                      e2[:, 0] * e1[:, 1] - e2[:, 1] * e1[:, 0]], axis=1)
    return lengths, 0.5 * np.sqrt((cross * cross).sum(axis=1))


def areas(corners: np.ndarray) -> np.ndarray:
    """(T,) areas of (T, 3, 3) triangles."""
    return _measure(corners)[1]


def _aspect(lengths: np.ndarray, area: np.ndarray) -> np.ndarray:
    lmax2 = lengths.max(axis=1) ** 2
    out = np.full(len(area), np.inf)
    ok = area > 0.0
    out[ok] = lmax2[ok] / area[ok] * _SQRT3_4
    return out


def aspect_ratio(corners: np.ndarray) -> np.ndarray:
    """(T,) longest edge over shortest altitude of (T, 3, 3) triangles, scaled so an equilateral triangle has 1
    (``l_max^2 sqrt(3) / (4 area)``); ``inf`` for one of zero area."""
    return _aspect(*_measure(corners))


def priority(corners: np.ndarray) -> np.ndarray:
    """(T,) the subdivision's key: aspect ratio times longest edge (length units); ``-inf`` (never split) above
    ``MAX_ASPECT``."""
    lengths, area = _measure(corners)
    aspect = _aspect(lengths, area)
    return np.where(aspect <= MAX_ASPECT, aspect * lengths.max(axis=1), -np.inf)


def _split_plan(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each of (T, 3, 3) triangles: (h, j, t): the new vertex is corner h + t (corner j - corner h), on e_max
    (which joins corners h and j) at distance min(l_min, l_max / 2) from corner h, the corner e_max and e_min
    share."""
    lengths = edge_lengths(corners)
    rows = np.arange(len(corners))
    i = np.argmax(lengths, axis=1)                            # e_max: the edge opposite corner i
    others = lengths.copy()
    others[rows, i] = np.inf
    j = np.argmin(others, axis=1)                             # e_min: the shortest other edge, opposite corner j
    h = 3 - i - j
    l_max, l_min = lengths[rows, i], lengths[rows, j]
    return h, j, np.minimum(l_min, l_max / 2.0) / l_max


def split(corners: np.ndarray, attributes: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One step of the scheme on each of (T, 3, 3) triangles ``corners`` with (T, 3, A) per-corner
    ``attributes`` (interpolated linearly along e_max, as the corners are).

    Returns (first corners, first attributes, second corners, second attributes): the first piece holds the
    vertex e_max and e_min share, the second the other end of e_max; both keep the input's winding."""
    first_c, first_a = corners.copy(), attributes.copy()
    second_c, second_a = corners.copy(), attributes.copy()
    _split_into(first_c, first_a, second_c, second_a)
    return first_c, first_a, second_c, second_a


def _split_into(first_c: np.ndarray, first_a: np.ndarray, second_c: np.ndarray, second_a: np.ndarray) -> None:
    """:func:`split` in place: ``first_*`` and ``second_*`` both hold the triangles on entry; on return the
    first and the second pieces."""
    h, j, t = _split_plan(first_c)
    rows, t = np.arange(len(first_c)), t[:, None]
    new_corner = first_c[rows, h] + t * (first_c[rows, j] - first_c[rows, h])
    new_attr = first_a[rows, h] + t * (first_a[rows, j] - first_a[rows, h])
    first_c[rows, j], first_a[rows, j] = new_corner, new_attr
    second_c[rows, h], second_a[rows, h] = new_corner, new_attr


def target_count(count: int, budget: float) -> int:
    """The triangle count a ``budget`` (times ``count``) allows: floor(budget * count)."""
    return int(math.floor(budget * count + 1e-9))


def subdivide(corners: np.ndarray, attributes: np.ndarray, budget: float) -> tuple[np.ndarray, np.ndarray,
                                                                                  np.ndarray]:
    """Split (T, 3, 3) triangles ``corners`` (the space lengths are measured in) carrying (T, 3, A) per-corner
    ``attributes``, highest :func:`priority` first, until there are floor(``budget`` * T) of them (fewer only
    when no triangle left may be split: every one above ``MAX_ASPECT``).

    Returns (corners, attributes, parent): ``parent`` (T',) is the input triangle each output triangle
    comes from; the outputs are in the input's order, a triangle's pieces together where it stood."""
    corners = np.asarray(corners, dtype=np.float64)
    attributes = np.asarray(attributes, dtype=np.float64)
    count = len(corners)
    if corners.shape != (count, 3, 3) or attributes.ndim != 3 or attributes.shape[:2] != (count, 3):
        raise ValueError(f"subdivide: corners {corners.shape} and attributes {attributes.shape} are not (T, 3, 3) "
                         "and (T, 3, A)")
    if not budget >= 1.0:
        raise ValueError(f"subdivide: budget {budget} is below 1 (1 keeps every triangle as it is)")
    target = max(count, target_count(count, budget))
    pos = np.empty((target, 3, 3))
    att = np.empty((target, 3, attributes.shape[2]))
    parent = np.empty(target, np.int64)
    key = np.empty(target)
    pos[:count], att[:count], parent[:count] = corners, attributes, np.arange(count)
    key[:count] = priority(corners)
    n = count
    threshold = np.inf
    while n < target:
        top = key[:n].max()
        if top == -np.inf:                       # no triangle left may be split
            break
        threshold = min(threshold, top) / (1.0 + ROUND_STEP)
        pick = np.flatnonzero(key[:n] > threshold)
        while len(pick) and n < target:          # the round: split every piece still above the threshold
            room = target - n
            if len(pick) > room:                 # the budget ends here: the highest first
                pick = pick[np.argpartition(key[pick], len(pick) - room)[len(pick) - room:]]
            m = len(pick)
            first_c, first_a = pos[pick], att[pick]
            second_c, second_a = first_c.copy(), first_a.copy()
            _split_into(first_c, first_a, second_c, second_a)
            pos[pick], att[pick] = first_c, first_a
            pos[n:n + m], att[n:n + m], parent[n:n + m] = second_c, second_a, parent[pick]
            both = np.concatenate([pick, np.arange(n, n + m)])
            key[both] = priority(np.concatenate([first_c, second_c]))
            n += m
            pick = both[key[both] > threshold]
    order = np.argsort(parent[:n], kind="stable")  # pieces where their triangle stood
    return pos[:n][order], att[:n][order], parent[:n][order]
