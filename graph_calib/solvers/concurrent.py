"""Two solvers on one problem at the same time: the first in a forked worker process, the second here.

``graph-calib calibrate`` runs the filter and the factor graph on the same problem; they share nothing
while they run, so on a machine with a second free core the filter's time can hide behind the graph's
(docs/performance.md, "``calibrate`` on the Xsens session").  :func:`solve_pair` does that and keeps what a
run one after the other gives:

- the outputs are the ones :func:`graph_calib.solvers.registry.solve` returns in this process, bit for
  bit (the worker is a fork of this process after the problem was built: the same code and data);
- the progress events reach ``progress`` in the order of a sequential run: the first solver's as they
  come (a thread here reads them from the worker), the second's held back until the first has finished
  and then passed on as they come;
- an error of the first solver is raised here as it would have been raised before the second started
  (the second is stopped at its next progress event and its events are never shown); an error of the
  second is raised after the first has finished, as in a sequential run.

Each of the two runs with BLAS on one thread (``threadpoolctl``): they share the cores, and OpenBLAS's
threads, two per process on a 2-core machine, spin against each other (docs/performance.md).

Without ``fork`` (not on Linux), inside a daemonic worker process or with other threads running
(:func:`fork_available`), the two run one after the other.

:func:`run_both` does the same for any two tasks (the loop's held-out guard: the current model's and the grown
model's cross-validations at once).
"""

from __future__ import annotations

import multiprocessing
import pickle
import threading
import traceback

from threadpoolctl import threadpool_limits

from graph_calib.solvers.registry import solve


class _FirstSolverFailed(Exception):
    """Raised inside the second solver's progress callback to stop it once the first has failed."""


def _run_in_worker(conn, task, what):
    """Run ``task()`` in the forked worker (BLAS on one thread); send ``("done", result)`` or ``("error", exception
    or text)``: every error goes back to the parent, which raises it (as text, naming ``what``, when it does not
    pickle)."""
    try:
        with threadpool_limits(limits=1, user_api="blas"):
            result = task()
        conn.send(("done", result))
    except BaseException as exc:
        try:
            pickle.loads(pickle.dumps(exc))    # it must also unpickle there
            conn.send(("error", exc))
        except Exception:          # an exception that does not pickle: its text
            conn.send(("error", f"{what} failed in its worker process:\n" + "".join(traceback.format_exception(exc))))
    finally:
        conn.close()


def _worker(conn, name, problem, options, initial):
    """Run solver ``name`` in the forked worker; send ``("progress", event)``, then ``("done", output)``
    or ``("error", exception or text)``."""
    _run_in_worker(conn, lambda: solve(name, problem, options=options, progress=lambda e: conn.send(("progress", e)),
                                       initial=initial), name)


def fork_available():
    """Whether :func:`solve_pair` can run the first solver in a forked worker: the platform forks, this
    process is not itself a daemonic worker (a campaign's), which may not have children, and it runs no
    other Python thread (a fork copies only the forking thread: a lock another thread held at that moment,
    a Dask cluster's say, would stay locked in the worker for ever)."""
    return ("fork" in multiprocessing.get_all_start_methods() and not multiprocessing.current_process().daemon
            and threading.active_count() == 1)


def solve_pair(names, problem, *, options, progress=None, initial=None, on_output=None):
    """Solve ``problem`` with the two solvers ``names`` at once; their outputs in the order of ``names``.

    Parameters
    ----------
    names : sequence of two str
        Registered solver names; the first runs in a worker process.
    problem : graph_calib.records.problem.Problem
    options : graph_calib.options.CalibrationOptions
    progress : callable, optional
        Called (in this process) with each :class:`graph_calib.solvers.interface.ProgressEvent`, every
        event of the first solver before any of the second.
    initial : mapping of str to (R, x), optional
        A solver's starting keyframe attitudes and calibration (its ``initial``); the others start on their own.
    on_output : callable, optional
        ``on_output(name, output)`` as each solver's output is here: the second's while the first may still
        run in its worker (work on it then overlaps the first solver's); an exception it raises is raised
        after the first has finished.

    Returns
    -------
    list of graph_calib.solvers.interface.SolverOutput
    """
    first, second = names
    initial = dict(initial or {})
    if not fork_available():
        outs = []
        for n in names:
            outs.append(solve(n, problem, options=options, progress=progress, initial=initial.get(n)))
            if on_output is not None:
                on_output(n, outs[-1])
        return outs
    ctx = multiprocessing.get_context("fork")
    recv, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_worker, args=(send, first, problem, options, initial.get(first)),
                       daemon=True)
    lock = threading.Lock()
    state = {"finished": False, "output": None, "error": None, "held": []}

    def read():
        """The worker's messages: its progress passed on, its output or error kept."""
        result = None
        try:
            while result is None:
                kind, payload = recv.recv()
                if kind == "progress":
                    if progress is not None:
                        progress(payload)
                else:
                    result = (kind, payload)
        except EOFError:
            proc.join()
            result = ("error", f"the {first} worker process ended without a result (exit code {proc.exitcode})")
        except BaseException as exc:   # a failing progress callback: raised here as in a sequential run
            result = ("error", exc)
        with lock:
            if result[0] == "done":
                state["output"] = result[1]
                held, state["held"] = state["held"], []
                if progress is not None:
                    for event in held:
                        progress(event)
            else:
                state["error"] = result[1]
            state["finished"] = True

    def second_progress(event):
        with lock:
            if state["error"] is not None:
                raise _FirstSolverFailed()
            if not state["finished"]:
                state["held"].append(event)
                return
        if progress is not None:
            progress(event)

    proc.start()
    send.close()
    reader = threading.Thread(target=read, name=f"{first}-progress", daemon=True)
    reader.start()
    try:
        try:
            with threadpool_limits(limits=1, user_api="blas"):
                out_second = solve(second, problem, options=options, progress=second_progress,
                                   initial=initial.get(second))
                if on_output is not None:
                    on_output(second, out_second)
            error_second = None
        except _FirstSolverFailed:
            out_second, error_second = None, None
        except BaseException as exc:
            out_second, error_second = None, exc
        reader.join()
        if state["error"] is not None:
            err = state["error"]
            if isinstance(err, BaseException):
                raise err
            raise RuntimeError(err)
        if error_second is not None:
            raise error_second
        if on_output is not None:
            on_output(first, state["output"])
        return [state["output"], out_second]
    finally:
        if proc.is_alive():
            proc.terminate()
        proc.join()
        recv.close()


def run_both(first, second):
    """``(first(), second())``: ``first`` in a forked worker while ``second`` runs here, as :func:`solve_pair` runs
    two solvers (one after the other where :func:`fork_available` says no).

    Both take no argument and return a picklable value; the worker is a fork of this process, so ``first()`` gives
    there what it gives here.  An error of either is raised here, ``first``'s first.
    """
    if not fork_available():
        return first(), second()
    ctx = multiprocessing.get_context("fork")
    recv, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_run_in_worker, args=(send, first, "a task"), daemon=True)
    proc.start()
    send.close()
    try:
        try:
            with threadpool_limits(limits=1, user_api="blas"):
                out_second, error_second = second(), None
        except BaseException as exc:
            out_second, error_second = None, exc
        try:
            kind, payload = recv.recv()
        except EOFError:
            proc.join()
            kind, payload = "error", f"the worker process ended without a result (exit code {proc.exitcode})"
        if kind == "error":
            raise payload if isinstance(payload, BaseException) else RuntimeError(payload)
        if error_second is not None:
            raise error_second
        return payload, out_second
    finally:
        if proc.is_alive():
            proc.terminate()
        proc.join()
        recv.close()


__all__ = ["fork_available", "solve_pair", "run_both"]
