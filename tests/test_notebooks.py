"""Every notebook runs end to end under papermill on tiny parameters."""
from pathlib import Path

import papermill as pm
import pytest

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))

TINY = {
    "10_depthcluster_clustering_and_masks": {"frames": 8, "pair": 3, "real_pair": 3, "eval_frames": 5},
    "11_depthcluster_iterations": {"frames": 10, "pair": 4, "map_stride": 4},
    "20_weightedstatic_masks_and_geometry": {"frames": 12, "pair": 8, "eval_stride": 3, "real_stride": 30},
    "21_weightedstatic_weighted_ba": {"frames": 12, "pair": 8},
    "30_bgrestore_inpainting": {"frames": 14, "shown": 10, "eval_stride": 5},
}
FIGURES = {
    "10_depthcluster_clustering_and_masks": ["A_fig2_depth_clustering.png", "A_blocks.png",
                                             "A_fig7_removal_synthetic.png"],
    "11_depthcluster_iterations": ["A_fig6_iterations.png", "A_fig6_convergence.png",
                                   "A_fig8_ate.png", "A_fig9_map.png"],
    "20_weightedstatic_masks_and_geometry": ["B_fig7_semantic_static_points.png",
                                             "B_fig4_epipolar_line_motion.png",
                                             "B_fig5_dynamic_points.png", "B_sigma_sweep.png"],
    "21_weightedstatic_weighted_ba": ["B_weights_before_after.png", "B_lm_cost.png",
                                      "B_fig6_trajectory.png"],
    "30_bgrestore_inpainting": ["C_fig3_holes.png", "C_fig3_rgb_restoration.png",
                                "C_fig4_otsu_region_growing.png", "C_fig5_depth_restoration.png",
                                "C_fig6_matches.png", "C_fig7_fig8_trajectory_errors.png"],
}


def test_every_notebook_has_tiny_parameters():
    assert {p.stem for p in NOTEBOOKS} == set(TINY)


@pytest.mark.parametrize("nb", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_runs(nb, tmp_path, synth_cache):
    params = dict(TINY[nb.stem], output_dir=str(tmp_path / "out"), cache_dir=str(synth_cache))
    declared = {p for p in pm.inspect_notebook(str(nb))}
    assert set(params) <= declared, set(params) - declared
    pm.execute_notebook(str(nb), str(tmp_path / nb.name), parameters=params, cwd=str(ROOT),
                        progress_bar=False, kernel_name="python3")
    for fig in FIGURES[nb.stem]:
        assert (tmp_path / "out" / "figures" / fig).stat().st_size > 10_000, fig
