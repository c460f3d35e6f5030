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
from graph_calib.records.plausibility import JUMP_WINDOW_S, attitude_jumps, check_continuity
from graph_calib.simulation import simulate

from _synthetic import assert_pair_jacobians_match_fd


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


def test_the_cut_record_is_the_whole_session_less_the_cut_turns(cut_session):
    from graph_calib.simulation.experiments import cut_out

    whole = simulate("consumer-handheld", rng=np.random.default_rng(7)).run()[0]
    keep, segment = cut_out(whole.motion, range(1, 30, 2))
    e, w = cut_session.experiment, whole.experiment
    # the same sensor, the same noise: equal to rounding (the truth is parametrised at another T_ref)
    np.testing.assert_allclose(e.dv, w.dv[keep], rtol=0, atol=1e-13)
    np.testing.assert_allclose(e.dtheta, w.dtheta[keep], rtol=0, atol=1e-13)
    assert np.array_equal(e.segment, segment)
    assert cut_session.truth.t_ref_degC == pytest.approx(e.default_t_ref(), abs=1e-12)   # T_ref of what is kept


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


def test_factor_jacobians_of_a_segmented_record_match_fd():
    """Three segments cut at samples that are no keyframe boundary of the uncut record: keyframes restart at
    each cut, and the rotation factors kept (and the gravity factors, the last of a segment included) have
    the Jacobians finite differences give."""
    from graph_calib.model import CalibrationModel
    from graph_calib.navigation.rotations import exp_so3

    from _synthetic import wobbly_experiment

    eps = 1e-6
    rng = np.random.default_rng(1)
    exp = wobbly_experiment(rng=rng)
    n = exp.n_samples
    seg = np.zeros(n, dtype=np.int32)
    seg[n // 3 + 7:] = 1
    seg[2 * n // 3 + 3:] = 2
    model = CalibrationModel(replace(exp, segment=seg), options=ModelOptions(keyframe_s=0.5))
    rec = model.record
    assert np.array_equal(rec.k0[rec.segment_keys], [0, n // 3 + 7, 2 * n // 3 + 3])
    x = rng.normal(size=model.layout.size) * 1e-3
    preint = model.preintegrate(x)
    R = model.propagate(np.stack([np.eye(3)] * 3), preint, x) @ exp_so3(rng.normal(size=(rec.n_keyframes + 1, 3)) * 1e-2)
    kinds = ("rotation_factors", "gravity_factors")
    at_x = {kind: getattr(model, kind)(R, preint, x) for kind in kinds}
    for c in range(model.layout.size):
        xp, xm = x.copy(), x.copy()
        xp[c] += eps
        xm[c] -= eps
        pp, pm = model.preintegrate(xp), model.preintegrate(xm)
        for kind in kinds:
            f = getattr(model, kind)
            fd = (f(R, pp, xp).r - f(R, pm, xm).r) / (2 * eps)
            H = at_x[kind].H_x[:, :, c]
            scale = np.abs(fd).max() + np.abs(H).max() + 1e-12
            assert np.abs(fd - H).max() / scale < 1e-5, (kind, model.layout.element_names()[c])
    res = model.rotation_factors(R, preint, x)
    last = rec.segment_keys[1:] - 1                       # the last keyframe of each segment but the last
    for k in np.concatenate([last, last - 1, [rec.n_keyframes - 1]]):
        i = int(np.flatnonzero(res.key == k)[0]) if k in res.key else None
        assert (i is None) == (k in last)
        if i is None:
            continue
        assert_pair_jacobians_match_fd(lambda R_: model.rotation_factors(R_, preint, x), R, index=i, key=k,
                                       H_R=res.H_R[i], H_R_next=res.H_R_next[i], eps=eps, atol=1e-8)


def test_the_diagnosis_linearises_a_segmented_fit_at_its_optimum(cut_run):
    """The diagnosis's reduced system (every segment's attitude prior in its attitude block) sees the
    graph's solution as the optimum: the Gauss-Newton step from there is a small fraction of a sigma."""
    from graph_calib.diagnosis import linearise

    _, run = cut_run
    problem = run.problem                   # the model solved: with its variance factors
    out = run.outputs["factor-graph"]
    model = problem.model
    rs, _ = linearise(model, out.attitudes, out.x, q_nb0=problem.q_nb0, null_names=model.layout.names,
                      drivers=False)
    step = np.linalg.solve(rs.A, rs.b)
    sigma = np.sqrt(np.diag(np.linalg.inv(rs.A)))
    assert np.max(np.abs(step) / sigma) < 0.05
    np.testing.assert_allclose(sigma, np.sqrt(np.diag(out.covariance)), rtol=1e-3)   # the graph's own sigmas


def test_the_measured_sessions_are_not_taken_for_cut_records():
    """The continuity rule judges only where both sides rest: the Xsens session ends in a shake whose gyros
    saturate (390 deg/s) and whose window means come near gravity by chance; it is not a cut."""
    from graph_calib.importers import import_mpu6050, import_xsens

    from _shared import REAL_DATA, require_real

    xsens = import_xsens(require_real(REAL_DATA / "imu_tk_xsens" / "xsens_acc.mat"),
                         require_real(REAL_DATA / "imu_tk_xsens" / "xsens_gyro.mat"))
    mpu = import_mpu6050(require_real(REAL_DATA / "mpu6050_uncuyo" / "example_data_calibration.csv"))
    for e in (xsens, mpu):
        assert attitude_jumps(e)[0].size == 0
        check_continuity(e)


def test_calibrate_on_an_unmarked_cut_record_exits_2_with_one_line_and_writes_nothing(cut_session, tmp_path):
    import subprocess
    import sys
    from pathlib import Path

    from graph_calib import io

    bad = tmp_path / "CUT.h5"
    io.write_experiment(replace(cut_session.experiment, segment=None), bad)
    out = tmp_path / "C"
    out.mkdir()
    proc = subprocess.run([sys.executable, "-m", "graph_calib.cli", "calibrate", str(bad), "--out", str(out),
                           "--grade", "consumer"], cwd=Path(__file__).resolve().parents[2], capture_output=True,
                          text=True, timeout=300, check=False)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    first = cut_session.experiment.segment_bounds()[1][0]
    assert f"CUT.h5: /imu/dv [sample {first}]: the record is discontinuous" in lines[0]
    assert "/imu/segment" in lines[0]
    assert list(out.iterdir()) == []
