"""The batch beyond one short run: its plan and ETA, a TUM sequence in the papers' own rows, and
the same tables on a Dask distributed cluster (``reproduce --scheduler``) as on the local pool."""
import shutil

import pytest
from distributed import LocalCluster

from dynslam_lite import batch
from dynslam_lite import experiments as E
from dynslam_lite.cli import main
from dynslam_lite.synth import ensure_scene

from conftest import tiny_plan

TIMED = ("timing", "paper_b_table4")  # wall-clock columns
TUM = "rgbd_dataset_freiburg3_walking_xyz"  # the folder TUM's archive of fr3/walking_xyz unpacks to


def _tables(folder):
    return {p.name: p.read_bytes() for p in (folder / "tables").iterdir() if p.stem not in TIMED}


@pytest.fixture(scope="module")
def local(tmp_path_factory):
    """The tiny profile plus a synthetic scene saved under TUM's folder name of fr3/walking_xyz,
    on the local pool: (folder, printed output, arguments)."""
    root = tmp_path_factory.mktemp("batch")
    tum = root / TUM
    shutil.copytree(ensure_scene(root / "scenes", "walking_xyz", 12, 5), tum)
    args = ["reproduce", "--profile", "tiny", "--no-notebooks", "--cache", str(root / "cache"), "--data", str(tum)]
    out = _run(args + ["--reports", str(root / "local")])
    return root, out, args


def _run(args):
    import io
    from contextlib import redirect_stdout

    buf = io.StringIO()
    with redirect_stdout(buf):
        assert main(args) == 0
    return buf.getvalue()


def test_the_plan_and_an_eta_are_printed(local):
    _, out, _ = local
    runs, frames = tiny_plan(real_frames=12)
    assert f"[plan] {runs} runs, {frames} frames to track; about" in out
    assert f"[run {runs}/{runs}]" in out and ", ETA " in out


def test_a_tum_named_sequence_fills_the_papers_own_rows(local):
    root, _, _ = local
    real = f"real/{TUM}"
    for table, row, published in (("paper_a_table2", "fr3/walking_xyz", "1.4540 / 0.0590 / 0.6731"),
                                  ("paper_b_table1", "w_xyz", "0.7323 / 0.6673 / 0.2564"),
                                  ("paper_c_table1", "walking_xyz", "0.2954 / 0.2628 / 0.0135")):
        lines = (root / "local" / "tables" / f"{table}.md").read_text().splitlines()
        own = [l for l in lines if l.startswith(f"| {row} |")]
        assert len(own) == 1 and f"| {real} | 12 |" in own[0] and published in own[0], (table, own)
        assert own[0].split("|")[-3].strip() not in ("-", "")  # measured cells filled
        analogue = [l for l in lines if l.startswith(f"| synthetic analogue of {row} | synthetic/walking_xyz |")]
        assert len(analogue) == 1 and published not in analogue[0], (table, analogue)
        assert not [l for l in lines if l.startswith(f"| {TUM} |")], table  # not again below


def test_the_real_sequence_at_lower_frame_rates_has_a_table_of_its_own(local):
    """Every 2nd and 3rd frame of a real sequence: the main methods (and depthcluster without its
    pose selection), in real_frame_rate (and the timing table) only, beside the same on every frame."""
    root, _, _ = local
    tables = root / "local" / "tables"
    rows = [l.split(" | ") for l in (tables / "real_frame_rate.md").read_text().splitlines()
            if l.startswith(f"| real/{TUM} |")]
    assert [r[1] for r in rows] == [r.label for r in E.FRAME_RATE_ROWS]
    assert {r.label for r in E.MAIN} < {r[1] for r in rows}
    assert all(r[2] == "12 / 6 / 4" and "-" not in r[3:6] for r in rows), rows
    summary = [l for l in (tables / "summary.md").read_text().splitlines() if l.startswith(f"| real/{TUM} |")]
    assert len(summary) == len({l.split(" | ")[2] for l in summary})  # one row per run, every frame
    assert all(" | 12 | " in l for l in summary)
    timing = (tables / "timing.md").read_text()
    assert f"| real/{TUM}/stride3 | bgrestore |" in timing and f"| real/{TUM} | bgrestore |" in timing


def test_reproduce_on_a_local_dask_cluster_gives_the_local_tables(local):
    root, _, args = local
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        # --fresh: every run goes to the cluster's workers, none is taken from the run cache
        out = _run(args + ["--fresh", "--scheduler", cluster.scheduler_address, "--reports", str(root / "dask")])
    runs = tiny_plan(real_frames=12)[0]
    assert f"{runs} to run on 2 worker(s) of the Dask cluster at {cluster.scheduler_address}" in out
    assert f"[run {runs}/{runs}]" in out and "[cached" not in out
    assert _tables(root / "dask") == _tables(root / "local")


def test_an_unreachable_scheduler_is_a_clear_error(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(batch, "SCHEDULER_TIMEOUT", "2s")
    rc = main(["reproduce", "--profile", "tiny", "--no-notebooks", "--cache", str(tmp_path / "cache"),
               "--reports", str(tmp_path / "reports"), "--scheduler", "tcp://127.0.0.1:9"])
    err = capsys.readouterr().err
    assert rc == 2 and "--scheduler tcp://127.0.0.1:9: no Dask scheduler answers" in err, err
    assert not (tmp_path / "reports").exists()


def test_the_papers_profile_finds_the_papers_sequences_and_names_the_missing(local):
    root, _, _ = local
    present, missing = batch.papers_data(root)
    assert present == [str(root / TUM)]
    assert len(missing) == len(batch.ARCHIVES) - 1
    assert f"rgbd_dataset_freiburg3_walking_rpy: python -m dynslam_lite download fr3_walking_rpy --dest {root}" in missing
    profiles, _ = batch.load_registry()
    assert profiles["papers"]["papers_data"] and profiles["papers"]["scenes"] == profiles["full"]["scenes"]
