"""The batch reproduction: plan, run, score, write every report (``python -m dynslam_lite reproduce``).

1. plan: the profile's synthetic scenes (``notebooks/reproduce.yaml``) and the real sequences
   given, each with its runs from :mod:`dynslam_lite.experiments`;
2. run: scenes generated and runs tracked and scored in worker processes (:func:`worker_pool`,
   or a Dask distributed cluster with ``--scheduler``, :func:`dask_executor`), each estimated
   trajectory scored as written (:func:`evaluate_run`); a plan with the estimated time first,
   an ETA with every finished run (:class:`Estimate`);
3. report: tables, trajectories and ``runs.json``, the notebooks executed with papermill
   (notebook 90 scores the trajectories again and writes the tables), provenance and the index,
   all in a temporary folder first: ``reports/`` changes only when everything succeeded.
"""
from __future__ import annotations

import hashlib
import json
import multiprocessing as mp
import os
import shutil
import signal
import sys
import time
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor, as_completed
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path

from . import experiments, tables
from .errors import BatchError, ConfigError, Interrupted
from .download import ARCHIVES
from .evaluation import evaluate, exposure_pair_errors
from .experiments import Run, RunRecord
from .io import KeptSequence, atomic_write_text, format_trajectory, open_sequence, parse_trajectory
from .pipeline import run_method
from .reports import ReportWriter, code_fingerprint, fmt
from .synth import SCENES, ensure_scene

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOK_DIR = ROOT / "notebooks"
REGISTRY = NOTEBOOK_DIR / "reproduce.yaml"
DEFAULT_CACHE = Path("build") / "data"
SCHEDULER_TIMEOUT = "20s"  # how long to wait for a Dask scheduler to answer


@dataclass
class Options:
    """What to reproduce (the ``reproduce`` command's arguments)."""

    profile: str = "full"
    frames: int | None = None  # overrides the profile's frame count
    data: list[str] = field(default_factory=list)  # real TUM/Bonn sequence folders
    seed: int = 0
    jobs: int = 2
    cache: str = str(DEFAULT_CACHE)
    reports: str = "reports"
    notebooks: bool = True
    fresh: bool = False  # run everything again instead of taking finished runs from the run cache
    scheduler: str | None = None  # a Dask distributed scheduler address: runs and notebooks go there
    data_root: str | None = None  # where a profile with 'papers_data' looks (default: the profile's folder)


@dataclass(frozen=True)
class Job:
    """One run on one sequence: ``sequence`` is 'synthetic/<scene>' or 'real/<folder>', tracked
    every ``stride``-th frame."""

    sequence: str
    path: str
    run: Run
    stride: int = 1

    @property
    def kind(self) -> str:
        return self.sequence.split("/", 1)[0]

    @property
    def name(self) -> str:
        """The sequence with its stride (:func:`experiments.sequence_name`)."""
        return experiments.sequence_name(self.sequence, self.stride)


@dataclass
class Done:
    """A run that finished: its record, the trajectory text it was scored on, its time."""

    record: RunRecord
    trajectory: str
    seconds: float


@dataclass
class Failure:
    """A run that raised: reported in the summary instead of ending the batch."""

    job: Job
    error: str
    seconds: float


def load_registry(path: Path = REGISTRY) -> tuple[dict, dict]:
    """(profiles, notebooks) of the reproduction registry (``notebooks/reproduce.yaml``)."""
    import yaml

    try:
        reg = yaml.safe_load(path.read_text(encoding="utf-8"))
        profiles, notebooks = reg["profiles"], reg["notebooks"]
    except (OSError, yaml.YAMLError, KeyError, TypeError) as exc:
        raise ConfigError(f"{path}: not a readable reproduction registry ({exc})") from exc
    for prof in profiles.values():
        prof["scenes"] = tuple(SCENES) if prof["scenes"] == "all" else tuple(prof["scenes"] or ())
    for name, params in notebooks.items():
        if not (NOTEBOOK_DIR / f"{name}.ipynb").exists():
            raise ConfigError(f"{path}: notebook {name}.ipynb does not exist")
        if set(params) != set(profiles):
            raise ConfigError(f"{path}: notebook {name} needs parameters for every profile {sorted(profiles)}")
    return profiles, notebooks


def papers_data(root: Path) -> tuple[list[str], list[str]]:
    """The papers' sequences (those ``download`` knows) under ``root``: (folders present, one line
    per missing sequence with the command that downloads it)."""
    present, missing = [], []
    for name, arc in ARCHIVES.items():
        folder = root / arc.folder
        if (folder / "rgb.txt").is_file():
            present.append(str(folder))
        else:
            missing.append(f"{arc.folder}: python -m dynslam_lite download {name} --dest {root}")
    return present, missing


def plan(scene_paths: dict[str, str], data: list[str]) -> list[Job]:
    """Every job, synthetic scenes first, in registry order (the tables' row order); each real
    sequence every frame, then at the lower frame rates of the registry."""
    jobs = [Job(f"synthetic/{scene}", path, run)
            for scene, path in scene_paths.items() for run in experiments.runs_for("synthetic", scene)]
    jobs += [Job(f"real/{Path(d).resolve().name}", d, run, n) for d in data for n in experiments.strides()
             for run in experiments.runs_for("real", stride=n)]
    return jobs


# ------------------------------------------------------------------ workers
def _say(line: str) -> None:
    """One line of progress, written whole (worker and main-process lines never run together)."""
    sys.stdout.write(line + "\n")
    sys.stdout.flush()


def _worker_init(jobs: int) -> None:
    """Workers leave Ctrl-C to the main process, which stops them (:func:`stop_children`);
    OpenCV's own thread pool: one thread per worker when the workers share the cores."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if jobs > 1:
        import cv2

        cv2.setNumThreads(1)


def stop_children(grace_s: float = 3.0) -> None:
    """End every process this one started (workers, notebook kernels): SIGTERM, then SIGKILL
    for those still alive after ``grace_s`` seconds. multiprocessing's resource tracker is left
    alone: it ignores SIGTERM, ends by itself when this process exits, and killing it made the
    pool's exit print its warnings and KeyErrors."""
    import psutil

    def tracker(p) -> bool:
        try:
            return any("resource_tracker" in part for part in p.cmdline())
        except psutil.Error:
            return False

    children = [c for c in psutil.Process().children(recursive=True) if not tracker(c)]
    for c in children:
        try:
            c.terminate()
        except psutil.NoSuchProcess:
            pass
    _, alive = psutil.wait_procs(children, timeout=grace_s)
    for c in alive:
        try:
            c.kill()
        except psutil.NoSuchProcess:
            pass


@contextmanager
def one_blas_thread(jobs: int):
    """With more than one worker, every process started meanwhile (workers, notebook kernels)
    runs one BLAS and one OpenCV thread: OpenBLAS's spinning threads had doubled the batch on 2
    cores, and the notebooks (run two at a time after the pool) took 3-4x as long as the same
    runs in it."""
    saved = {v: os.environ.get(v) for v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS",
                                            "OPENCV_FOR_THREADS_NUM")}
    if jobs > 1:
        for var in saved:
            os.environ.setdefault(var, "1")
    try:
        yield
    finally:
        for var, value in saved.items():
            if value is None:
                os.environ.pop(var, None)
            else:
                os.environ[var] = value


@contextmanager
def worker_pool(jobs: int):
    """A process pool of ``jobs`` workers (one BLAS and OpenCV thread each when there are
    several, :func:`one_blas_thread`). Spawned, not forked: a forked child inherits OpenCV's
    thread pool in a broken state and hangs. Left by an exception (Ctrl-C), the workers are
    stopped at once instead of finishing the queue."""
    with one_blas_thread(jobs):
        pool = ProcessPoolExecutor(max_workers=jobs, mp_context=mp.get_context("spawn"),
                                   initializer=_worker_init, initargs=(jobs,))
        try:
            yield pool
        except BaseException:
            stop_children()
            pool.shutdown(wait=False, cancel_futures=True)
            raise
        else:
            pool.shutdown(wait=True)


@contextmanager
def dask_executor(address: str):
    """(executor, worker threads) on a Dask distributed cluster (``Client.get_executor``, a
    ``concurrent.futures`` executor):
    its workers import dynslam_lite and read the data and write the notebooks at the same paths,
    so the cluster shares this file system (a Slurm/PBS cluster through dask-jobqueue, or a
    ``LocalCluster``). Left by an exception (Ctrl-C), the futures are cancelled."""
    try:
        from distributed import Client
    except ImportError as exc:
        raise ConfigError(f"--scheduler needs dask distributed ({exc}); pip install -r environment.txt") from exc
    try:
        client = Client(address, timeout=SCHEDULER_TIMEOUT)
    except (OSError, TimeoutError) as exc:
        raise ConfigError(f"--scheduler {address}: no Dask scheduler answers ({exc})") from exc
    pool = client.get_executor(pure=False)
    try:
        yield pool, max(sum(client.nthreads().values()), 1)
    except BaseException:
        pool.shutdown(wait=False)
        raise
    else:
        pool.shutdown(wait=True)
    finally:
        client.close()


@contextmanager
def run_executor(opt: Options):
    """Where the runs go: (executor, runs it takes at once), the local worker pool or the Dask
    cluster at ``opt.scheduler`` (its worker threads)."""
    if opt.scheduler:
        with dask_executor(opt.scheduler) as (pool, workers):
            yield pool, workers
    else:
        with worker_pool(opt.jobs) as pool:
            yield pool, opt.jobs


@contextmanager
def notebook_executor(opt: Options):
    """Where the notebooks go: threads here (each starts its kernel process, one BLAS thread
    each), or the Dask cluster at ``opt.scheduler``."""
    if opt.scheduler:
        with dask_executor(opt.scheduler) as (pool, _):
            yield pool
        return
    with one_blas_thread(opt.jobs):
        threads = ThreadPoolExecutor(max_workers=opt.jobs)  # kernels are processes
        try:
            yield threads
        finally:  # on Ctrl-C: kernels stopped, threads not waited for
            threads.shutdown(wait=False, cancel_futures=True)


def generate_scene(job: tuple) -> str:
    """Generate (or find cached) one synthetic scene; runs in a worker process."""
    cache, scene, frames, seed = job
    return str(ensure_scene(cache, scene, frames, seed))


_KEPT: dict[str, KeptSequence] = {}  # the sequence this worker process tracked last


def _open_kept(path: str) -> KeptSequence:
    """The sequence at ``path`` with its frames kept in memory while this worker's jobs stay on
    it (the plan lists a sequence's runs one after another)."""
    if path not in _KEPT:
        _KEPT.clear()
        _KEPT[path] = KeptSequence(open_sequence(path))
    return _KEPT[path]


def evaluate_run(job: Job) -> Done | Failure:
    """Track and score one job (in a worker process): the record and the trajectory text, which
    is what gets scored (notebook 90 reads the same rounded poses). An exception is returned as
    a :class:`Failure`."""
    t = time.perf_counter()
    run = job.run
    try:
        seq = _open_kept(job.path)
        if job.stride > 1:
            seq = seq.window(0, None, job.stride)
        _say(f"[run] {job.name:32s} {run.label:42s} started ({len(seq)} frames)")
        masks = run.mask_source(job.kind)
        r = run_method(run.method, seq, run.overrides, masks=masks)
        text = format_trajectory(r.trajectory)
        estimate = parse_trajectory(text, "estimate")
        errors = evaluate(seq.groundtruth, estimate)
        extras = dict(r.extras)
        if seq.exposure is not None:  # a synthetic scene with automatic exposure
            extras.update(exposure_pair_errors(seq.groundtruth, estimate, seq.timestamps, seq.exposure[:, 0]))
    except Exception as exc:
        return Failure(job, f"{type(exc).__name__}: {exc}", time.perf_counter() - t)
    errors.aligned = None  # not needed past this point; keeps the record small
    record = RunRecord(
        job.sequence, run.label, run.method, masks, _relative(job.path), len(seq), errors,
        len(r.failed_frames), r.stats()["ms_per_frame"],
        {k: float(sum(v)) / len(seq) for k, v in r.stage_ms.items()}, extras, r.scores,
        r.scored_points, f"{job.name}/{file_name(run.label)}.txt", job.stride)
    return Done(record, text, time.perf_counter() - t)


def execute_notebook(job: tuple) -> tuple[str, float, str]:
    """Execute one notebook with papermill; returns (name, seconds, error or '')."""
    name, params, out_path = job
    import papermill as pm

    t = time.perf_counter()
    _say(f"[notebook] {name}: started")
    try:
        pm.execute_notebook(str(NOTEBOOK_DIR / f"{name}.ipynb"), str(out_path), parameters=params,
                            cwd=str(ROOT), progress_bar=False, kernel_name="python3")
        return name, time.perf_counter() - t, ""
    except Exception as exc:  # reported in the summary; the run fails without touching reports/
        last = str(exc).strip().splitlines()[-1] if str(exc).strip() else ""
        return name, time.perf_counter() - t, f"{type(exc).__name__}: {last}"


def _last_seconds(executed: Path) -> float:
    """How long the notebook took in the last reproduction (papermill's record in its executed
    copy; 0 when there is none): the batch starts the longest first, so that the kernels finish
    together."""
    try:
        return float(json.loads(executed.read_text(encoding="utf-8"))["metadata"]["papermill"]["duration"] or 0.0)
    except (OSError, ValueError, KeyError, TypeError):
        return 0.0


# ------------------------------------------------------------------ run cache
class RunCache:
    """Finished runs by key (:meth:`key`): the code that tracks and scores, the run's method,
    mask source and parameters, and the input data. A batch takes what is there and runs the
    rest; each run is stored as soon as it finishes, so an interrupted batch resumes."""

    # modules that only present results: editing them keeps the runs
    PRESENTATION = {"notebook.py", "tables.py", "published.py", "download.py", "cli.py"}

    def __init__(self, root: Path):
        self.root = Path(root)
        self.code = code_fingerprint(ROOT, exclude={f"dynslam_lite/{m}" for m in self.PRESENTATION},
                                     patterns=("dynslam_lite/**/*.py",))
        self._data: dict[str, str] = {}

    def data_id(self, path: str) -> str:
        """sha256 of a sequence folder's lists and of the names and sizes of its images."""
        if path not in self._data:
            root = Path(path)
            h = hashlib.sha256()
            for name in ("rgb.txt", "depth.txt", "groundtruth.txt", "scene.json", "instances.json", "camera.txt"):
                f = root / name
                h.update(name.encode() + b"\0" + (f.read_bytes() if f.is_file() else b"-") + b"\0")
            seq = open_sequence(root)
            for f in seq.rgb_files + seq.depth_files:
                h.update(f"{f.relative_to(root)} {f.stat().st_size}\n".encode())
            self._data[path] = h.hexdigest()
        return self._data[path]

    def key(self, job: Job) -> str:
        run = job.run
        spec = {"code": self.code, "data": self.data_id(job.path), "sequence": job.sequence, "label": run.label,
                "method": run.method, "masks": run.mask_source(job.kind), "params": [list(p) for p in run.params],
                "stride": job.stride}
        return hashlib.sha256(json.dumps(spec, sort_keys=True, default=str).encode()).hexdigest()[:32]

    def get(self, key: str) -> Done | None:
        f = self.root / f"{key}.json"
        if not f.is_file():
            return None
        try:
            d = json.loads(f.read_text(encoding="utf-8"))
            return Done(RunRecord.from_json(d["record"]), d["trajectory"], 0.0)
        except (ValueError, KeyError, TypeError):
            return None  # unreadable: run again

    def put(self, key: str, done: Done) -> None:
        atomic_write_text(self.root / f"{key}.json",
                          json.dumps({"record": done.record.to_json(), "trajectory": done.trajectory}) + "\n")


# ------------------------------------------------------------------ paths
def file_name(label: str) -> str:
    """A run label (brackets, colons, commas) as a plain file name."""
    return "".join(c if c.isalnum() or c in "._-" else "_" for c in label).strip("_")


def _relative(path) -> str:
    """A path relative to the repository root where possible (committed reports stay portable)."""
    return os.path.relpath(Path(path).resolve(), ROOT)


def _portable(executed: Path, replacements: dict[str, str]) -> None:
    """Replace machine paths (the temporary report folder, the cache) in an executed notebook by
    the paths relative to the repository root that the reader has."""
    text = executed.read_text(encoding="utf-8")
    for old, new in replacements.items():
        text = text.replace(old, new)
    executed.write_text(text, encoding="utf-8")


# ------------------------------------------------------------------ the batch
def reproduce(opt: Options) -> int:
    """Run the batch; returns 0, or raises BatchError (with reports/ left as it was) when a run
    or a notebook failed, Interrupted on Ctrl-C / SIGTERM (workers and kernels stopped, reports/
    left as it was)."""
    try:
        return _reproduce(opt)
    except KeyboardInterrupt:
        raise Interrupted(f"reproduce stopped, its workers and notebook kernels ended; {opt.reports}/ "
                          "left as it was") from None


def _reproduce(opt: Options) -> int:
    profiles, notebooks = load_registry()
    if opt.profile not in profiles:
        raise ConfigError(f"unknown profile {opt.profile!r}: {REGISTRY} has {', '.join(profiles)}")
    prof = profiles[opt.profile]
    frames = opt.frames or prof["frames"]
    cache = Path(opt.cache)
    t0 = time.perf_counter()
    fingerprint = code_fingerprint(ROOT)
    if prof.get("papers_data"):  # every paper sequence found, whole; the missing ones named
        root = Path(opt.data_root or prof["papers_data"])
        found, missing = papers_data(root)
        _say(f"[papers] {len(found)} of the papers' {len(ARCHIVES)} sequences under {root}"
             + "".join(f"\n[papers] missing {m}" for m in missing))
        opt = replace(opt, data=list(dict.fromkeys([*opt.data, *found])))  # the caller's stays as it was
    lengths = {}
    for d in opt.data:
        lengths[d] = len(open_sequence(d))  # validate real data before any long work, with a clear error
        _say(f"[data] {d}: {lengths[d]} frames")
    with run_executor(opt) as (pool, workers):
        scenes = list(prof["scenes"])
        paths = dict(zip(scenes, pool.map(generate_scene, [(str(cache), s, frames, opt.seed) for s in scenes])))
        for scene, path in paths.items():
            lengths[path] = frames
            _say(f"[data] synthetic {scene}: {frames} frames at {path}")
        jobs = plan(paths, opt.data)
        t_runs = time.perf_counter()
        runs = RunCache(cache.parent / "runs")
        keys = [runs.key(job) for job in jobs]
        outcomes: list[Done | Failure | None] = [None if opt.fresh else runs.get(k) for k in keys]
        todo = [i for i, o in enumerate(outcomes) if o is None]
        _say(f"[runs] {len(jobs)} runs: {len(jobs) - len(todo)} finished earlier (run cache {runs.root}; "
             f"--fresh runs them again), {len(todo)} to run on {workers} worker(s)"
             + (f" of the Dask cluster at {opt.scheduler}" if opt.scheduler else ""))
        for k, (job, o) in enumerate(((j, o) for j, o in zip(jobs, outcomes) if o is not None), 1):
            _say(f"[cached {k}] {job.name:32s} {job.run.label:42s} ATE {o.record.errors.ate.rmse:.4f} m")
        eta = Estimate(Path(opt.reports) / "trajectories" / "runs.json", [jobs[i] for i in todo], lengths, workers)
        _say(eta.plan())
        futures = {pool.submit(evaluate_run, jobs[todo[k]]): todo[k] for k in eta.order([jobs[i] for i in todo])}
        for k, fut in enumerate(as_completed(futures), 1):
            outcome = fut.result()
            outcomes[futures[fut]] = outcome
            if isinstance(outcome, Done):
                runs.put(keys[futures[fut]], outcome)  # at once: an interrupted batch resumes here
            _progress(k, len(todo), outcome, eta.done(jobs[futures[fut]]))
    failed = [o for o in outcomes if isinstance(o, Failure)]
    done = [o for o in outcomes if isinstance(o, Done)]
    records = [d.record for d in done]
    t_nb = time.perf_counter()
    writer = ReportWriter(opt.reports)
    nb_times, failed_nbs = {}, []
    command = _command(opt)
    source = (f"Run: `python -m dynslam_lite reproduce --profile {opt.profile}` (synthetic seed "
              f"{opt.seed}, {frames} frames" + "".join(f", --data {Path(d).name}" for d in opt.data) + ").")
    try:
        tables.write_all(records, writer.tmp, source)
        for d in done:
            writer.write_text(f"trajectories/{d.record.trajectory}", d.trajectory)
        writer.write_text("trajectories/runs.json", experiments.runs_json(records))
        writer.adopt_all()
        (writer.tmp / "executed").mkdir(exist_ok=True)
        out = str(writer.tmp.resolve())
        nb_jobs = [(name, {**params[opt.profile], "output_dir": out,
                           **({"runs_dir": str(writer.tmp.resolve() / "trajectories"), "source": source}
                              if name.startswith("90_") else {"cache_dir": str(cache.resolve())})},
                    writer.tmp / "executed" / f"{name}.ipynb")
                   for name, params in notebooks.items() if opt.notebooks]
        portable = {out: _relative(opt.reports), str(cache.resolve()): _relative(cache), f"{ROOT}{os.sep}": "",
                    str(writer.tmp): _relative(opt.reports)}  # papermill's metadata: the relative form
        nb_jobs.sort(key=lambda job: -_last_seconds(Path(opt.reports) / "executed" / f"{job[0]}.ipynb"))
        with notebook_executor(opt) as nb_pool:
            for (name, secs, err), (_, _, path) in zip(nb_pool.map(execute_notebook, nb_jobs), nb_jobs):
                _say(f"[notebook] {name}: {'FAILED ' + err if err else 'ok'} ({secs:.0f} s)")
                nb_times[name] = secs
                if err:
                    failed_nbs.append((name, err))
                elif path.exists():
                    _portable(path, portable)
        if code_fingerprint(ROOT) != fingerprint:  # the workers and notebook kernels import the working tree
            raise BatchError(f"the code changed while the batch ran (code fingerprint {fingerprint[:12]} at "
                             f"the start): its runs and notebooks are not of one version; {opt.reports}/ "
                             "left as it was. Run it again on a tree that stays as it is")
        writer.write_text("provenance.json", _provenance(opt, prof, frames, command, fingerprint))
        writer.write_text("README.md", _index(opt, prof, frames, command))
        _summary(records, failed, nb_times, failed_nbs, t_nb - t_runs, time.perf_counter() - t0)
        if failed or failed_nbs:
            keep = cache.parent / "failed_notebooks"
            for name, _ in failed_nbs:
                src = writer.tmp / "executed" / f"{name}.ipynb"
                if src.exists():
                    keep.mkdir(parents=True, exist_ok=True)
                    shutil.copy(src, keep / src.name)
            raise BatchError(f"{len(failed)} run(s) and {len(failed_nbs)} notebook(s) failed; "
                               f"{opt.reports}/ left as it was"
                               + (f"; executed copies with the error in {keep}" if failed_nbs else ""))
        writer.adopt_all()
        written = writer.commit()
    except BaseException:
        writer.abort()
        raise
    _say(f"[done] wrote {len(written)} files under {opt.reports}/ (index: {opt.reports}/README.md)")
    return 0


class Estimate:
    """The plan's time estimate and the progress lines' ETA: each run's frames times its method's
    ms/frame in the last reproduction's ``runs.json`` (or :attr:`DEFAULT_MS`), over the workers;
    as runs finish, the estimate is scaled by measured time / estimated time so far."""

    DEFAULT_MS = 300.0  # ms/frame of a method never measured here

    def __init__(self, runs_json: Path, jobs: list[Job], lengths: dict[str, int], workers: int):
        measured: dict[str, list[float]] = {}
        try:
            for r in json.loads(runs_json.read_text(encoding="utf-8")):
                measured.setdefault(r["method"], []).append(float(r["ms_per_frame"]))
        except (OSError, ValueError, KeyError, TypeError):
            pass  # no earlier reproduction: the default rate
        self.ms = {m: sum(v) / len(v) for m, v in measured.items() if v}
        self.lengths = lengths
        self.runs, self.frames = len(jobs), sum(self._frames(job) for job in jobs)
        self.workers = max(workers, 1)
        self.left = sum(self._seconds(job) for job in jobs)
        self.estimated_done = 0.0
        self.t0 = time.perf_counter()

    def _frames(self, job: Job) -> int:
        """Frames the job tracks: every ``stride``-th of the sequence, the first included."""
        return -(-self.lengths.get(job.path, 0) // job.stride)

    def _seconds(self, job: Job) -> float:
        return self._frames(job) * self.ms.get(job.run.method, self.DEFAULT_MS) / 1000.0

    def order(self, jobs: list[Job]) -> list[int]:
        """Submission order, as positions in ``jobs``: the sequence with the most estimated work
        first, and within one the longest runs first. A sequence's runs stay together (a worker
        keeps the frames of the sequence it tracked last) and the short runs come last, where
        workers would otherwise wait for each other's long ones."""
        total: dict[str, float] = {}
        for job in jobs:
            total[job.path] = total.get(job.path, 0.0) + self._seconds(job)
        return sorted(range(len(jobs)), key=lambda i: (-total[jobs[i].path], jobs[i].path, -self._seconds(jobs[i])))

    def plan(self) -> str:
        return (f"[plan] {self.runs} runs, {self.frames} frames to track; about "
                f"{self.left / self.workers / 60:.0f} min on {self.workers} worker(s) (ms/frame per method "
                f"from the last reproduction's runs.json, {self.DEFAULT_MS:.0f} ms where none)")

    def done(self, job: Job) -> str:
        """' ETA ...' after ``job`` finished."""
        est = self._seconds(job)
        self.left -= est
        self.estimated_done += est
        elapsed = time.perf_counter() - self.t0
        scale = elapsed * self.workers / self.estimated_done if self.estimated_done > 0 else 1.0
        return f", ETA {max(self.left, 0.0) * scale / self.workers / 60:.1f} min"


def _progress(k: int, n: int, outcome, eta: str = "") -> None:
    if isinstance(outcome, Failure):
        _say(f"[run {k}/{n}] {outcome.job.name:32s} {outcome.job.run.label:42s} FAILED {outcome.error}{eta}")
        return
    rec = outcome.record
    _say(f"[run {k}/{n}] {rec.name:32s} {rec.label:42s} ATE {rec.errors.ate.rmse:.4f} m "
         f"RPE {fmt(rec.errors.rpe_trans.rmse)} m/s ({rec.frames} frames, {outcome.seconds:.0f} s{eta})")


def _command(opt: Options) -> str:
    return (f"python -m dynslam_lite reproduce --profile {opt.profile}"
            + (f" --frames {opt.frames}" if opt.frames else "") + (f" --seed {opt.seed}" if opt.seed else "")
            + "".join(f" --data {_relative(d)}" for d in opt.data))


def _provenance(opt: Options, prof: dict, frames: int, command: str, fingerprint: str) -> str:
    return json.dumps({
        "command": command, "profile": opt.profile, "frames": frames, "seed": opt.seed,
        "scenes": list(prof["scenes"]), "data": [_relative(d) for d in opt.data],
        "notebooks": opt.notebooks, "code_sha256": fingerprint}, indent=1) + "\n"


def _index(opt: Options, prof: dict, frames: int, command: str) -> str:
    """``reports/README.md`` from its template, with what wrote the folder."""
    template = Path(__file__).with_name("reports_README.md").read_text(encoding="utf-8")
    return template.replace(
        "{{provenance}}",
        f"This folder was written by `{command}` ({opt.profile} profile: {len(prof['scenes'])} synthetic "
        f"scenes x {frames} frames, seed {opt.seed}"
        + (", plus the real clips " + ", ".join(f"`{Path(d).name}`" for d in opt.data) if opt.data else "")
        + "; which methods run where is set in `dynslam_lite/experiments.py`).")


def _summary(records, failed, nb_times, failed_nbs, run_secs, total_secs) -> None:
    """What ran, how long, what failed: printed at the end of the batch."""
    seqs = sorted({r.sequence for r in records})
    print("\n[summary]")
    print(f"  runs:      {len(records)} ok, {len(failed)} failed, on {len(seqs)} sequences, "
          f"{run_secs / 60:.1f} min")
    for f in failed:
        print(f"    FAILED {f.job.name} {f.job.run.label}: {f.error}")
    for r in records:
        if r.failed_frames:
            print(f"    tracking failed on {r.failed_frames} frame(s): {r.name} {r.label}")
    print(f"  notebooks: {len(nb_times) - len(failed_nbs)} ok, {len(failed_nbs)} failed"
          + "".join(f"; {n} {t:.0f} s" for n, t in nb_times.items()))
    for name, err in failed_nbs:
        print(f"    FAILED {name}: {err}")
    print(f"  total:     {total_secs / 60:.1f} min", flush=True)
