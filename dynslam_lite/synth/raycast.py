"""Vectorised ray casting of textured oriented boxes: the renderer of the synthetic benchmark.

Every object is an oriented box (room walls seen from inside, furniture, body parts). A ray per
pixel is intersected with every box by the slab method, all rays at once; the nearest hit
gives depth, the surface normal and texture coordinates on the face hit.

Rays are ``d = R_w_c @ [(u - cx) / fx, (v - cy) / fy, 1]``, so the ray parameter t of a hit
is directly its depth along the camera's optical axis (metres).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry import PinholeCamera, interpolate


@dataclass
class Box:
    """An oriented box.

    Attributes
    ----------
    T_w_b : (4, 4), box-to-world; the box is centred at the origin of its frame
    half : (3,) float, half extents along the box axes (metres)
    texture : int, index into the texture list
    inside : bool, True for the room: rays start inside and hit its far faces
    dynamic : bool, part of an object that can move (people, carried and pushed objects)
    no_depth : bool, surface the depth sensor cannot see (glossy / black)
    instance : int, object instance id for the instance masks (0 = room, no object)
    """

    T_w_b: np.ndarray
    half: np.ndarray
    texture: int
    inside: bool = False
    dynamic: bool = False
    no_depth: bool = False
    instance: int = 0


@dataclass
class Group:
    """Boxes culled together by one bounding box (an articulated body)."""

    bound: Box
    parts: list[Box]


def pixel_rays(camera: PinholeCamera) -> np.ndarray:
    """(3, H*W) float32 camera-frame ray directions with z = 1, row-major pixel order."""
    v, u = np.mgrid[0 : camera.height, 0 : camera.width].astype(np.float32)
    return np.stack(
        [(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, np.ones_like(u)]
    ).reshape(3, -1)


def _slab(box: Box, origin: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Ray parameter of the hit on ``box`` for rays (3, N) from ``origin``; inf where none."""
    R = box.T_w_b[:3, :3].astype(np.float32)
    o = R.T @ (origin - box.T_w_b[:3, 3]).astype(np.float32)
    tnear = np.full(dirs.shape[1], -np.inf, np.float32)
    tfar = np.full(dirs.shape[1], np.inf, np.float32)
    with np.errstate(divide="ignore", invalid="ignore"):
        for k in range(3):  # the three slabs of the box
            d = R[0, k] * dirs[0] + R[1, k] * dirs[1] + R[2, k] * dirs[2]
            inv = np.float32(1.0) / d
            t1 = (np.float32(-box.half[k]) - o[k]) * inv
            t2 = (np.float32(box.half[k]) - o[k]) * inv
            np.maximum(tnear, np.fmin(t1, t2), out=tnear)
            np.minimum(tfar, np.fmax(t1, t2), out=tfar)
    if box.inside:
        return np.where(tfar > 1e-4, tfar, np.inf).astype(np.float32)
    return np.where((tnear <= tfar) & (tnear > 1e-4), tnear, np.inf).astype(np.float32)


def _contains(box: Box, point: np.ndarray) -> bool:
    """Whether ``point`` (3,) lies inside ``box``."""
    local = box.T_w_b[:3, :3].T @ (point - box.T_w_b[:3, 3])
    return bool(np.all(np.abs(local) <= box.half))


def _screen_bounds(camera: PinholeCamera, T_c_w: np.ndarray, box: Box) -> tuple[int, int, int, int] | None:
    """(u0, u1, v0, v1) pixel bounds of the projected box, clipped to the image (u0 > u1 or
    v0 > v1: outside), or None when the box reaches behind the camera (no bound)."""
    corners = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T * box.half
    p_w = corners @ box.T_w_b[:3, :3].T + box.T_w_b[:3, 3]
    p_c = p_w @ T_c_w[:3, :3].T + T_c_w[:3, 3]
    if box.inside or np.any(p_c[:, 2] < 0.05):
        return None
    u = camera.fx * p_c[:, 0] / p_c[:, 2] + camera.cx
    v = camera.fy * p_c[:, 1] / p_c[:, 2] + camera.cy
    return (int(max(np.floor(u.min()), 0)), int(min(np.ceil(u.max()), camera.width - 1)),
            int(max(np.floor(v.min()), 0)), int(min(np.ceil(v.max()), camera.height - 1)))


def _screen_rect(camera: PinholeCamera, T_c_w: np.ndarray, box: Box) -> np.ndarray | None:
    """Flat indices of the pixels inside the projected bounding rectangle of a box, or None
    (= all pixels) when the box reaches behind the camera."""
    b = _screen_bounds(camera, T_c_w, box)
    if b is None:
        return None
    u0, u1, v0, v1 = b
    if u0 > u1 or v0 > v1:
        return np.zeros(0, np.int64)
    cols = np.arange(u0, u1 + 1)
    rows = np.arange(v0, v1 + 1)
    return (rows[:, None] * camera.width + cols[None, :]).reshape(-1)


def render(
    camera: PinholeCamera,
    T_w_c: np.ndarray,
    boxes: list[Box],
    groups: list[Group],
    textures: list[np.ndarray],
    light_w: np.ndarray,
    rays_c: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Render colour, true depth and masks of a scene from one camera pose.

    Parameters
    ----------
    T_w_c : (4, 4) camera-to-world
    boxes : static boxes; groups : culled groups of boxes (bodies)
    textures : list of (S, S, 3) float32 RGB in [0, 1], tiled over faces at 256 px per metre
    light_w : (3,) unit vector towards the light, world frame
    Returns
    -------
    rgb : (H, W, 3) float32 in [0, 1], Lambertian shading, noise-free
    depth : (H, W) float32 metres along the optical axis (inf = nothing hit)
    dynamic : (H, W) bool, pixels showing an object that can move
    no_depth : (H, W) bool, pixels on surfaces the depth sensor cannot see
    instance : (H, W) uint8, object instance id of each pixel (0 = room)
    """
    H, W = camera.height, camera.width
    rays_c = pixel_rays(camera) if rays_c is None else rays_c
    dirs = (T_w_c[:3, :3].astype(np.float32) @ rays_c).astype(np.float32)
    origin = T_w_c[:3, 3].astype(np.float32)
    T_c_w = np.linalg.inv(T_w_c)
    n = dirs.shape[1]
    t_best = np.full(n, np.inf, np.float32)
    prim = np.full(n, -1, np.int32)
    all_boxes: list[Box] = []

    def consider(box: Box, idx: np.ndarray | None, sub: np.ndarray | None = None) -> None:
        """Nearest hits so far, with ``box`` on the rays ``idx`` (None: all; ``sub`` = their directions)."""
        k = len(all_boxes)
        all_boxes.append(box)
        if idx is None:
            t = _slab(box, origin, dirs)
            closer = t < t_best
            np.copyto(t_best, t, where=closer)
            prim[closer] = k
        elif idx.size:
            t = _slab(box, origin, np.take(dirs, idx, axis=1) if sub is None else sub)
            closer = t < np.take(t_best, idx)
            sel = np.compress(closer, idx)
            t_best[sel] = np.compress(closer, t)
            prim[sel] = k

    for box in boxes:
        consider(box, _screen_rect(camera, T_c_w, box))
    for group in groups:
        rect = _screen_rect(camera, T_c_w, group.bound)
        rect = np.arange(n) if rect is None else rect
        if _contains(group.bound, origin):  # a body closer than its bound: no ray enters it
            idx = rect
        else:
            tb = _slab(group.bound, origin, np.take(dirs, rect, axis=1))
            idx = np.compress(tb < np.take(t_best, rect), rect)
        if idx.size:
            sub = np.take(dirs, idx, axis=1)  # gathered once; each part tests the rays inside its own rectangle
            row, col = np.divmod(idx, W)
            for part in group.parts:
                b = _screen_bounds(camera, T_c_w, part)
                if b is None:
                    consider(part, idx, sub)
                    continue
                inside = (col >= b[0]) & (col <= b[1]) & (row >= b[2]) & (row <= b[3])
                consider(part, np.compress(inside, idx), np.compress(inside, sub, axis=1))

    rgb = np.zeros((n, 3), np.float32)
    dynamic = np.zeros(n, bool)
    no_depth = np.zeros(n, bool)
    instance = np.zeros(n, np.uint8)
    order = np.argsort(prim, kind="stable")
    bounds = np.searchsorted(prim[order], np.arange(len(all_boxes) + 1))
    for k, box in enumerate(all_boxes):
        sel = order[bounds[k] : bounds[k + 1]]
        if sel.size == 0:
            continue
        R = box.T_w_b[:3, :3].astype(np.float32)
        o = R.T @ (origin - box.T_w_b[:3, 3]).astype(np.float32)
        d = (np.take(dirs, sel, axis=1).T @ R).astype(np.float32)
        p = o + np.take(t_best, sel)[:, None] * d  # hit points in the box frame
        half = box.half.astype(np.float32)
        ax = np.argmax(np.abs(p) / half, axis=1)  # the face hit is the one the point lies on
        # face coordinates: the two axes other than the face normal, from the face corner
        a1 = np.where(ax == 0, 1, 0)
        a2 = np.where(ax == 2, 1, 2)
        rows = np.arange(sel.size)
        fu = np.take_along_axis(p, a1[:, None], 1)[:, 0] + np.take(half, a1) + 1.7 * ax
        fv = np.take_along_axis(p, a2[:, None], 1)[:, 0] + np.take(half, a2) + 0.9 * ax
        tex = textures[box.texture]
        S = tex.shape[0]
        colour = interpolate(tex, fu * 256.0 % S, fv * 256.0 % S, wrap=True)
        normal_b = np.zeros((sel.size, 3), np.float32)
        normal_b[rows, ax] = -np.sign(d[rows, ax])
        normal_w = normal_b @ R.T
        shade = 0.55 + 0.45 * np.clip(normal_w @ light_w.astype(np.float32), 0.0, 1.0)
        rgb[sel] = colour * shade[:, None]
        dynamic[sel] = box.dynamic
        no_depth[sel] = box.no_depth
        instance[sel] = box.instance
    return (
        rgb.reshape(H, W, 3),
        t_best.reshape(H, W),
        dynamic.reshape(H, W),
        no_depth.reshape(H, W),
        instance.reshape(H, W),
    )
