"""The closed loop forms each preintegration once, and runs BLAS on one thread.

:func:`graph_calib.diagnosis.diagnose` runs inside
:func:`graph_calib.model.calibration_model.reusing_preintegrations`; run once with it and once with it made a
no-op, on a short record whose loop adds an effect (both solvers, two stages), the two diagnoses must be the
same bit for bit, and the first must form fewer preintegrations.  Its rounds and solves run with BLAS on one
thread, as a campaign's Dask worker runs them.
"""

import contextlib

import numpy as np
import pytest
from threadpoolctl import threadpool_info

import graph_calib.diagnosis.loop as loop
import graph_calib.model.calibration_model as calibration_model
from graph_calib.diagnosis import DiagnosisOptions, diagnose
from graph_calib.simulation import simulate


def _counted(monkeypatch):
    """Count the preintegrations formed (the function :class:`CalibrationModel` calls)."""
    formed = []
    original = calibration_model.preintegrate

    def counting(*args, **kwargs):
        formed.append(1)
        return original(*args, **kwargs)

    monkeypatch.setattr(calibration_model, "preintegrate", counting)
    return formed


def _timeless(block):
    """A result's residual block without its wall times."""
    if isinstance(block, dict):
        return {k: _timeless(v) for k, v in block.items() if not k.startswith("seconds")}
    return block


def _figures(d):
    """Every number a diagnosis reports of its two stages and rounds."""
    out = {"added": tuple(d.added)}
    for label, stage in (("before", d.before), ("after", d.after)):
        for solver, res in stage.results.items():
            out[(label, solver, "values")] = tuple(res.values.values())
            out[(label, solver, "sigmas")] = tuple(res.sigmas.values())
            out[(label, solver, "residuals")] = repr(_timeless(res.residuals))
    for rnd in d.rounds:
        out[("round", rnd.index)] = tuple((c.name, c.statistic) for c in rnd.candidates)
    return out


def test_the_loop_forms_each_preintegration_once_with_the_same_results(monkeypatch):
    exp = simulate("effect-accel.bias_tc2", rng=np.random.default_rng(3), hours=0.1, rate_hz=50.0).run()[0].experiment
    dopts = DiagnosisOptions(solvers=("factor-graph", "sqrt-kf"), max_added=1, holdout=False)
    formed = _counted(monkeypatch)
    reused = diagnose(exp, diagnosis=dopts)
    n_reused = len(formed)
    formed.clear()
    monkeypatch.setattr(loop, "reusing_preintegrations", contextlib.nullcontext)
    fresh = diagnose(exp, diagnosis=dopts)
    assert fresh.added == reused.added == ["accel.bias_tc2"]
    assert _figures(reused) == _figures(fresh)
    assert n_reused < len(formed), (n_reused, len(formed))


class _Stop(Exception):
    pass


def _blas_threads():
    return [m["num_threads"] for m in threadpool_info() if m["user_api"] == "blas"]


def test_the_loop_runs_blas_on_one_thread(monkeypatch):
    outside = _blas_threads()
    if not outside or max(outside) == 1:
        pytest.skip("BLAS runs on one thread in this process anyway")
    exp = simulate("effect-accel.bias_tc2", rng=np.random.default_rng(3), hours=0.02, rate_hz=50.0).run()[0].experiment
    seen = []

    def loop_from(*args, **kwargs):
        seen.extend(_blas_threads())
        raise _Stop

    monkeypatch.setattr(loop, "_loop_from", loop_from)
    with pytest.raises(_Stop):
        diagnose(exp, diagnosis=DiagnosisOptions(solvers=("factor-graph",)))
    assert seen and set(seen) == {1}
    assert _blas_threads() == outside                  # restored after the loop
