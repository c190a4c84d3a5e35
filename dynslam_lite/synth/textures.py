"""Procedural textures rich enough for ORB corners and photometric gradients.

Each texture is (S, S, 3) float32 RGB in [0, 1], tiled over faces at 256 px per metre.
Multi-scale value noise gives gradients everywhere; drawn rectangles, discs and lines give
corners (posters, books, patterns on clothes).
"""
from __future__ import annotations

import cv2
import numpy as np

SIZE = 512

# Material names, in the order of the list returned by make_textures.
MATERIALS = (
    "wall", "floor", "ceiling", "wood", "books", "poster", "cabinet", "dark",
    "shirt_a", "shirt_b", "trousers", "skin", "chair",
)


def _noise(rng: np.random.Generator, cells: int, size: int = SIZE) -> np.ndarray:
    """Smooth value noise in [-1, 1]: random grid of ``cells`` x ``cells`` upsampled (tileable)."""
    g = rng.uniform(-1.0, 1.0, (cells, cells)).astype(np.float32)
    g = np.pad(g, 1, mode="wrap")
    big = cv2.resize(g, (size + 2 * size // cells, size + 2 * size // cells),
                     interpolation=cv2.INTER_CUBIC)
    off = size // cells
    return np.clip(big[off : off + size, off : off + size], -1.0, 1.0)


def _base(rng, colour, variation=0.12) -> np.ndarray:
    n = 0.5 * _noise(rng, 4) + 0.3 * _noise(rng, 16) + 0.2 * _noise(rng, 64)
    tex = np.asarray(colour, np.float32)[None, None, :] * (1.0 + variation * n[..., None])
    return tex


def _rectangles(rng, tex, count, size_range, palette=None):
    S = tex.shape[0]
    for _ in range(count):
        w, h = rng.integers(size_range[0], size_range[1], 2)
        x, y = rng.integers(0, S - w), rng.integers(0, S - h)
        col = rng.uniform(0.05, 0.95, 3) if palette is None else palette[rng.integers(len(palette))]
        cv2.rectangle(tex, (int(x), int(y)), (int(x + w), int(y + h)), tuple(float(c) for c in col), -1)
    return tex


def make_textures(seed: int) -> list[np.ndarray]:
    """Build the material textures of a scene, deterministic for ``seed``."""
    rng = np.random.default_rng(seed)
    tex: dict[str, np.ndarray] = {}
    wall = _base(rng, (0.78, 0.74, 0.66), 0.15)
    _rectangles(rng, wall, 10, (20, 90))  # posters, notes
    for _ in range(12):
        c = tuple(float(v) for v in rng.uniform(0.1, 0.9, 3))
        cv2.circle(wall, tuple(int(v) for v in rng.integers(0, SIZE, 2)), int(rng.integers(6, 30)), c, -1)
    tex["wall"] = wall
    floor = _base(rng, (0.45, 0.36, 0.28), 0.25)
    for i in range(0, SIZE, 64):  # tiles
        cv2.line(floor, (i, 0), (i, SIZE), (0.2, 0.16, 0.12), 2)
        cv2.line(floor, (0, i), (SIZE, i), (0.2, 0.16, 0.12), 2)
    tex["floor"] = floor
    tex["ceiling"] = _rectangles(rng, _base(rng, (0.85, 0.85, 0.82), 0.08), 6, (30, 80),
                                 [(0.95, 0.95, 0.9), (0.6, 0.6, 0.6)])
    wood = _base(rng, (0.55, 0.38, 0.22), 0.1)
    stripes = np.sin(np.linspace(0, 40 * np.pi, SIZE))[None, :, None] * 0.08
    tex["wood"] = _rectangles(rng, wood * (1 + stripes).astype(np.float32), 8, (15, 60))
    books = _base(rng, (0.4, 0.4, 0.4), 0.1)
    x = 0
    while x < SIZE:  # book spines
        w = int(rng.integers(10, 28))
        cv2.rectangle(books, (x, int(rng.integers(0, 120))), (x + w - 2, SIZE),
                      tuple(float(v) for v in rng.uniform(0.05, 0.95, 3)), -1)
        x += w
    tex["books"] = books
    tex["poster"] = _rectangles(rng, _base(rng, (0.9, 0.9, 0.85), 0.05), 40, (8, 70))
    tex["cabinet"] = _rectangles(rng, _base(rng, (0.3, 0.45, 0.6), 0.15), 14, (20, 60))
    tex["dark"] = _base(rng, (0.08, 0.08, 0.1), 0.3)
    shirt_a = _base(rng, (0.7, 0.15, 0.15), 0.15)
    for i in range(0, SIZE, 24):
        cv2.line(shirt_a, (0, i), (SIZE, i), (0.95, 0.9, 0.8), 6)
    tex["shirt_a"] = shirt_a
    shirt_b = _base(rng, (0.15, 0.3, 0.65), 0.15)
    for i in range(0, SIZE, 32):
        cv2.line(shirt_b, (i, 0), (i, SIZE), (0.9, 0.8, 0.2), 5)
        cv2.line(shirt_b, (0, i), (SIZE, i), (0.05, 0.05, 0.1), 3)
    tex["shirt_b"] = shirt_b
    tex["trousers"] = _rectangles(rng, _base(rng, (0.2, 0.22, 0.3), 0.2), 10, (10, 40))
    tex["skin"] = _base(rng, (0.85, 0.65, 0.52), 0.1)
    tex["chair"] = _rectangles(rng, _base(rng, (0.25, 0.25, 0.28), 0.2), 12, (10, 40))
    return [np.clip(tex[m], 0.0, 1.0).astype(np.float32) for m in MATERIALS]


def material(name: str) -> int:
    """Index of a material name in the texture list."""
    return MATERIALS.index(name)
