"""Helpers of the notebooks, kept out of the reader's way: setup, figure saving, ground-truth
lookups and the trajectory plots every paper shows.

Every notebook starts with ``FIG = nb.setup(output_dir)``; figures go through :func:`save`.
"""
from __future__ import annotations

import os
from pathlib import Path

import matplotlib
import matplotlib.pyplot as plt
import numpy as np

from .evaluation import TrajectoryErrors, ate, evaluate, rpe_errors
from .geometry import sample_nearest
from .io import Trajectory

ROOT = Path(__file__).resolve().parents[1]
_figures = Path("reports") / "figures"


def setup(output_dir: str = "reports") -> Path:
    """The repository root as working directory (path parameters are relative to it), one plot
    style, short float printing; figures of :func:`save` go to ``output_dir/figures``, which is
    returned."""
    global _figures
    os.chdir(ROOT)
    np.set_printoptions(precision=4, suppress=True)
    matplotlib.rcParams["figure.dpi"] = 72
    try:  # inline figures as JPEG: executed notebooks stay small (the PNG files are saved by save())
        from matplotlib_inline.backend_inline import set_matplotlib_formats

        set_matplotlib_formats("jpeg", pil_kwargs={"quality": 80})
    except ImportError:  # not in IPython
        pass
    _figures = Path(output_dir) / "figures"
    _figures.mkdir(parents=True, exist_ok=True)
    return _figures


def save(fig, name: str) -> Path:
    """Save a figure as ``output_dir/figures/name`` (fixed metadata: identical bytes run to run)."""
    path = _figures / name
    fig.savefig(path, dpi=80, bbox_inches="tight", metadata={"Software": None})
    print("wrote", path)
    return path


def mask_at(mask: np.ndarray | None, uv: np.ndarray) -> np.ndarray:
    """(N,) bool: the mask under each pixel of ``uv`` (N, 2); all False when there is no mask."""
    return np.zeros(len(uv), bool) if mask is None else sample_nearest(mask, uv)


def relative_truth(gt: Trajectory, t_ref: float, t_cur: float) -> np.ndarray:
    """(4, 4) ground-truth ``T_cur_ref`` between the frames at colour timestamps t_ref, t_cur."""
    return np.linalg.inv(gt.nearest(t_cur)) @ gt.nearest(t_ref)


def plot_trajectory(ax, gt: Trajectory, est: Trajectory, label: str, heat: bool = False,
                    links: bool = False, color=None) -> TrajectoryErrors:
    """Top view (x, z) of ``est`` aligned to ``gt`` (SE(3), evo) over the ground truth.

    ``heat`` colours the estimate by its ATE (paper C fig. 7), ``links`` draws error segments to
    the true positions (paper A fig. 8). Returns the errors (ATE, 1-s RPE).
    """
    e = evaluate(gt, est)
    _, _, aligned = ate(gt, est)
    ref = np.stack([gt.nearest(t)[:3, 3] for t in aligned.timestamps])
    p = aligned.positions
    ax.plot(ref[:, 0], ref[:, 2], "k--" if heat else "k-", lw=0.8 if heat else 1.5, label="ground truth")
    if heat:
        sc = ax.scatter(p[:, 0], p[:, 2], c=np.linalg.norm(p - ref, axis=1), cmap="jet", s=8)
        ax.figure.colorbar(sc, ax=ax, label="ATE (m)")
    else:
        ax.plot(p[:, 0], p[:, 2], "-", color=color, label=f"{label} ({e.ate.rmse:.4f} m)")
    if links:
        for i in range(0, len(p), max(1, len(p) // 40)):
            ax.plot([ref[i, 0], p[i, 0]], [ref[i, 2], p[i, 2]], "r-", lw=0.5)
    ax.set_xlabel("x (m)"); ax.set_ylabel("z (m)"); ax.axis("equal")
    return e


def plot_errors_over_time(ax, gt: Trajectory, est: Trajectory, label: str, ate_too: bool = True) -> None:
    """ATE of each aligned pose and the 1-s RPE (translation) against time (paper C fig. 8)."""
    t0 = est.timestamps[0]
    if ate_too:
        _, _, aligned = ate(gt, est)
        ref = np.stack([gt.nearest(t)[:3, 3] for t in aligned.timestamps])
        ax.plot(aligned.timestamps - t0, np.linalg.norm(aligned.positions - ref, axis=1), label=f"{label} ATE")
    t_end, d, _ = rpe_errors(gt, est)
    ax.plot(t_end - t0, d, "--" if ate_too else "-", label=f"{label} RPE over 1 s")
    ax.set_xlabel("time (s)"); ax.set_ylabel("m"); ax.set_yscale("log")


def overlay(rgb: np.ndarray, mask: np.ndarray, colour=(153, 0, 0)) -> np.ndarray:
    """(H, W, 3) uint8 copy of ``rgb`` with ``mask`` tinted (removed / moving pixels)."""
    shown = rgb.copy()
    shown[mask] = (0.4 * shown[mask] + colour).astype(np.uint8)
    return shown


__all__ = ["setup", "save", "mask_at", "relative_truth", "plot_trajectory", "plot_errors_over_time",
           "overlay", "plt"]
