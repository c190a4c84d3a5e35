"""The notebooks' registry and parameters. Every notebook is executed by the tiny reproduction in
``tests/test_cli.py`` (which also checks the figures each one writes)."""
import re
import subprocess
import sys
from pathlib import Path

import papermill as pm
import pytest

from dynslam_lite.batch import load_registry

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))

# figures each notebook must write (checked after the tiny reproduction)
FIGURES = {
    "10_depthcluster_clustering_and_masks": ["A_fig2_depth_clustering.png", "A_blocks.png",
                                             "A_fig7_removal_synthetic.png"],
    "11_depthcluster_iterations": ["A_fig6_iterations.png", "A_fig6_convergence.png", "A_brightness.png",
                                   "A_fig8_ate.png", "A_fig9_map.png"],
    "20_weightedstatic_masks_and_geometry": ["B_fig7_semantic_static_points.png",
                                             "B_fig4_epipolar_line_motion.png",
                                             "B_fig5_dynamic_points.png", "B_sigma_sweep.png"],
    "21_weightedstatic_weighted_ba": ["B_weights_before_after.png", "B_lm_cost.png",
                                      "B_fig6_trajectory.png"],
    "30_bgrestore_inpainting": ["C_fig3_holes.png", "C_fig3_rgb_restoration.png",
                                "C_fig4_otsu_region_growing.png", "C_fig5_depth_restoration.png",
                                "C_fig6_matches.png", "C_fig7_fig8_trajectory_errors.png",
                                "C_unsegmented_objects.png"],
    "90_results_tables": ["summary_ate.png"],
}


def test_registry_lists_every_notebook_with_declared_parameters_per_profile():
    profiles, notebooks = load_registry()
    assert {"tiny", "quick", "full"} <= set(profiles)
    assert list(notebooks) == [p.stem for p in NOTEBOOKS] == list(FIGURES)
    for nb in NOTEBOOKS:
        declared = set(pm.inspect_notebook(str(nb)))
        for profile, params in notebooks[nb.stem].items():
            assert set(params) <= declared, (nb.stem, profile, set(params) - declared)


@pytest.mark.parametrize("nb", NOTEBOOKS, ids=lambda p: p.stem)
def test_every_parameter_is_documented(nb):
    params = pm.inspect_notebook(str(nb))
    assert params and all(p["help"].strip() for p in params.values()), \
        [n for n, p in params.items() if not p["help"].strip()]
    assert {"output_dir"} <= set(params)


def test_papermill_help_notebook_prints_each_parameter():
    nb = ROOT / "notebooks" / "90_results_tables.ipynb"
    out = subprocess.run([sys.executable, "-m", "papermill", "--help-notebook", str(nb)],
                         capture_output=True, text=True, check=True).stdout
    for name, p in pm.inspect_notebook(str(nb)).items():
        assert re.search(rf"{name}: {p['inferred_type_name']} \(default .*\)\s+{re.escape(p['help'])}", out), (name, out)


def test_notebooks_are_committed_without_outputs():
    import nbformat

    for nb in NOTEBOOKS:
        cells = nbformat.read(nb, as_version=4).cells
        assert not [c for c in cells if c.cell_type == "code" and (c.outputs or c.execution_count)], nb.name
