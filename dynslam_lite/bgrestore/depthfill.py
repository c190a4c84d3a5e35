"""Paper C, sec. 4: depth holes left after the keyframe mapping, filled by 8-neighbour region
growing with thresholds from a 3-class Otsu split of the depth histogram.

Depth is handled as an 8-bit grey image ``v = round(255 * z / z_max)`` (0 = no depth), as in the
paper. Three classes by two thresholds T0 < T1: C0 = [0, T0 - 1] the near foreground (the moving
object), C1 = [T0, T1 - 1] the depth to restore, C2 = [T1, L - 1] the far background.

* Eqs. 10-11: class probabilities ``P_k = sum_{v in C_k} p_v`` and means ``m_k``.
* Eq. 12 as printed, ``sum_k sum_{v in C_k} (v - m_k)^2 p_v``, is the *within*-class variance;
  Otsu maximises the *between*-class variance ``sum_k P_k (m_k - m)^2`` (m the global mean). The
  two add up to the fixed total variance, so eq. 13's argmax of the between-class variance is the
  argmin of the printed expression: we compute the between-class form.
* Growing (fig. 4): from a seed, a pixel joins the region when it is an 8-neighbour of a region
  pixel, its value v is in [T0, T1) and ``|v - v_neighbour| <= Td`` (Td = 6).

Filling (our reading of "new seeds around the grown region until the hole is filled"): the hole's
own depth is unknown, so the region grows over the known pixels around it, from the known pixel
nearest to the hole centroid whose value is in [T0, T1); hole pixels touching the region take the
mean value of their region neighbours and join it, layer by layer, so the hole is filled from the
C1 surface (what the moving object hid) and never from the foreground or the far background.
When the growth stops with hole pixels left, a new seed is taken among the C1 pixels nearest to
them. :func:`grow_region` shows the growth step by step (fig. 4, vectorised per step); the filling
uses ``cv2.floodFill`` with a floating range, which grows the same region in one call.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from .. import checks

KERNEL8 = np.ones((3, 3), np.uint8)


def otsu3(hist: np.ndarray) -> tuple[int, int]:
    """Thresholds (T0, T1), 0 < T0 < T1 < L, maximising the 3-class between-class variance.

    Classes [0, T0 - 1], [T0, T1 - 1], [T1, L - 1]; ties go to the smallest (T0, T1). Every pair
    is evaluated at once from cumulative sums (L^2 / 2 candidates).
    """
    h = np.asarray(hist, float)
    L = h.size
    if L < 3 or h.sum() <= 0:
        raise ValueError("otsu3 needs a histogram of at least 3 bins with some mass")
    p = h / h.sum()
    v = np.arange(L)
    P = np.concatenate([[0.0], np.cumsum(p)])  # P[T] = mass of [0, T - 1]
    S = np.concatenate([[0.0], np.cumsum(v * p)])  # first moment of [0, T - 1]
    m = S[-1]
    T = np.arange(L + 1)

    def term(wk, sk):  # P_k (m_k - m)^2 of a class of mass wk and first moment sk
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(wk > 0, (sk - wk * m) ** 2 / np.where(wk > 0, wk, 1.0), 0.0)

    # the first class depends on T0 only and the last on T1 only: 1-D, the middle one (T0, T1)
    var = term(P, S)[:, None] + term(P[None, :] - P[:, None], S[None, :] - S[:, None])
    var += term(1.0 - P, m - S)[None, :]
    valid = (T[:, None] >= 1) & (T[None, :] > T[:, None]) & (T[None, :] <= L - 1)
    var[~valid] = -np.inf
    t0, t1 = np.unravel_index(int(np.argmax(var)), var.shape)  # first max in (T0, T1) order
    return int(t0), int(t1)


def depth_to_gray(depth: np.ndarray, z_max: float) -> np.ndarray:
    """(H, W) metres -> uint8 grey, 0 = no depth, 1..255 over (0, z_max]."""
    g = depth / z_max  # in place from here: one full-size temporary
    np.clip(g, 0.0, 1.0, out=g)
    g *= 255.0
    np.rint(g, out=g)
    np.maximum(g, 1, out=g)
    g[~(depth > 0)] = 0
    return g.astype(np.uint8)


def grow_region(gray: np.ndarray, seed: tuple[int, int], t0: int, t1: int, td: int = 6,
                allowed: np.ndarray | None = None) -> list[np.ndarray]:
    """Region growing of fig. 4 from ``seed`` (row, col): the pixels added at each step.

    A pixel joins when it is an 8-neighbour of a pixel added before, ``t0 <= v < t1`` and
    ``|v - v_neighbour| <= td`` for at least one such neighbour. Returns a list of (H, W) bool
    masks, the seed first, then one per growth step (the last step adds at least one pixel).
    """
    g = gray.astype(np.int32)
    ok = (g >= t0) & (g < t1)
    if allowed is not None:
        ok &= allowed
    region = np.zeros(g.shape, bool)
    region[seed] = True
    steps = [region.copy()]
    front = region.copy()
    H, W = g.shape
    while front.any():
        new = np.zeros_like(region)
        ys, xs = np.nonzero(front)
        for dy in (-1, 0, 1):  # 8 shifts of the current front, each vectorised
            for dx in (-1, 0, 1):
                if dy == dx == 0:
                    continue
                y, x = ys + dy, xs + dx
                inside = (y >= 0) & (y < H) & (x >= 0) & (x < W)
                y, x, sy, sx = y[inside], x[inside], ys[inside], xs[inside]
                join = ok[y, x] & ~region[y, x] & (np.abs(g[y, x] - g[sy, sx]) <= td)
                new[y[join], x[join]] = True
        if not new.any():
            break
        region |= new
        steps.append(new)
        front = new
    return steps


def flood_region(gray: np.ndarray, seed: tuple[int, int], td: int, allowed: np.ndarray) -> np.ndarray:
    """The final region of :func:`grow_region` in one call: ``cv2.floodFill`` with a floating
    range (each new pixel within ``td`` of a neighbour already in the region), 8-connected,
    restricted to ``allowed`` (which holds the [T0, T1) test)."""
    return _flood(gray, seed, td, allowed)[0]


def _flood(gray, seed, td, allowed):
    """:func:`flood_region` and the region's bounding box (row0, row1, col0, col1)."""
    H, W = gray.shape
    barrier = np.ones((H + 2, W + 2), np.uint8)  # floodFill's mask: non-zero = never filled
    barrier[1:-1, 1:-1] = ~allowed
    flags = 8 | cv2.FLOODFILL_MASK_ONLY | (2 << 8)
    _, _, _, (x, y, w, h) = cv2.floodFill(gray.copy(), barrier, (int(seed[1]), int(seed[0])), 0, td, td, flags)
    return barrier[1:-1, 1:-1] == 2, (y, y + h, x, x + w)


@dataclass
class DepthFill:
    """Result of :func:`fill_depth_hole`.

    Attributes
    ----------
    depth : (H, W) metres with the hole filled where the growth reached
    filled : (H, W) bool, hole pixels given a value
    thresholds : (T0, T1) on the 8-bit scale
    seeds : (row, col) of every seed used
    """

    depth: np.ndarray
    filled: np.ndarray
    thresholds: tuple[int, int]
    seeds: list[tuple[int, int]] = field(default_factory=list)


def fill_depth_hole(depth: np.ndarray, hole: np.ndarray, z_max: float = 8.0, td: int = 6,
                    max_seeds: int = 20, margin_px: int = 20) -> DepthFill:
    """Fill the pixels of ``hole`` (bool) in ``depth`` (metres) by region growing (module doc).

    The Otsu thresholds come from the histogram of every valid depth of the frame, the moving
    object's depth in the hole included (it is class C0); only pixels outside the hole are
    sources.
    """
    checks.depth("depth", depth)
    checks.mask("hole", hole, depth.shape)
    gray = depth_to_gray(depth, z_max)
    known = (gray > 0) & ~hole
    if not known.any() or not hole.any():
        return DepthFill(depth.copy(), np.zeros_like(hole), (0, 0))
    hist = np.bincount(gray.ravel(), minlength=256)
    hist[0] = 0  # no depth
    t0, t1 = otsu3(hist)
    # work in the hole's box plus a margin: sources farther away are never reached first
    rows, cols = np.flatnonzero(hole.any(axis=1)), np.flatnonzero(hole.any(axis=0))
    m = margin_px
    r0, r1 = max(rows[0] - m, 0), min(rows[-1] + m + 1, hole.shape[0])
    c0, c1 = max(cols[0] - m, 0), min(cols[-1] + m + 1, hole.shape[1])
    sub = fill_crop(gray[r0:r1, c0:c1], hole[r0:r1, c0:c1], known[r0:r1, c0:c1], t0, t1, td, max_seeds)
    vals, filled_sub, seeds = sub
    filled = np.zeros_like(hole)
    filled[r0:r1, c0:c1] = filled_sub
    result = depth.copy()
    result[r0:r1, c0:c1][filled_sub] = vals[filled_sub] / 255.0 * z_max
    return DepthFill(result, filled, (t0, t1), [(y + r0, x + c0) for y, x in seeds])


def fill_crop(gray: np.ndarray, hole: np.ndarray, known: np.ndarray, t0: int, t1: int, td: int,
              max_seeds: int) -> tuple[np.ndarray, np.ndarray, list[tuple[int, int]]]:
    """The filling of :func:`fill_depth_hole` on a crop.

    Returns the grey values (float, hole pixels filled where reached), the filled hole pixels,
    and the seeds (row, col).
    """
    H, W = gray.shape
    out = gray.astype(np.float32)
    src = known & (gray >= t0) & (gray < t1)  # class C1, the depth to restore
    todo = hole.copy()
    seeds: list[tuple[int, int]] = []
    k8 = KERNEL8.astype(np.float32)
    # the seed candidates (row-major flat indices and coordinates); those a region took are dropped
    cand = np.flatnonzero(src)
    cand_r, cand_c = np.divmod(cand, W)
    n_todo = -1
    while todo.any() and cand.size and len(seeds) < max_seeds:
        if np.count_nonzero(todo) != n_todo:  # the centroid of what is left (exact: integer sums)
            n_todo = np.count_nonzero(todo)
            target = np.array([todo.sum(axis=1) @ np.arange(H), todo.sum(axis=0) @ np.arange(W)]) / n_todo
        i = _nearest(cand_r, cand_c, target)
        seed = (int(cand_r[i]), int(cand_c[i]))
        seeds.append(seed)
        region, (a0, a1, b0, b1) = _flood(gray, seed, td, src)
        src &= ~region  # the next seed comes from another region
        left = ~region.ravel()[cand]
        cand, cand_r, cand_c = cand[left], cand_r[left], cand_c[left]
        # the hole pixels touching the region take the mean of their region neighbours; only
        # the region's box widened by one pixel can be touched
        a0, a1, b0, b1 = max(a0 - 1, 0), min(a1 + 1, H), max(b0 - 1, 0), min(b1 + 1, W)
        box = (slice(a0, a1), slice(b0, b1))
        count = cv2.filter2D(region[box].astype(np.float32), -1, k8, borderType=cv2.BORDER_CONSTANT)
        layer_box = todo[box] & (count > 0)
        if not layer_box.any():
            continue
        total = cv2.filter2D(out[box] * region[box], -1, k8, borderType=cv2.BORDER_CONSTANT)
        out[box][layer_box] = total[layer_box] / count[layer_box]
        layer = np.zeros_like(todo)
        layer[box] = layer_box
        todo &= ~layer
        _fill_layers(out, todo, layer)
    return out, hole & ~todo, seeds


def _nearest(rows: np.ndarray, cols: np.ndarray, target: np.ndarray) -> int:
    """Index of the first point (rows, cols) nearest to ``target``, as
    ``np.argmin(np.hypot(rows - target[0], cols - target[1]))`` gives it: ``hypot`` is taken only
    where the squared distance is within rounding of the smallest."""
    dr, dc = rows - target[0], cols - target[1]
    d2 = dr * dr + dc * dc
    near = np.flatnonzero(d2 <= d2.min() * (1 + 1e-9) + 1e-300)
    return int(near[np.argmin(np.hypot(dr[near], dc[near]))])


def _fill_layers(out: np.ndarray, todo: np.ndarray, layer: np.ndarray) -> None:
    """Continue the filling layer by layer, in place: the ``todo`` pixels touching ``layer`` take
    the mean of their ``layer`` neighbours and become the next layer.

    Only the last layer can touch the next one (a pixel next to an older layer would have joined
    that layer's successor), so each step works on the front's pixels alone (flat indices into a
    padded grid, one ``np.bincount`` per step) instead of filtering the whole crop.
    """
    H, W = out.shape
    Wp = W + 2
    open_ = np.zeros((H + 2) * Wp, bool)  # padded: the border is never open
    open_.reshape(H + 2, Wp)[1:-1, 1:-1] = todo
    values = np.zeros((H + 2) * Wp, np.float32)
    values.reshape(H + 2, Wp)[1:-1, 1:-1] = out
    shifts = np.array([dy * Wp + dx for dy in (-1, 0, 1) for dx in (-1, 0, 1) if dy or dx])
    front = np.flatnonzero(np.pad(layer, 1).ravel())
    slots = np.empty((H + 2) * Wp, np.int64)  # scratch: each target pixel's slot in the next front
    while front.size:
        target = (front[None, :] + shifts[:, None]).ravel()  # each neighbour of each front pixel, shift by shift
        keep = open_[target]
        target = np.compress(keep, target)  # np.compress: faster than boolean indexing
        if not target.size:
            break
        from_ = np.empty((len(shifts), front.size))  # the value of the front pixel each entry comes from
        from_[:] = values[front]
        src = np.compress(keep, from_)
        # np.unique(target, return_inverse=True) without sorting every entry: the one entry of
        # each pixel that the scatter kept marks it, only the distinct pixels are sorted
        entry = np.arange(target.size)
        slots[target] = entry
        front = np.sort(target[slots[target] == entry])
        slots[front] = np.arange(front.size)
        slot = slots[target]
        total = np.bincount(slot, src, len(front))  # in the order of the entries
        values[front] = (total / np.bincount(slot, None, len(front))).astype(np.float32)
        open_[front] = False
    out[:] = values.reshape(H + 2, Wp)[1:-1, 1:-1]
    todo[:] = open_.reshape(H + 2, Wp)[1:-1, 1:-1]
