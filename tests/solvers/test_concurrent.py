"""Two solvers at once (graph_calib.solvers.concurrent): what a sequential run gives, outputs, progress, errors."""

import os
import time

import numpy as np
import pytest

from graph_calib.calibrate import build_problem, solve_problem
from graph_calib.errors import InputError
from graph_calib.options import CalibrationOptions
from graph_calib.solvers import concurrent
from graph_calib.solvers.interface import ProgressEvent



@pytest.fixture(autouse=True)
def forking():
    """Each test here needs the worker: a platform that forks and a test process without other threads.

    Only a platform without fork skips; a thread an earlier test left running fails the test, naming it (the
    suite's conftest stops those a campaign leaves, ``no_threads_left_behind``)."""
    import multiprocessing

    from _shared import other_threads

    if "fork" not in multiprocessing.get_all_start_methods():
        pytest.skip("solve_pair runs sequentially on a platform without fork")
    assert other_threads() == [], f"threads left running by earlier tests: {other_threads()}"
    assert concurrent.fork_available()


@pytest.fixture(scope="module")
def problem():
    from _shared import make_experiment
    return build_problem(make_experiment(n=3000, seed=4), options=CalibrationOptions())


def test_real_solvers_give_the_sequential_outputs_and_events_bit_for_bit(problem):
    opts = CalibrationOptions()
    seq_events, par_events = [], []
    seq = solve_problem(problem, options=opts, progress=seq_events.append)
    par = solve_problem(problem, options=opts, progress=par_events.append, concurrent=True)
    assert list(par.outputs) == ["sqrt-kf", "factor-graph"]
    for name in par.outputs:
        a, b = seq.outputs[name], par.outputs[name]
        assert np.array_equal(a.x, b.x) and np.array_equal(a.covariance, b.covariance)
        assert np.array_equal(a.attitudes, b.attitudes)
        assert (a.iterations, a.converged, a.final_cost) == (b.iterations, b.converged, b.final_cost)
        for kind in a.residuals:
            assert np.array_equal(a.residuals[kind].values, b.residuals[kind].values)
    assert par_events == seq_events
    assert par.verdict == seq.verdict and par.comparison == seq.comparison


def _fake(fail=None, error=None):
    """A stand-in for registry.solve: three progress events per solver, then its name or ``error``."""
    def solve(name, problem, *, options, progress=None, initial=None):
        for i in range(3):
            progress(ProgressEvent(solver=name, iteration=i + 1, cost=float(10 - i)))
        if name == fail:
            raise error
        return f"output of {name}", os.getpid(), initial
    return solve


def test_every_event_of_the_first_solver_comes_before_any_of_the_second(monkeypatch):
    monkeypatch.setattr(concurrent, "solve", _fake())
    events = []
    outs = concurrent.solve_pair(("a", "b"), None, options=None, progress=events.append)
    assert [o[0] for o in outs] == ["output of a", "output of b"]
    assert outs[0][1] != os.getpid() and outs[1][1] == os.getpid()     # the first ran in the worker
    assert [(e.solver, e.iteration) for e in events] == [("a", 1), ("a", 2), ("a", 3), ("b", 1), ("b", 2), ("b", 3)]


def test_each_solver_gets_its_own_start_and_the_second_output_is_handed_on_while_the_first_runs(monkeypatch):
    fake = _fake()

    def solve(name, problem, *, options, progress=None, initial=None):
        if name == "a":
            time.sleep(0.5)           # the worker still runs when the second's output is handed on
        return (*fake(name, problem, options=options, progress=progress, initial=initial), time.monotonic())

    monkeypatch.setattr(concurrent, "solve", solve)
    seen = []
    outs = concurrent.solve_pair(("a", "b"), None, options=None, progress=lambda e: None, initial={"b": "warm"},
                                 on_output=lambda name, out: seen.append((name, out, time.monotonic())))
    assert [o[2] for o in outs] == [None, "warm"]                  # the first starts on its own
    assert [n for n, _, _ in seen] == ["b", "a"]
    assert seen[0][1] is outs[1] and seen[1][1] == outs[0]
    assert seen[0][2] < outs[0][3]                                   # handed on before the first had finished


def test_an_error_of_the_first_solver_is_raised_with_its_message_and_the_second_is_not_shown(monkeypatch):
    monkeypatch.setattr(concurrent, "solve", _fake("a", InputError("no static interval", dataset="/imu")))
    events = []
    with pytest.raises(InputError, match="/imu: no static interval") as info:
        concurrent.solve_pair(("a", "b"), None, options=None, progress=events.append)
    assert info.value.dataset == "/imu"
    assert [e.solver for e in events] == ["a"] * 3


def test_an_error_of_the_second_solver_is_raised_after_every_event_of_the_first(monkeypatch):
    monkeypatch.setattr(concurrent, "solve", _fake("b", RuntimeError("indeterminate system")))
    events = []
    with pytest.raises(RuntimeError, match="indeterminate system"):
        concurrent.solve_pair(("a", "b"), None, options=None, progress=events.append)
    assert [e.solver for e in events] == ["a"] * 3 + ["b"] * 3


def test_a_worker_that_dies_is_an_error_naming_the_solver(monkeypatch):
    def solve(name, problem, *, options, progress=None, initial=None):
        if name == "a":
            os._exit(7)
        return name
    monkeypatch.setattr(concurrent, "solve", solve)
    with pytest.raises(RuntimeError, match="a worker process ended without a result .exit code 7"):
        concurrent.solve_pair(("a", "b"), None, options=None)


class _Unpicklable(Exception):
    def __init__(self, message, *, code):
        super().__init__(message)
        self.code = code

    def __reduce__(self):
        return (_Unpicklable, (str(self),))     # loses the keyword: unpickling fails


def test_an_error_that_does_not_unpickle_comes_back_as_its_traceback(monkeypatch):
    monkeypatch.setattr(concurrent, "solve", _fake("a", _Unpicklable("odd failure", code=3)))
    with pytest.raises(RuntimeError, match="(?s)a failed in its worker process:.*odd failure"):
        concurrent.solve_pair(("a", "b"), None, options=None)


def test_run_both_runs_the_first_task_in_a_worker_and_gives_both_results():
    """The first task runs in another process (its pid is not this one's); both results come back in order."""
    a, b = concurrent.run_both(lambda: (os.getpid(), np.arange(3.0)), lambda: (os.getpid(), "here"))
    assert a[0] != os.getpid() and b == (os.getpid(), "here")
    np.testing.assert_array_equal(a[1], [0.0, 1.0, 2.0])


def test_run_both_raises_the_first_task_s_error_before_the_second_s():
    def bad_first():
        raise InputError("first task refused", dataset="x")

    def bad_second():
        raise ValueError("second task failed")

    with pytest.raises(InputError, match="first task refused"):
        concurrent.run_both(bad_first, bad_second)
    with pytest.raises(ValueError, match="second task failed"):
        concurrent.run_both(lambda: 1, bad_second)
