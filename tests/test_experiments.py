"""The experiment registry is the one place of every run, and the package's layering holds: one
file per run label, no import cycle, papers never import each other."""
import ast
import math
import re
from pathlib import Path

import pytest

from dynslam_lite import experiments as E
from dynslam_lite.evaluation import ErrorStats, MaskScores, TrajectoryErrors
from dynslam_lite.masks import make_mask_source
from dynslam_lite.pipeline import METHODS, make_config

ROOT = Path(__file__).resolve().parents[1]
PAPERS = ("depthcluster", "weightedstatic", "bgrestore")


def test_every_run_is_valid_and_labelled_once():
    runs = [r for s in E.RUN_SETS for r in s.runs]
    by_label = E.all_runs()
    assert all(by_label[r.label] is r for r in runs)  # one Run object per label
    for r in runs:
        cls = METHODS[r.method]
        make_config(cls.config_type, r.overrides)  # parameters exist
        for kind in ("synthetic", "real"):
            spec = r.mask_source(kind)
            assert spec == "none" or cls.uses_masks, r
            if not spec.startswith("person"):
                make_mask_source(spec)


def test_runs_per_sequence_follow_the_run_sets():
    assert [r.label for r in E.runs_for("synthetic", "static_xyz")] == [
        "static-dense", "opencv-odometry", "depthcluster", "static-orb", "weightedstatic", E.OPENCV_FAST.label]
    assert E.OPENCV_FAST not in E.runs_for("synthetic", "sitting_xyz")
    xyz = E.runs_for("synthetic", "walking_xyz")
    assert len(xyz) == 27 and xyz[-1] is E.BG_ALL_VIEWS and E.BGRESTORE in xyz
    carry = E.runs_for("synthetic", "walking_carry")
    assert carry == [E.STATIC_DENSE, E.OPENCV_ODOMETRY, E.DEPTHCLUSTER, *E.OBJECT_ROWS, *E.SENSITIVITY]
    assert E.DC_PAPER not in carry and E.DC_PAPER in E.runs_for("synthetic", "crowd")
    real = E.runs_for("real")
    assert E.WEIGHTEDSTATIC.mask_source("real") == "person" and E.WEIGHTEDSTATIC.mask_source("synthetic") == "oracle"
    assert E.BG_NO_RESTORE in real and E.BG_MAP_RESTORED in real and E.OPENCV_FAST in real and E.STATIC_ORB_PERSON in real


def test_the_real_clips_at_lower_frame_rates_run_the_main_methods_only():
    assert E.strides() == (1, 2, 3)
    # and depthcluster without its selection, without its brightness model, without its depth gate
    assert set(E.FRAME_RATE_ROWS) == {*E.MAIN, E.DC_NO_SELECT, E.DC_NO_BRIGHTNESS, E.DC_NO_GATE}
    for n in (2, 3):
        assert E.runs_for("real", stride=n) == list(E.FRAME_RATE_ROWS)
        assert E.runs_for("synthetic", "walking_xyz", stride=n) == []
    assert E.BG_NO_RESTORE in E.runs_for("real") and E.BG_NO_RESTORE not in E.runs_for("real", stride=2)
    assert E.sequence_name("real/x", 3) == "real/x/stride3" and E.sequence_name("real/x") == "real/x"


def _files():
    for folder in ("dynslam_lite", "notebooks", "tests"):
        for p in (ROOT / folder).rglob("*"):
            if p.suffix in (".py", ".ipynb", ".md", ".yaml") and "__pycache__" not in p.parts:
                yield p


def test_no_run_label_is_written_outside_the_registry():
    """A label that is not simply its method's name (brackets: mask source, variant) appears in
    experiments.py only: tables, notebooks and tests refer to the Run objects."""
    labels = [label for label, r in E.all_runs().items() if label != r.method]
    assert len(labels) >= 10
    texts = {p: p.read_text(encoding="utf-8") for p in _files()}
    for label in labels:
        where = sorted(str(p.relative_to(ROOT)) for p, t in texts.items() if label in t)
        assert where == ["dynslam_lite/experiments.py"], (label, where)


def _imports(path: Path, package: str) -> set[str]:
    """Package modules imported by ``path`` (any depth, relative imports resolved)."""
    mod = ".".join(path.relative_to(ROOT).with_suffix("").parts)
    base = mod.split(".") if path.name == "__init__.py" else mod.split(".")[:-1]
    if path.name == "__init__.py":
        base = base[:-1] if base[-1] == "__init__" else base
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                parts = base[: len(base) - node.level + 1] + (node.module.split(".") if node.module else [])
            else:
                parts = (node.module or "").split(".")
            if parts[0] == package:
                name = ".".join(parts)
                out.add(name)
                out.update(f"{name}.{a.name}" for a in node.names)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names if a.name.split(".")[0] == package)
    return out


def _graph():
    modules = {}
    for p in (ROOT / "dynslam_lite").rglob("*.py"):
        parts = p.relative_to(ROOT).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        modules[name] = p
    graph = {}
    for name, p in modules.items():
        deps = {d for d in _imports(p, "dynslam_lite") if d in modules and d != name}
        graph[name] = deps
    return graph


def test_no_import_cycle_and_papers_never_import_each_other():
    graph = _graph()
    state: dict[str, int] = {}

    def visit(n, path):
        state[n] = 1
        for d in graph[n]:
            if state.get(d) == 1:
                pytest.fail("import cycle: " + " -> ".join(path + [n, d]))
            if d not in state:
                visit(d, path + [n])
        state[n] = 2

    for n in graph:
        if n not in state:
            visit(n, [])
    for paper in PAPERS:
        for n, deps in graph.items():
            if n.startswith(f"dynslam_lite.{paper}"):
                others = {d for d in deps if any(d.startswith(f"dynslam_lite.{o}") for o in PAPERS if o != paper)}
                assert not others, (n, others)
    assert not graph["dynslam_lite.geometry"] - {"dynslam_lite.checks"}  # pure maths


def test_run_record_round_trips_through_json_with_undefined_numbers_as_null():
    nan = math.nan
    errors = TrajectoryErrors(ErrorStats(0.1, 0.09, 0.08, 0.02, 0.01, 0.3, 12),
                              ErrorStats(nan, nan, nan, nan, nan, nan, 0),
                              ErrorStats(nan, nan, nan, nan, nan, nan, 0), 12)
    rec = E.RunRecord("synthetic/walking_xyz", E.WS_DEGRADED.label, "weightedstatic", "oracle:degraded",
                      "build/data/x", 12, errors, 1, 50.0, {"orb": 7.0}, {"keyframes": 3},
                      {"points/geometric": MaskScores.from_counts(5, 2, 1)}, 40, "synthetic/walking_xyz/x.txt")
    text = E.runs_json([rec])
    assert "NaN" not in text and "null" in text
    import json

    back = E.RunRecord.from_json(json.loads(text)[0])
    assert back.errors.ate == rec.errors.ate and math.isnan(back.errors.rpe_trans.rmse)
    assert back.scores == rec.scores and back.label == rec.label and back.score("points/geometric").tp == 5


def test_notebooks_set_up_in_one_call_and_define_no_package_helper():
    import json

    from dynslam_lite import notebook

    helpers = {n for n in dir(notebook) if not n.startswith("_")} | {"psnr", "gt_pose", "gt_T_w_c", "at"}
    for nb in sorted((ROOT / "notebooks").glob("*.ipynb")):
        code = "\n".join("".join(c["source"]) for c in json.loads(nb.read_text())["cells"] if c["cell_type"] == "code")
        assert len(re.findall(r"nb\.setup\(", code)) == 1, nb.name
        defined = set(re.findall(r"^\s*def (\w+)\(", code, re.M))
        assert not defined & helpers, (nb.name, defined & helpers)
        assert "os.chdir" not in code and "sys.path" not in code, nb.name


def _record(sequence: str, run: E.Run, ate: float, scores=None) -> E.RunRecord:
    s = ErrorStats(ate, ate, ate, 0.0, ate, ate, 10)
    return E.RunRecord(sequence, run.label, run.method, run.mask_source("synthetic"), "x", 10,
                       TrajectoryErrors(s, s, s, 10), scores=scores or {})


def test_object_scenes_are_labelled_rows_of_papers_b_and_c_and_fill_their_own_table():
    from dynslam_lite import tables

    carry = "synthetic/walking_carry"
    recs = [_record(carry, run, 0.01 * (k + 1)) for k, run in enumerate(E.OBJECT_ROWS)]
    recs[E.OBJECT_ROWS.index(E.WEIGHTEDSTATIC)].scores = {"points/geometric": MaskScores.from_counts(8, 2, 2),
                                                          "points/new": MaskScores.from_counts(10, 0, 0)}
    recs[E.OBJECT_ROWS.index(E.WS_NO_SCREEN)].scores = {"points/geometric": MaskScores.from_counts(8, 2, 2)}
    recs.append(_record("synthetic/walking_xyz", E.STATIC_ORB, 0.5))
    for make, measured in ((tables.paper_b_table1, E.WEIGHTEDSTATIC), (tables.paper_c_table1, E.BGRESTORE)):
        header, rows, notes = make(recs)
        ours = [r for r in rows if r[1] == carry]
        assert len(ours) == 1 and ours[0][0].startswith("ours: walking_carry") and ours[0][3:5] == ["-", "-"]
        ate = 0.01 * (E.OBJECT_ROWS.index(measured) + 1)
        assert ours[0][6].startswith(f"{ate:.4f}")  # measured on the scene, no published cell
    header, rows, _ = tables.paper_bc_objects(recs)
    assert [r[2] for r in rows] == [run.label for run in E.OBJECT_ROWS]
    ws = rows[E.OBJECT_ROWS.index(E.WEIGHTEDSTATIC)]
    assert ws[5:8] == ["0.80 / 0.80", "1.00 / 1.00", "0.90 / 0.90"]  # both tests' verdicts pooled
    assert rows[E.OBJECT_ROWS.index(E.WS_NO_SCREEN)][5:8] == ["0.80 / 0.80", "-", "-"]


def test_real_clips_run_the_missed_detector_rows_and_fill_their_own_table():
    """The missed-detection rows of synthetic crowd run on the real clips with the person model
    missing the near people (``person:missed``); the real table lists papers B and C's rows per
    real clip in registry order, with the frames they miss."""
    import dataclasses

    from dynslam_lite import tables

    real = E.runs_for("real")
    assert len(E.MISSED_REAL_ROWS) == len(E.MISSED_ROWS) and all(r in real for r in E.MISSED_REAL_ROWS)
    for r, s in zip(E.MISSED_REAL_ROWS, E.MISSED_ROWS):
        assert (r.method, r.params) == (s.method, s.params) and r.mask_source("real") == "person:missed"
        assert r.label == s.label.replace(s.masks, "person:missed") and "person model" in r.description
    assert not set(E.MISSED_REAL_ROWS) & set(E.runs_for("synthetic", "crowd"))
    recs = [dataclasses.replace(_record("real/bonn", run, 0.01 * (k + 1)), frames=120)
            for k, run in enumerate(E.REAL_BC_ROWS)]
    recs.append(_record("synthetic/crowd", E.WEIGHTEDSTATIC, 0.5))
    header, rows, notes = tables.paper_bc_real(recs[::-1])
    assert [r[2] for r in rows] == [run.label for run in E.REAL_BC_ROWS] and {r[0] for r in rows} == {"real/bonn"}
    assert rows[0][3] == 0.01 and "frames 24-35, 60-71 and 96-107" in notes


def test_paper_a_ablation_has_the_paper_alone_each_addition_and_the_default_per_sequence():
    from dynslam_lite import tables

    assert [r.label for r in E.runs_for("synthetic", "walking_rpy") if r.method == "depthcluster"] == [
        E.DEPTHCLUSTER.label, E.DC_PAPER.label, E.DC_PRIOR.label, E.DC_GROW.label, E.DC_CUT.label,
        E.DC_BRIGHTNESS.label, E.DC_GATE.label, E.DC_NO_SELECT.label, E.DC_NO_BRIGHTNESS.label, E.DC_NO_GATE.label]
    assert E.DC_PAPER in E.runs_for("real") and E.DC_PAPER not in E.runs_for("synthetic", "sitting_xyz")
    # each addition by itself: its own override missing, the others kept off
    offs = {k for k, _ in E.DC_PAPER.params}
    for run in (E.DC_PRIOR, E.DC_GROW, E.DC_CUT, E.DC_BRIGHTNESS):
        assert len(offs - {k for k, _ in run.params}) == 1 and ("release", False) in run.params
        assert ("select_margin", 0.0) in run.params
    assert E.DC_NO_SELECT.params == (("select_margin", 0.0),)  # the default less the selection
    assert E.DC_NO_BRIGHTNESS.params == (("dense.affine_brightness", False),)  # less the brightness model
    xyz, real = "synthetic/walking_xyz", "real/rgbd_bonn_crowd_dev"
    recs = [_record(seq, run, 0.01 * (k + 1), {"pixels/final": MaskScores.from_counts(3, 1, 1)})
            for seq in (real, xyz) for k, run in enumerate(E.PAPER_A_ABLATION)]
    recs.append(_record(xyz, E.STATIC_ORB, 0.5))
    header, rows, _ = tables.paper_a_ablation(recs)
    assert [(r[0], r[2]) for r in rows] == [(s, run.label) for s in (xyz, real) for run in E.PAPER_A_ABLATION]
    assert rows[0][3] == 0.01 and rows[4][3] == 0.05 and rows[0][10:13] == [0.75, 0.75, 0.6]


def test_sensitivity_rows_hold_the_default_and_both_budgets_of_each_object_scene_and_real_clip():
    from dynslam_lite import tables

    assert all(r in E.runs_for("real") for r in E.SENSITIVITY)
    assert all(r in E.runs_for("synthetic", s) for r in E.SENSITIVITY for s in E.OBJECT_SCENES)
    assert not any(r in E.runs_for("synthetic", "walking_xyz") for r in E.SENSITIVITY)
    bonn, push = "real/rgbd_bonn_crowd_dev", "synthetic/walking_push"
    recs = [_record(bonn, E.WEIGHTEDSTATIC, 0.02), *(_record(bonn, r, a) for r, a in
                                                    zip(E.SENSITIVITY_OF[E.WEIGHTEDSTATIC], (0.01, 0.03)))]
    recs += [_record(push, E.BGRESTORE, 0.02), *(_record(push, r, a) for r, a in
                                                 zip(E.SENSITIVITY_OF[E.BGRESTORE], (0.04, 0.03)))]
    recs.append(_record(bonn, E.BGRESTORE, 0.02))  # a base without its variants gives no row
    recs.append(_record("synthetic/walking_xyz", E.WEIGHTEDSTATIC, 0.5))
    header, rows, _ = tables.sensitivity(recs)
    assert [r[:2] for r in rows] == [[push, E.BGRESTORE.label], [bonn, E.WEIGHTEDSTATIC.label]]
    assert rows[1][:5] == [bonn, E.WEIGHTEDSTATIC.label, 0.02, 0.01, 0.03]
    assert abs(rows[1][5] - 0.02) < 1e-12 and rows[1][6] == "3.00" and rows[0][6] == "2.00"


def test_exposure_table_sets_each_exposure_scene_beside_the_scene_it_shows_at_one_exposure():
    from dynslam_lite import tables
    from dynslam_lite.synth import EXPOSURE_SCENES

    assert EXPOSURE_SCENES == {"walking_exposure": "walking_xyz"}
    assert all(r in E.runs_for("synthetic", "walking_exposure") for r in E.EXPOSURE_ROWS)
    recs = [_record("synthetic/walking_exposure", E.DEPTHCLUSTER, 0.03), _record("synthetic/walking_xyz", E.DEPTHCLUSTER, 0.02),
            _record("synthetic/walking_exposure", E.WEIGHTEDSTATIC, 0.01), _record("synthetic/walking_carry", E.BGRESTORE, 0.5)]
    recs[0].extras = {"pair_error_mm_exposure_change": 3.0, "pair_error_mm_elsewhere": 2.0}
    recs[2].extras = {"pair_error_mm_exposure_change": 1.0, "pair_error_mm_elsewhere": 4.0}
    header, rows, _ = tables.exposure(recs)
    assert len(header) == len(rows[0]) == 7
    assert rows == [["walking_exposure (walking_xyz)", E.DEPTHCLUSTER.label, 0.02, 0.03, "3.0", "2.0", "1.50"],
                    ["walking_exposure (walking_xyz)", E.WEIGHTEDSTATIC.label, "-", 0.01, "1.0", "4.0", "0.25"]]
