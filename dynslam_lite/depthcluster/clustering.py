"""Step 1 of paper A: depth k-means clustering and depth hole filling (sec. 3, sec. 6.1, fig. 2).

The depth image is split into ``n = floor((D_max - D_min) / D_sd)`` depth layers (eq. 1) by
1-D k-means. Zero-depth holes are filled first, so that every measured surface gets a layer:

* enclosed holes by grey-scale morphological reconstruction (hole filling by reconstruction by
  erosion: a hole takes the lowest level at which it would spill out, i.e. the surrounding
  depth), as ``imfill`` does;
* zero runs left at object edges (the Kinect shadow beside a depth jump) from the nearest valid
  pixel to their right, up to ``max_edge_run`` pixels (sec. 6.1).

Filled depth is used for clustering and pre-removal only; the pose is estimated on measured
depth, because a filled value is not a measurement.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.cluster.vq import kmeans2

_CROSS = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))


def cluster_count(depth: np.ndarray, min_clusters: int = 2, max_clusters: int = 12) -> int:
    """Eq. 1: ``floor((D_max - D_min) / D_sd)`` over the valid depths, clamped to a sane range.

    Parameters
    ----------
    depth : (H, W) metres, 0 = invalid
    """
    z = depth[depth > 0]
    if z.size < 2 or z.std() == 0:
        return min_clusters
    n = int(np.floor((z.max() - z.min()) / z.std()))
    return int(np.clip(n, min_clusters, max_clusters))


def fill_holes(depth: np.ndarray) -> np.ndarray:
    """Fill enclosed zero-depth holes as morphological reconstruction by erosion does.

    Reconstruction by erosion (marker = the image on its border and +inf inside, geodesic
    erosions ``marker = max(erode(marker), image)`` with the 4-neighbour cross until stable)
    gives every pixel of a 4-connected zero hole the lowest measured depth next to it (the level
    at which the hole would spill out); measured pixels keep their value and holes touching the
    image border stay zero. That fixed point is computed directly: connected components of the
    holes, the minimum of the measured cross-neighbours per component.

    Parameters
    ----------
    depth : (H, W) float32 metres, 0 = invalid
    Returns
    -------
    (H, W) float32
    """
    out = depth.astype(np.float32)  # a copy
    holes = out <= 0
    if not holes.any():
        return out
    n, comp = cv2.connectedComponents(holes.view(np.uint8), connectivity=4)
    # at a hole pixel: the lowest measured depth among its 4 neighbours (inf: none)
    out[holes] = np.inf
    around = cv2.erode(out, _CROSS, borderType=cv2.BORDER_CONSTANT, borderValue=float("inf"))
    rim = holes & (around < np.inf)  # hole pixels next to a measured one (only they lower a level)
    level = np.full(n, np.inf, np.float32)
    np.minimum.at(level, comp[rim], around[rim])
    level[np.concatenate([comp[0], comp[-1], comp[:, 0], comp[:, -1]])] = 0.0  # open to the border
    level[~np.isfinite(level)] = 0.0
    out[holes] = level[comp[holes]]
    return out


def fill_edge_zeros(depth: np.ndarray, max_edge_run: int = 12) -> np.ndarray:
    """Fill zero runs of at most ``max_edge_run`` pixels from the nearest valid pixel to the right.

    Longer runs (a real hole, not an edge shadow) and runs reaching the right border stay zero.
    Vectorised over the zero runs: each row is framed by a valid column on both sides, so a run
    of the flattened image never crosses rows, and a run is where the validity steps down then up.
    """
    z = depth.astype(np.float32)
    H, W = z.shape
    valid = np.ones((H, W + 2), np.int8)  # columns 0 and W + 1: the frame
    valid[:, 1:-1] = z > 0
    step = np.diff(valid.ravel())
    starts = np.flatnonzero(step == -1) + 1  # first zero of each run (framed flat index)
    ends = np.flatnonzero(step == 1) + 1  # the valid pixel right after it
    keep = (ends - starts <= max_edge_run) & (ends % (W + 2) <= W)  # a real pixel on the right
    starts, ends = starts[keep], ends[keep]
    out = z.copy()
    if starts.size == 0:
        return out
    n = ends - starts
    idx = np.repeat(ends - n.cumsum(), n) + np.arange(n.sum())  # every pixel of the kept runs
    flat_src = ends - (ends // (W + 2)) * 2 - 1  # framed -> image flat index: row * W + col - 1
    out.reshape(-1)[idx - (idx // (W + 2)) * 2 - 1] = np.repeat(z.reshape(-1)[flat_src], n)
    return out


def preprocess_depth(depth: np.ndarray, max_edge_run: int = 12) -> np.ndarray:
    """Hole filling by reconstruction, then edge zeros from the right (the order of sec. 3, 6.1)."""
    return fill_edge_zeros(fill_holes(depth), max_edge_run)


@dataclass
class DepthClusters:
    """Depth layers of one frame.

    Attributes
    ----------
    labels : (H, W) int32, layer index (0 = nearest), -1 where there is no depth even after filling
    centres : (n,) float, layer centres in metres, increasing
    filled : (H, W) float32, the hole-filled depth that was clustered
    """

    labels: np.ndarray
    centres: np.ndarray
    filled: np.ndarray

    @property
    def n(self) -> int:
        return len(self.centres)

    def clustered_depth(self) -> np.ndarray:
        """The depth image with every pixel replaced by its layer centre (paper fig. 2b)."""
        out = np.zeros(self.labels.shape, np.float32)
        ok = self.labels >= 0
        out[ok] = self.centres[self.labels[ok]]
        return out


def assign(depth: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """Nearest-centre layer of every pixel (-1 where depth is 0); centres sorted increasing."""
    edges = 0.5 * (centres[1:] + centres[:-1])
    labels = np.zeros(depth.shape, np.int32)
    for e in edges:  # the number of boundaries below each depth (what searchsorted gives)
        labels += depth > e
    labels[depth <= 0] = -1
    return labels


def cluster_depth(
    depth: np.ndarray,
    n_clusters: int | None = None,
    max_samples: int = 20000,
    max_edge_run: int = 12,
    max_clusters: int = 12,
) -> DepthClusters:
    """k-means clustering of the (hole-filled) depth into layers (paper A, sec. 3, eq. 1).

    Deterministic: k-means starts from the depth quantiles ``(i + 0.5) / n`` and runs on an
    evenly strided subsample of at most ``max_samples`` valid pixels; every pixel then takes its
    nearest centre (in 1-D, a threshold between neighbouring centres).

    Parameters
    ----------
    depth : (H, W) float32 metres, 0 = invalid
    n_clusters : layer count; None = eq. 1 on the filled depth
    """
    filled = preprocess_depth(depth, max_edge_run)
    z = filled[filled > 0]
    if z.size == 0:
        return DepthClusters(np.full(depth.shape, -1, np.int32), np.zeros(0), filled)
    n = n_clusters or cluster_count(filled, max_clusters=max_clusters)
    sample = np.sort(z[:: max(1, z.size // max_samples)]).astype(float)
    init = np.unique(np.quantile(sample, (np.arange(n) + 0.5) / n))  # tied quantiles collapse
    centres = _kmeans_1d(sample, init, 20)
    if centres is None:  # centres not strictly increasing: scipy's general k-means
        centres = kmeans2(sample[:, None], init[:, None], iter=20, minit="matrix", missing="warn")[0][:, 0]
    centres = np.unique(np.sort(centres))
    return DepthClusters(assign(filled, centres), centres, filled)


def _kmeans_1d(x: np.ndarray, centres: np.ndarray, iters: int) -> np.ndarray | None:
    """scipy's ``kmeans2(x[:, None], centres[:, None], iters, minit="matrix")`` for sorted 1-D
    ``x``, bit for bit, without its (N, k) distance matrix: with increasing centres each cluster
    is a run of the sorted samples, its ends found where the squared distances (vq's test, ties
    to the lower centre) change order, and its mean summed in order as scipy does. None when the
    centres stop increasing (the caller falls back to scipy)."""
    c = np.array(centres, float)
    n = len(x)
    last: list[int] = []
    for _ in range(iters):
        if np.any(np.diff(c) <= 0):
            return None
        ends = [0]
        for c0, c1 in zip(c[:-1].tolist(), c[1:].tolist()):
            j = int(np.searchsorted(x, 0.5 * (c0 + c1)))  # the split, then vq's exact test around it
            while j > 0 and (float(x[j - 1]) - c1) ** 2 < (float(x[j - 1]) - c0) ** 2:
                j -= 1
            while j < n and not (float(x[j]) - c1) ** 2 < (float(x[j]) - c0) ** 2:
                j += 1
            ends.append(max(j, ends[-1]))
        ends.append(n)
        if ends == last:  # the same clusters give the same centres: converged
            break
        last = ends
        for i, (a, b) in enumerate(zip(ends[:-1], ends[1:])):
            if b > a:  # an empty cluster keeps its centre
                c[i] = np.cumsum(x[a:b])[-1] / (b - a)
    return c


def layer_components(clusters: DepthClusters, edge_tol_m: float = 0.05, edge_tol_rel: float = 0.03):
    """Connected regions of equal depth layer (8-connectivity), split at depth discontinuities.

    A person and the chair behind them can fall into one layer; a step in depth larger than
    ``edge_tol_m + edge_tol_rel * z`` between neighbours separates them.

    Returns
    -------
    components : (H, W) int32, 0 = none, 1..M region ids
    areas : (M + 1,) int64 pixel count per id (index 0 unused)
    """
    z = clusters.filled
    step = np.maximum(np.abs(cv2.Sobel(z, cv2.CV_32F, 1, 0, ksize=1)),
                      np.abs(cv2.Sobel(z, cv2.CV_32F, 0, 1, ksize=1))) * 0.5
    cut = step > edge_tol_m + edge_tol_rel * z
    comp = np.zeros(z.shape, np.int32)
    offset = 0
    for layer in range(clusters.n):
        m = (clusters.labels == layer) & ~cut
        n_cc, cc = cv2.connectedComponents(m.view(np.uint8), connectivity=8)
        cc += offset
        np.copyto(comp, cc, where=m)
        offset += n_cc - 1
    return comp, np.bincount(comp.ravel(), minlength=offset + 1)


def grow_to_components(seed: np.ndarray, components: np.ndarray, areas: np.ndarray,
                       min_overlap: float, max_area: float) -> np.ndarray:
    """Seed pixels plus every region in which at least ``min_overlap`` of the pixels are seeds
    (regions above ``max_area`` pixels, such as a wall, are never taken whole)."""
    hit = np.bincount(components[seed], minlength=areas.size)
    take = (hit >= min_overlap * np.maximum(areas, 1)) & (areas <= max_area)
    take[0] = False
    return seed | select_components(components, take)


def select_components(components: np.ndarray, take: np.ndarray) -> np.ndarray:
    """``take[components]``: (H, W) bool, the pixels of the regions whose ``take`` is True (a few
    regions: one comparison each, cheaper than the whole image's gather)."""
    ids = np.flatnonzero(take)
    if ids.size > 8:
        return take[components]
    out = np.zeros(components.shape, bool)
    for c in ids:
        out |= components == c
    return out
