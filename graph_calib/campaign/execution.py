"""Running a campaign's tasks: one job per experiment, in this process or on Dask, with a progress display.

- :func:`run_tasks`: one job, what a worker runs: the experiment read and its problem set up once, then
  each task's solver, each task's files written as soon as its solver finishes (:func:`experiment_summary`
  is its ``summary.json``);
- :func:`execute`: every job, one after the other in this process (``workers=0``), on a local Dask
  cluster of processes with one thread each, or on an existing cluster given by its scheduler address;
  a tqdm bar and a line per finished task on stderr.  Before any job it warms the numba kernels in this
  process (:func:`graph_calib.campaign.warmup.warm_kernels`): compiled once per machine into numba's on-disk cache,
  which the workers then load instead of each compiling them inside its first job.  Numba compile time
  that still happens inside a job is measured and kept out of the job's seconds.

``distributed`` is imported inside the function that starts or joins a cluster: importing it takes
seconds and a campaign run in this process (``workers=0``) never needs it.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path

import numba
import numpy as np
from tqdm import tqdm

from graph_calib import io
from graph_calib.campaign.loop import declared_path, loop_record, wave_record
from graph_calib.diagnosis import diagnose, diagnose_from
from graph_calib.errors import InputError
from graph_calib.records.problem import build_problem
from graph_calib.solvers.orchestration import run_solvers
from graph_calib.solvers.registry import PRIMARY_SOLVER
from graph_calib.stitching import SENSORS
from graph_calib.campaign.warmup import CompileClock, cache_present, warm_kernels


# ---------------------------------------------------------------------------
# one task (runs on a worker)
# ---------------------------------------------------------------------------

#: The primary solver's keyframe attitudes of an experiment's chosen solution (with the loop), beside its results:
#: where a pooled wave's primary solve starts (docs/campaign.md).
ATTITUDES_FILE = f"{PRIMARY_SOLVER}.attitudes.npy"


def _write_attitudes(folder, graph):
    """``graph``'s keyframe attitudes (K+1, 3, 3) into ``folder``/:data:`ATTITUDES_FILE`, atomically."""
    with io.atomic_path(Path(folder) / ATTITUDES_FILE) as tmp, open(tmp, "wb") as fh:
        np.save(fh, np.asarray(graph.attitudes, dtype=float))


def _read_attitudes(folder):
    """The attitudes :func:`_write_attitudes` kept in ``folder``, or None."""
    p = Path(folder) / ATTITUDES_FILE
    try:
        return np.load(p) if p.is_file() else None
    except (OSError, ValueError):
        return None


def experiment_summary(experiment, *, t_ref_degC, points=1500):
    """``summary.json`` of an experiment: length, temperatures (ranges per sensor and a thinned series)."""
    T = experiment.sensor_temperatures()
    step = max(1, experiment.n_samples // points)
    tbl = experiment.table
    return {
        "file": Path(experiment.source).name if experiment.source else "",
        "imu_id": experiment.imu_id, "n_samples": experiment.n_samples, "rate_hz": experiment.rate_hz,
        "duration_s": float(experiment.t[-1] - experiment.t[0] + 1.0 / experiment.rate_hz),
        "t_ref_degC": float(t_ref_degC),
        "sensors": list(SENSORS),
        "sensor_temperature_range_degC": np.stack([T.min(axis=0), T.max(axis=0)], axis=1).tolist(),
        "temperature_range_degC": [float(T.min()), float(T.max())],
        "table_readings": 0 if tbl is None else int(tbl.t.size),
        "valid_table_readings": 0 if tbl is None else int(np.count_nonzero(tbl.valid)),
        "series": {"t_s": experiment.t[::step], "sensor_temperature_degC": T[::step]},
    }


def run_tasks(tasks):
    """Calibrate one experiment with each task's solver (one problem built for all) and write their files.

    Parameters
    ----------
    tasks : sequence of Task
        Tasks of the same experiment (same file and options).

    Returns
    -------
    list of dict
        Per task ``name``, ``solver``, ``status`` (``"computed"`` or ``"failed"`` with ``error``; an
        ``input_error`` when the experiment file breaks a rule), ``seconds`` (its share of the set-up
        plus its solve, numba compiling left out) and ``compile_seconds`` (numba compiling during its
        share of the set-up and its solve: 0 when the warm-up compiled every kernel this job needs).
    """
    tasks = list(tasks)
    if not tasks:
        return []
    first = tasks[0]
    if first.numba_threads:
        try:
            numba.set_num_threads(max(1, min(first.numba_threads, numba.config.NUMBA_NUM_THREADS)))
        except Exception:  # pragma: no cover - numba threading is an optimisation only
            pass
    if first.wave:
        return _run_wave_tasks(tasks)
    if first.diagnosis is not None:
        return _run_tasks_with_loop(tasks)
    t0 = time.perf_counter()
    try:
        with CompileClock() as build_clock:
            Path(first.out_dir).mkdir(parents=True, exist_ok=True)
            exp = io.read_experiment(first.file)
            problem = build_problem(exp, options=first.options)
            io.atomic_write_json(first.summary_path,
                                 experiment_summary(exp, t_ref_degC=problem.model.t_ref_degC))
    except (KeyboardInterrupt, SystemExit):
        raise
    except Exception as exc:  # noqa: BLE001 - reported per task
        return [_failure(t, exc) for t in tasks]
    build_seconds = time.perf_counter() - t0 - build_clock.seconds
    by_solver = {t.solver: t for t in tasks}
    outcomes = {}
    with CompileClock() as clock:
        mark = [0.0, 0.0]         # when the running solver started, and the compiling until then

        def start(name):
            mark[:] = [time.perf_counter(), clock.seconds]

        def write(name, output, result):
            """A task's files as soon as its solver finished (its seconds: its share of the set-up plus its solve)."""
            task = by_solver[name]
            solve_seconds = time.perf_counter() - mark[0] - (clock.seconds - mark[1])
            compile_seconds = build_clock.seconds / len(tasks) + clock.seconds - mark[1]
            seconds = build_seconds / len(tasks) + solve_seconds
            io.write_residuals(task.residuals_path, output.residual_arrays(), solver=task.solver,
                               source=Path(task.file).name, kind=output.residual_quantity)
            extra = dict(result.extra)
            extra["campaign"] = {"key": task.key, "input_sha256": task.input_sha256,
                                 "options_sha256": task.options_sha256, "experiment": task.name,
                                 "seconds": seconds, "setup_seconds": build_seconds, "solve_seconds": solve_seconds,
                                 "compile_seconds": compile_seconds}
            io.write_result(replace(result, extra=extra), task.result_path)
            outcomes[name] = {"name": task.name, "solver": task.solver, "status": "computed", "seconds": seconds,
                              "compile_seconds": compile_seconds}

        # the tasks' result files hold no verdict: the campaign judges the experiment's results together
        # (graph_calib.campaign.run), also those read back from the cache
        run = run_solvers(problem, options=first.options, solvers=[t.solver for t in tasks], on_start=start,
                          on_solved=write, keep_going=True, stamp=False)
    for name, exc in run.errors.items():
        outcomes[name] = _failure(by_solver[name], exc)
    return [outcomes[t.solver] for t in tasks]


def _run_tasks_with_loop(tasks):
    """:func:`run_tasks` with the closed loop: diagnose, then each task's solver on the chosen model.

    :func:`graph_calib.diagnosis.diagnose` solves the declared model (the factor graph, and the filter
    when it is one of the experiment's solvers), tests every further effect, adds what the data ask for
    and solves the chosen model with both.  Files, in this order (each atomic): ``summary.json``,
    ``diagnosis.json`` (the loop's full record), ``declared/<solver>.json`` (the declared model's
    results, only when something was added), and per task its residual series and ``<solver>.json``
    of the chosen model, last, its ``campaign.loop`` holding :func:`graph_calib.campaign.loop.loop_record`.
    """
    def loop(first, exp):
        diag = diagnose(exp, options=first.options, diagnosis=first.diagnosis)
        return diag, loop_record(diag)

    return _loop_job(tasks, loop)


def _run_wave_tasks(tasks):
    """One experiment solved again after the campaign's pooled test adopted an effect in it (a wave's job).

    :func:`graph_calib.diagnosis.diagnose_from` solves the grown model (the tasks' options: the model the
    previous wave chose plus the adopted effect), warm-started from the previous wave's results (the factor
    graph's and the filter's own, read from ``start_dir``), and runs the loop's rounds on it, which may add
    further effects up to the loop's limit.  Files, into the wave's folder (``<experiment>/pooled/<k>/``),
    each atomic: ``summary.json``, ``diagnosis.json`` (the wave's rounds), and per task its residual series and
    ``<solver>.json``, last, its ``campaign.loop`` the previous record carried on
    (:func:`graph_calib.campaign.loop.wave_record`).
    """
    def wave(first, exp):
        start = Path(first.start_dir)
        previous = {t.solver: io.read_result(start / f"{t.solver}.json") for t in tasks}
        record = next(r.extra["campaign"]["loop"] for r in previous.values())
        primary = first.diagnosis.solvers[0]
        primary_start = previous.get(primary) or next(iter(previous.values()))
        left = max(0, first.diagnosis.max_added - len(record["added"]))
        diag = diagnose_from(exp, options=first.options, diagnosis=first.diagnosis, start=primary_start.values,
                             attitudes=_read_attitudes(start) if primary in previous else None,
                             starts={s: r.values for s, r in previous.items() if s != primary}, max_added=left)
        return diag, wave_record(record, diag, wave=first.wave, effects=first.added_by_wave)

    return _loop_job(tasks, wave, wave=tasks[0].wave, pooled_effects=tasks[0].added_by_wave)


def _loop_job(tasks, run, *, wave=None, pooled_effects=()):
    """One experiment's loop job: read it, ``run(first_task, experiment) -> (diagnosis, loop record)``, write
    its diagnosis (:func:`_write_diagnosis`) and its tasks' files (:func:`_write_chosen`); every task failed
    with the error when reading or the loop fails."""
    first = tasks[0]
    t0 = time.perf_counter()
    try:
        with CompileClock() as clock:
            Path(first.out_dir).mkdir(parents=True, exist_ok=True)
            exp = io.read_experiment(first.file)
            diag, record = run(first, exp)
            _write_diagnosis(first, exp, diag)
    except (KeyboardInterrupt, SystemExit):
        raise
    except Exception as exc:  # noqa: BLE001 - reported per task
        return [_failure(t, exc) for t in tasks]
    return _write_chosen(tasks, diag, record, seconds=(time.perf_counter() - t0 - clock.seconds) / len(tasks),
                         compile_seconds=clock.seconds / len(tasks), wave=wave, pooled_effects=pooled_effects)


def _write_diagnosis(first, exp, diag):
    """An experiment's ``summary.json``, ``diagnosis.json`` and the chosen graph's keyframe attitudes."""
    io.atomic_write_json(first.summary_path, experiment_summary(exp, t_ref_degC=diag.before.problem.model.t_ref_degC))
    js = diag.to_json()
    js["source"] = Path(first.file).name
    io.atomic_write_json(Path(first.out_dir) / "diagnosis.json", js)
    _write_attitudes(first.out_dir, diag.after.solution)


def _write_chosen(tasks, diag, record, *, seconds, compile_seconds, wave=None, pooled_effects=()):
    """Each task's residual series and result file of the model ``diag`` chose (the declared model's results
    beside them when the loop added something, first wave only); the tasks' outcomes.  ``wave``: the pooled
    wave the job belongs to (None: the first wave), ``pooled_effects`` the effects it adopted (first among the
    outcome's ``added``, before the loop's own)."""
    outcomes = []
    for task in tasks:
        try:
            output = diag.after.outputs.get(task.solver)
            result = diag.after.results.get(task.solver)
            if output is None or result is None:
                raise RuntimeError(f"the {'loop' if wave is None else 'pooled wave'} ran no {task.solver} on the "
                                   f"{'chosen' if wave is None else 'grown'} model")
            if wave is None and diag.added:
                declared = declared_path(task)
                declared.parent.mkdir(parents=True, exist_ok=True)
                io.write_result(diag.before.results[task.solver], declared)
            io.write_residuals(task.residuals_path, output.residual_arrays(), solver=task.solver,
                               source=Path(task.file).name, kind=output.residual_quantity)
            extra = dict(result.extra)
            extra["campaign"] = {"key": task.key, "input_sha256": task.input_sha256,
                                 "options_sha256": task.options_sha256, "experiment": task.name,
                                 **({} if wave is None else {"wave": wave}),
                                 "seconds": seconds, "compile_seconds": compile_seconds, "loop": record}
            io.write_result(replace(result, extra=extra), task.result_path)
            outcomes.append({"name": task.name, "solver": task.solver, "status": "computed", "seconds": seconds,
                             "compile_seconds": compile_seconds,
                             "added": list(pooled_effects) + list(diag.added)})
        except (KeyboardInterrupt, SystemExit):
            raise
        except Exception as exc:  # noqa: BLE001
            outcomes.append(_failure(task, exc))
    return outcomes


# ---------------------------------------------------------------------------
# running the tasks
# ---------------------------------------------------------------------------


class _Bar(tqdm):
    """tqdm without its monitor thread, which would outlive the campaign: a process with a thread left running
    cannot fork (``calibrate`` after a campaign in one Python session would solve one solver after the other,
    graph_calib.solvers.concurrent.fork_available)."""

    monitor_interval = 0


def _progress_bar(total, enabled):
    """A tqdm bar on a terminal only: in a CI log or a file its redraws break the lines (the task lines stay)."""
    if not enabled or total == 0 or not sys.stderr.isatty():
        return None
    return _Bar(total=total, desc="calibrating", unit="task", file=sys.stderr, dynamic_ncols=True)


def _say(bar, text, enabled):
    if not enabled:
        return
    if bar is not None:
        bar.write(text, file=sys.stderr)
    else:
        print(text, file=sys.stderr)


def _one_line(exc):
    text = f"{type(exc).__name__}: {exc}".strip().splitlines()
    return text[0] if text else type(exc).__name__


def _failure(task, exc):
    out = {"name": task.name, "solver": task.solver, "status": "failed", "error": _one_line(exc)}
    if isinstance(exc, InputError):
        out["input_error"] = str(exc)
    return out


def _groups(tasks):
    """Tasks grouped by experiment (one problem set-up serves every solver of an experiment), in order."""
    groups = {}
    for t in tasks:
        groups.setdefault((t.name, t.file, t.out_dir), []).append(t)
    return list(groups.values())


def warm_up(*, progress):
    """Warm the numba kernels in this process (:func:`graph_calib.campaign.warmup.warm_kernels`); its ``WarmUp``.

    With ``progress`` one line on stderr before (when the cache is missing: the compile takes minutes)
    and one after.  The warm-up only saves time: when it fails, one line says so and the run goes on (each
    worker then compiles what it needs, its compile time still kept apart); None is returned.
    """
    cold = not cache_present()
    if progress and cold:
        print("compiling the numba kernels once for this machine (a few minutes on a fresh clone; later runs "
              "and every Dask worker load them from the cache) ...", file=sys.stderr, flush=True)
    try:
        w = warm_kernels()
    except (KeyboardInterrupt, SystemExit):
        raise
    except Exception as exc:  # noqa: BLE001 - an optimisation only
        print(f"warning: warming the numba kernels failed ({_one_line(exc)}); each worker compiles them",
              file=sys.stderr, flush=True)
        return None
    if progress and (cold or w.compile_seconds > 1.0):
        print(f"numba kernels ready in {w.seconds:.0f} s ({w.compile_seconds:.0f} s compiling, {w.compiled} "
              f"signature(s))", file=sys.stderr, flush=True)
    return w


class Pool:
    """A campaign's Dask client, started on first use and kept for its later waves of jobs; :meth:`close` ends it.

    With ``options.scheduler`` the client of that cluster (:meth:`connect`); else a local cluster of processes
    with one thread each (:meth:`local`), as many as ``options.workers`` or CPU cores, at most one per job of
    the first wave that needs it.  The pooled score test's waves (:mod:`graph_calib.campaign.waves`) run on the
    same workers, which then load nothing again.
    """

    def __init__(self, options):
        self.options = options
        self.client = None
        self._cluster = None

    def connect(self):
        """The client of ``options.scheduler`` (InputError when it cannot be reached)."""
        if self.client is None:
            self.client = _connect(self.options.scheduler)
        return self.client

    def local(self, n_jobs, bar=None):
        """The client of the local cluster, started here for ``n_jobs`` jobs on first use."""
        if self.client is None:
            import dask                                   # seconds to import: only here (module docstring)
            from distributed import Client, LocalCluster

            n = self.options.workers if self.options.workers else min(os.cpu_count() or 1, n_jobs)
            n = max(1, min(n, n_jobs))
            _say(bar, f"starting a local Dask cluster: {n} worker process(es), 1 thread each", self.options.progress)
            # the workers keep glibc's own allocator policy: Dask's nanny would set MALLOC_TRIM_THRESHOLD_=65536,
            # which fixes glibc's mmap threshold at 128 KiB, so that every large temporary of a job is mapped,
            # faulted in and unmapped again (a 3 h loop job 1.38 times as long, a third of its CPU in the kernel:
            # docs/performance.md, "One 3 h job of the first wave"); a value set in the environment is passed on
            with dask.config.set({"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}), \
                    _children_ignore_interrupt():
                self._cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                             dashboard_address=":0", silence_logs=logging.ERROR)
            self.client = Client(self._cluster)
        return self.client

    def close(self):
        """Close the client and the local cluster, if any."""
        try:
            if self.client is not None:
                self.client.close()
        finally:
            if self._cluster is not None:
                self._cluster.close()
            self.client = self._cluster = None


@contextlib.contextmanager
def _children_ignore_interrupt():
    """Processes started inside ignore Ctrl-C (SIGINT), which the terminal sends to the whole process group: this
    process takes it, stops the run and closes the cluster; the Dask nannies and workers, each printing the traceback
    of its own KeyboardInterrupt, said nothing a user needs (an ignored signal stays ignored across exec, and Python
    then installs no handler of its own)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def execute(tasks, *, options, on_done=None, timing=None, pool=None):
    """Run ``tasks`` (Dask or in-process), one job per experiment; ``{(name, solver): outcome dict}``.

    First the numba kernels are warmed in this process (:func:`warm_up`; with ``options.scheduler`` after
    connecting to it, so that a wrong address fails at once).  ``on_done(outcome)`` is called
    in the main process as each task's outcome arrives (its exception, e.g. ``KeyboardInterrupt``, stops
    the run; finished tasks stay on disk).  ``timing``, a dict, receives ``warmup_seconds`` (the
    warm-up's wall time), ``compile_seconds`` (numba compiling during the warm-up) and
    ``compiled_signatures``; the tasks' own seconds leave numba compiling out (:func:`run_tasks`).
    ``pool``: a :class:`Pool` kept by the caller for later waves (left open); by default one of its own,
    closed at the end.
    """
    outcomes = {}
    if timing is None:
        timing = {}
    timing.update({"warmup_seconds": 0.0, "compile_seconds": 0.0, "compiled_signatures": 0})
    if not tasks:
        return outcomes
    own = pool is None
    pool = Pool(options) if own else pool
    try:
        if options.scheduler:
            pool.connect()
        t_warm = time.perf_counter()
        w = warm_up(progress=options.progress)
        timing.update({"warmup_seconds": time.perf_counter() - t_warm,
                       "compile_seconds": 0.0 if w is None else w.compile_seconds,
                       "compiled_signatures": 0 if w is None else w.compiled})
    except BaseException:
        if own:
            pool.close()
        raise
    bar = _progress_bar(len(tasks), options.progress)

    def finish(task, outcome):
        outcomes[(task.name, task.solver)] = outcome
        if bar is not None:
            bar.update(1)
        if outcome["status"] == "failed":
            _say(bar, f"  {task.name} {task.solver}: FAILED: {outcome['error']}", options.progress)
        else:
            cs = outcome.get("compile_seconds", 0.0)
            note = f" (and {cs:.0f} s compiling numba kernels)" if cs >= 0.5 else ""
            if "added" in outcome:
                note += f"; loop added {', '.join(outcome['added']) or 'nothing'}"
            _say(bar, f"  {task.name} {task.solver}: done in {outcome['seconds']:.1f} s{note}", options.progress)
        if on_done is not None:
            on_done(outcome)

    try:
        if options.scheduler is None and options.workers == 0:
            for group in _groups(tasks):
                for t, outcome in zip(group, run_tasks(group)):
                    finish(t, outcome)
        else:
            _run_dask(tasks, finish=finish, bar=bar, pool=pool)
    finally:
        try:
            if bar is not None:
                bar.close()
        finally:
            if own:
                pool.close()
    return outcomes


def _connect(scheduler):
    """A Dask client of the cluster at ``scheduler``; InputError when it cannot be reached.

    The scheduler is reached once first in this thread's own event loop (``asyncio.run``), so that an address
    nobody answers at is refused before a client exists: a client whose construction fails leaves its IO-loop
    thread running, and a process with a thread left running cannot fork
    (graph_calib.solvers.concurrent.fork_available).
    """
    import asyncio

    from distributed import Client  # seconds to import: only here (module docstring)
    from distributed.comm import connect

    async def reach():
        comm = await connect(scheduler, timeout="10s")
        await comm.close()

    try:
        asyncio.get_running_loop()
        running = True          # called from inside an event loop (a notebook): the client alone
    except RuntimeError:
        running = False
    try:
        if not running:
            asyncio.run(reach())
        return Client(scheduler, timeout="10s")
    except (OSError, TimeoutError) as exc:
        raise InputError(f"cannot connect to the Dask scheduler: {exc}", dataset="--scheduler") from None
    except ValueError as exc:        # distributed's parsing of the address: 'missing port number in address ...'
        raise InputError(f"not a scheduler address (tcp://HOST:PORT): {exc}", dataset="--scheduler") from None


def _run_dask(tasks, *, finish, bar, pool):
    """The jobs on ``pool``'s client (an existing cluster's, or a local cluster started on first use)."""
    from distributed import as_completed  # seconds to import: only here (module docstring)

    groups = _groups(tasks)
    client = pool.client or pool.local(len(groups), bar)
    by_future = {}
    for g in groups:
        key = f"calibrate-{g[0].name}-{'+'.join(t.solver for t in g)}-{g[0].key[:12]}"
        by_future[client.submit(run_tasks, g, key=key, pure=False)] = g
    for fut in as_completed(list(by_future)):
        g = by_future[fut]
        try:
            outs = fut.result()
        except (KeyboardInterrupt, SystemExit):
            raise
        except Exception as exc:  # noqa: BLE001 - e.g. a worker that died
            outs = [_failure(t, exc) for t in g]
        for t, outcome in zip(g, outs):
            finish(t, outcome)


__all__ = ["experiment_summary", "run_tasks", "warm_up", "execute", "Pool"]
