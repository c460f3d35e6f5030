"""Records cut together (``/imu/segment``): refused without the marks, calibrated with them.

The simulator's ``consumer-handheld`` scenario with ``cut=True`` cuts every second hand turn out
of the session and leaves the time stamps continuous (no gap for the reader's rule to see), marking
each piece in ``/imu/segment``.  Without the marks the attitude jumps at each cut and the record
must be refused, naming the sample; with them both solvers must calibrate it from a zero
calibration, agree, and land within 3 sigma of the truth (docs/model.md, "Segments").
"""

from dataclasses import replace

import numpy as np
import pytest

from graph_calib.calibrate import CalibrationOptions, build_problem, solve_problem
from graph_calib.errors import InputError
from graph_calib.model import ModelOptions
from graph_calib.plausibility import JUMP_WINDOW_S, attitude_jumps, check_continuity
from graph_calib.simulation import simulate


@pytest.fixture(scope="module")
def cut_session():
    return simulate("consumer-handheld", rng=np.random.default_rng(7), cut=True).run()[0]


def _options(se):
    return CalibrationOptions(model=ModelOptions(grade="consumer"), t_ref_degC=se.truth.t_ref_degC)


def test_the_cut_scenario_marks_every_piece_with_continuous_time(cut_session):
    e = cut_session.experiment
    assert e.n_segments == 16                       # 30 turns, every second one (15) cut out
    assert np.allclose(np.diff(e.t), 1.0 / e.rate_hz)       # no time gap: only the attitude jumps
    assert cut_session.truth.extra["simulation"]["segments"] == e.n_segments


def test_a_cut_record_without_segments_is_refused_naming_the_sample(cut_session):
    e = replace(cut_session.experiment, segment=None, source="cut.h5")
    first_cut = cut_session.experiment.segment_bounds()[1][0]
    with pytest.raises(InputError, match=r"cut\.h5: /imu/dv \[sample (\d+)\]: the record is discontinuous") as err:
        build_problem(e, options=_options(cut_session))
    assert abs(err.value.index - first_cut) <= JUMP_WINDOW_S * e.rate_hz
    assert "/imu/segment" in str(err.value)
    # every cut is found, and only the cuts
    index, excess = attitude_jumps(e)
    cuts = np.array([a for a, _ in cut_session.experiment.segment_bounds()[1:]])
    assert index.size == cuts.size
    assert np.all(np.abs(index - cuts) <= JUMP_WINDOW_S * e.rate_hz)
    assert np.all(np.degrees(excess) > 30.0)          # the cut turns are at least 40 deg


def test_the_marks_allow_the_cuts_and_a_continuous_session_passes(cut_session):
    check_continuity(cut_session.experiment)                  # marked: accepted
    whole = simulate("consumer-handheld", rng=np.random.default_rng(7)).run()[0].experiment
    assert attitude_jumps(whole)[0].size == 0              # hand turns up to 180 deg in 1 s: explained


def test_keyframes_and_rotation_factors_stop_at_segment_boundaries(cut_session):
    e = cut_session.experiment
    problem = build_problem(e, options=_options(cut_session))
    rec = problem.model.record
    starts = np.array([a for a, _ in e.segment_bounds()])
    assert np.array_equal(rec.k0[rec.segment_keys], starts)
    seg_of_key = e.segment[rec.k0[:-1]]
    assert np.all(seg_of_key == e.segment[rec.k0[1:] - 1])        # no keyframe spans a boundary
    kept = rec.rotation_keys
    assert kept.size == rec.n_keyframes - (e.n_segments - 1)
    assert not np.any(np.isin(kept + 1, rec.segment_keys))
    assert problem.q_nb0.shape == (e.n_segments, 4)
    assert len(problem.segment_alignments) == e.n_segments
    for al, (a, b) in zip(problem.segment_alignments, e.segment_bounds()):
        assert a <= al.interval[0] < al.interval[1] <= b


@pytest.fixture(scope="module")
def cut_run(cut_session):
    opts = _options(cut_session)
    problem = build_problem(cut_session.experiment, options=opts)
    return problem, solve_problem(problem, options=opts)


def test_a_cut_session_is_calibrated_with_its_segments(cut_session, cut_run):
    problem, run = cut_run
    truth = cut_session.truth
    assert run.verdict.passed, run.verdict.text()
    for solver, res in run.results.items():
        assert run.outputs[solver].converged, solver
        names = list(res.values)
        z = np.array([(res.values[n] - truth.values[n]) / res.sigmas[n] for n in names])
        assert np.all(np.abs(z) < 3.0), (solver, names[int(np.argmax(np.abs(z)))], float(np.abs(z).max()))
        # not vacuous: the truth lies well away from the zero start in prior sigmas
        prior = problem.model.prior()[1]
        assert np.max(np.abs([truth.values[n] for n in names]) / prior) > 0.5
    assert run.comparison["summary"]["agree"], run.comparison["summary"]
