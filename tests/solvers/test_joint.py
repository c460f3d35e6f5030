"""The joint campaign solver (graph_calib/solvers/joint/): the exact map, chained Jacobians, agreement with the
per-subrange graph on linear truth, the curves against the truth curves, the result file, validation and export.

Short simulated subranges (``nav-campaign``, 0.05 h each at 100 Hz: 18,000 samples per experiment).
"""

import json
from dataclasses import replace
import tomllib
from pathlib import Path

import numpy as np
import pytest

from graph_calib import io
from graph_calib.campaign import CampaignOptions, run_campaign
from graph_calib.campaign.joint_run import truth_check
from graph_calib.cli import main
from graph_calib.compensation import read_compensation
from graph_calib.compensation import read_table, write_table
from graph_calib.compensation.joint import JointCalibration
from graph_calib.errors import InputError
from graph_calib.sensors.effects import REGISTRY
from graph_calib.solvers.joint import JointSolver, WarmStart, plan_unknowns, solve_joint
from graph_calib.solvers.joint.result import joint_result, read_joint_result, write_joint_result
from graph_calib.model.attitude_elimination import AttitudeSolve
from graph_calib.solvers.joint.solver import _extend, _priors
from graph_calib.solvers.joint.unknowns import MAX_DEGREE, curve_label
from graph_calib.options import CalibrationOptions
from graph_calib.sensors.params import Layout, split_element_name
from graph_calib.records.problem import build_problem
from graph_calib.reports import html as H
from graph_calib.reports.joint_report import joint_sections
from graph_calib.simulation import simulate, write_simulation
from graph_calib.solvers.registry import get_solver, solve
from graph_calib.evaluation.validation import simulate_validation_record, validate

HOURS = 0.05
OPTS = CalibrationOptions()


def _campaign(curvature, seed):
    sim = simulate("nav-campaign", rng=np.random.default_rng(seed), hours=HOURS, curvature=curvature)
    runs = sim.run()
    problems = [build_problem(s.experiment, options=OPTS) for s in runs]
    return sim, runs, problems


@pytest.fixture(scope="module")
def linear():
    sim, runs, problems = _campaign(False, 11)
    graphs = [solve("factor-graph", p, options=OPTS) for p in problems]
    out = solve_joint(problems, options=OPTS.graph)
    return sim, runs, problems, graphs, out


@pytest.fixture(scope="module")
def curved():
    sim, runs, problems = _campaign(True, 7)
    graphs = [solve("factor-graph", p, options=OPTS) for p in problems]
    out = JointSolver().solve_campaign(problems, options=OPTS,
                                       initial=[WarmStart(layout=g.layout, x=g.x, sigma=g.sigma) for g in graphs])
    return sim, runs, problems, graphs, out


def _ranges(runs):
    out = []
    for s in runs:
        T = s.experiment.sensor_temperatures()
        out.append(np.column_stack([T.min(axis=0), T.max(axis=0)]))
    return out


def test_the_map_is_the_exact_taylor_expansion_of_the_curves():
    degrees = {b: d for b, d in MAX_DEGREE.items()}
    lay = Layout.declared(extra=tuple(e.name for e in REGISTRY if e.temperature_order >= 2))
    u = plan_unknowns([lay, lay], [3.0, 41.0], degrees=degrees)
    rng = np.random.default_rng(1)
    z = rng.normal(size=u.nz)
    A, B = u.experiment_map(1, lay, 41.0)
    x = A @ z
    T = np.linspace(-10.0, 50.0, 7)
    for flat in ("gyro.bias.y", "accel.scale.z"):
        base, el = split_element_name(flat)
        curve = sum(z[u.z_index()[curve_label(flat, j)]] * (T - u.t0_degC) ** j for j in range(degrees[base] + 1))
        names = lay.element_names()
        tcs = [base] + [f"{base}_tc{'' if k == 1 else k}" for k in range(1, degrees[base] + 1)]
        taylor = sum(x[names.index(f"{n}.{el}")] * (T - 41.0) ** k for k, n in enumerate(tcs))
        np.testing.assert_allclose(taylor, curve, rtol=1e-12, atol=1e-12 * np.abs(curve).max())
    assert B.shape[1] == len(u.setup_names[1]) and "mount.x" in u.setup_names[1]
    assert np.all(A[[lay.index(n) for n in u.setup_names[1]]] == 0.0)


@pytest.mark.slow
def test_chained_jacobians_match_finite_differences(linear):
    _, _, problems, graphs, out = linear
    ps = [_extend(p, {b: d for b, d in MAX_DEGREE.items()}) for p in problems[:2]]
    u = plan_unknowns([p.model.layout for p in ps], [p.model.t_ref_degC for p in ps])
    m = ps[1].model
    A, B = u.experiment_map(1, m.layout, m.t_ref_degC)
    rng = np.random.default_rng(3)
    z_sigma, s_sigmas = _priors(u, [p.model for p in ps])
    z = rng.normal(size=u.nz) * 0.01 * z_sigma
    s = rng.normal(size=B.shape[1]) * 0.01 * s_sigmas[1]
    x = A @ z + B @ s
    preint = m.preintegrate(x)
    R = m.propagate(np.eye(3), preint, x)
    kinds = {"rot": m.rotation_factors, "grav": m.gravity_factors, "enc": m.encoder_factors}

    def chained(kind, x):     # the joint solver's chaining, H_z = H_x A, H_s = H_x B
        H = kinds[kind](R, preint, x).H_x
        return H @ A, H @ B

    idx = u.z_index()
    z_cols = [idx[curve_label("gyro.bias.x", j)] for j in range(4)] + [idx[curve_label("accel.bias.y", 2)],
                                                                       idx["gyro.misalignment.xy"]]
    for kind in ("rot", "grav", "enc"):
        Hz, Hs = chained(kind, x)
        for col in z_cols:
            h = 1e-3 * z_sigma[col]
            zp, zm = z.copy(), z.copy()
            zp[col] += h
            zm[col] -= h
            fd = (kinds[kind](R, preint, A @ zp + B @ s).r - kinds[kind](R, preint, A @ zm + B @ s).r) / (2 * h)
            np.testing.assert_allclose(Hz[:, :, col], fd, rtol=1e-3, atol=1e-5 * np.abs(fd).max() + 1e-300,
                                       err_msg=f"{kind} d/d{u.z_names[col]}")
    Hz, Hs = chained("enc", x)
    mount = list(u.setup_names[1]).index("mount.y")
    h = 1e-5 * s_sigmas[1][mount]
    sp, sm = s.copy(), s.copy()
    sp[mount] += h
    sm[mount] -= h
    fd = (m.encoder_factors(R, preint, A @ z + B @ sp).r - m.encoder_factors(R, preint, A @ z + B @ sm).r) / (2 * h)
    np.testing.assert_allclose(Hs[:, :, mount], fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max())


def test_linear_truth_keeps_linear_curves_and_agrees_with_each_subrange_graph(linear):
    _, _, problems, graphs, out = linear
    assert out.converged
    # the data show no curvature; the curves may hold orders that cost little (degrees.RHO_MAX)
    assert all(c.significant_degree == 1 and c.next_order["passed"] for c in out.degree_choices), \
        [c.to_json() for c in out.degree_choices]
    z_all = []
    for g, j in zip(graphs, out.outputs):
        jn = {n: i for i, n in enumerate(j.layout.element_names())}
        for i, n in enumerate(g.layout.element_names()):
            s_j = np.sqrt(j.covariance[jn[n], jn[n]])
            z_all.append((j.x[jn[n]] - g.x[i]) / np.hypot(g.sigma[i], s_j))
    z_all = np.abs(np.array(z_all))
    # the joint sees every subrange, but its value at T_ref is a curve's Taylor coefficient there (the curve
    # may hold orders the data do not show: its local slope is not the subrange's mean slope), so the two
    # differ within both their sigmas
    assert np.sqrt(np.mean(z_all ** 2)) < 1.0, np.sqrt(np.mean(z_all ** 2))
    assert z_all.max() < 4.0, z_all.max()


@pytest.mark.slow
def test_warm_started_at_its_own_solution_the_joint_solver_starts_there(curved):
    """Handed its own solution (each experiment's view: calibration, sigmas, attitudes) as the warm start, the
    solver's first cost is the solution's: the factors are evaluated at the warm calibration, as GTSAM's
    values hold it (a start once preintegrated at the prior-scaled map applied to SI unknowns, near a zero
    calibration, began orders of magnitude higher and re-preintegrated every experiment)."""
    _, _, problems, _, out = curved
    starts = [WarmStart(layout=o.layout, x=o.x, sigma=o.sigma, attitudes=o.attitudes) for o in out.outputs]
    again = JointSolver().solve_campaign(problems, options=OPTS, initial=starts)
    assert again.converged
    assert again.cost_history[0] == pytest.approx(out.final_cost, rel=0.05), (again.cost_history, out.final_cost)
    assert again.final_cost == pytest.approx(out.final_cost, rel=1e-6)


def test_a_rejected_trial_is_undone_and_the_solve_ends_where_it_would(curved, monkeypatch):
    """The first trial spoiled (every attitude step off by 0.05 rad: its cost far higher, rejected): the solver
    damps harder from the systems it kept and ends at the same solution."""
    _, _, problems, graphs, out = curved
    original = AttitudeSolve.step
    calls = []

    def spoiled(self, d_theta):
        calls.append(1)
        return original(self, d_theta) + (0.05 if len(calls) <= len(problems) else 0.0)

    monkeypatch.setattr(AttitudeSolve, "step", spoiled)
    again = JointSolver().solve_campaign(problems, options=OPTS,
                                         initial=[WarmStart(layout=g.layout, x=g.x, sigma=g.sigma) for g in graphs])
    assert again.converged and len(calls) >= (again.iterations + 1) * len(problems)
    assert again.theta_names == out.theta_names
    z = (again.theta - out.theta) / np.sqrt(np.diag(out.covariance))
    assert np.abs(z).max() < 1e-2, np.abs(z).max()
    np.testing.assert_allclose(np.diag(again.covariance), np.diag(out.covariance), rtol=1e-4)


def test_curved_truth_the_joint_curves_follow_the_truth_curves(curved):
    sim, runs, problems, graphs, out = curved
    assert out.converged
    degrees = out.unknowns.degrees
    # the accelerometer curvature is far above the noise of even 3-minute subranges; the gyro one is not
    assert degrees["accel.bias"] >= 2, [c.to_json() for c in out.degree_choices]
    truth = runs[0].truth.extra["temperature_curves"]          # data-format.md's truth over temperature
    res = joint_result(out, source="campaign.toml", experiments=[f"e{i}" for i in range(len(runs))],
                       t_refs=[p.model.t_ref_degC for p in problems], sensor_ranges=_ranges(runs))
    cal = JointCalibration.from_result(res)
    zs = []
    for name, cv in cal.curves.items():
        if name not in truth:
            continue
        T = np.linspace(cv.t_span[0], cv.t_span[1], 25)
        v, s = cv.evaluate(T)
        t0, coefficients = float(truth[name]["t0_degC"]), truth[name]["coefficients"]
        zs.append((v - np.polynomial.polynomial.polyval(T - t0, coefficients)) / s)
    z = np.abs(np.concatenate(zs))
    assert np.mean(z < 2.0) >= 0.9, np.mean(z < 2.0)
    assert z.max() < 4.0, z.max()


def test_result_file_round_trip_and_its_bad_input(curved, tmp_path):
    _, runs, problems, _, out = curved
    res = joint_result(out, source="campaign.toml", experiments=[f"e{i}" for i in range(len(runs))],
                       t_refs=[p.model.t_ref_degC for p in problems], sensor_ranges=_ranges(runs))
    p = tmp_path / "joint.json"
    write_joint_result(res, p)
    back = read_joint_result(p)
    assert back.values == res.values and back.sigmas == res.sigmas
    np.testing.assert_array_equal(back.covariance, res.covariance)
    assert back.extra["verdict"]["passed"] and back.extra["verdict"]["converged"] == {"joint": True}
    assert back.t_ref_degC == out.unknowns.t0_degC and back.extra["joint"]["degrees"] == out.unknowns.degrees
    a, b = JointCalibration.from_result(res), JointCalibration.from_file(p)
    T = np.tile(np.linspace(-5, 45, 9)[:, None], (1, 6))
    for n, v in a.element_values(T).items():
        np.testing.assert_array_equal(v, b.element_values(T)[n])
    # the mount of each experiment with its sigma
    assert set(back.extra["joint"]["setups"]["e0"]["estimates"]) >= {"mount.x", "lever_arm.z"}
    # a per-experiment result is not a joint one: one clear message naming file and key
    io.write_result(res.__class__(**{**res.__dict__, "extra": {}}), tmp_path / "plain.json")
    with pytest.raises(InputError, match=r"plain\.json.*joint.*no 'joint' block"):
        read_joint_result(tmp_path / "plain.json")


def test_a_joint_result_apart_from_its_campaign_names_the_export_that_takes_it(curved, tmp_path, capsys):
    sim, runs, problems, _, out = curved
    res = joint_result(out, source="campaign.toml", experiments=[f"e{i}" for i in range(len(runs))],
                       t_refs=[p.model.t_ref_degC for p in problems], sensor_ranges=_ranges(runs))
    path = tmp_path / "joint.json"
    write_joint_result(res, path)
    assert main(["export", str(path), "--format", "px4", "--out", str(tmp_path / "j.params")]) == 2
    assert ("a joint result exports from its campaign: graph-calib export CAMPAIGN --solver joint (no campaign.json "
            "beside it") in capsys.readouterr().err
    assert not (tmp_path / "j.params").exists()


def test_validation_and_export_accept_the_joint_calibration(curved, tmp_path):
    sim, runs, problems, _, out = curved
    res = joint_result(out, source="campaign.toml", experiments=[f"e{i}" for i in range(len(runs))],
                       t_refs=[p.model.t_ref_degC for p in problems], sensor_ranges=_ranges(runs))
    cal = JointCalibration.from_result(res)
    se = simulate_validation_record(sim, hours=0.1, rate_hz=20.0, seed=8, start_degC=5.0, span_degC=20.0)
    v = validate(se.experiment, cal, se.truth, record_name="validation.h5")
    summ = v.summary()
    assert min(summ["fraction_inside"]) > 0.9, summ["fraction_inside"]
    # 3-minute subranges do not resolve the gyro biases to the 0.01 deg/h of the full-length campaign; the
    # remaining errors must lie inside the joint bands, and the accelerometers meet the 2e-4 m/s^2
    assert summ["pass"]["accel"], summ["largest"]
    assert summ["largest_z"]["gyro"] < 4.0 and summ["largest_z"]["accel"] < 4.0, summ["largest_z"]
    table = cal.table(step_degC=1.0)
    path = write_table(table, tmp_path / "joint.table.json")
    back = read_table(path)
    T = np.tile(table.grid_degC[3:6, None], (1, 6))
    for n, vals in cal.element_values(T).items():
        np.testing.assert_allclose(back.element_values(T)[n], vals, rtol=1e-12, atol=1e-300)


def test_the_joint_solver_is_registered_by_its_entry_point():
    doc = tomllib.loads((Path(__file__).resolve().parents[2] / "pyproject.toml").read_text())
    assert doc["project"]["entry-points"]["graph_calib.solvers"]["joint"] == "graph_calib.solvers.joint:JointSolver"
    assert get_solver("joint").name == "joint" and get_solver("joint").campaign


@pytest.mark.slow
def test_campaign_runs_the_joint_solver_beside_the_graph_and_caches_it(tmp_path):
    sim = simulate("nav-campaign", rng=np.random.default_rng(5), hours=HOURS, curvature=False)
    write_simulation(sim, tmp_path / "data")
    opts = CampaignOptions(workers=0, solvers="factor-graph+joint", report=False, progress=False)
    run = run_campaign(tmp_path / "data" / "campaign.toml", tmp_path / "out", options=opts)
    doc = json.loads((tmp_path / "out" / "campaign.json").read_text())
    entry = doc["joint"]["joint"]
    assert entry["status"] == "computed" and entry["verdict"]["passed"], entry["verdict"]
    assert (tmp_path / "out" / "joint.json").is_file() and run.joint.solver == "joint"
    # no curvature in the truth: the data show none (the curves may hold orders that cost little)
    assert all(c["significant_degree"] == 1 and c["next_order"]["passed"] for c in entry["degree_choice"]), \
        entry["degree_choice"]
    cc = entry["cross_check"]["factor-graph"]
    assert len(cc["experiments"]) == 6
    # the curve holds orders these short records do not show (degrees.RHO_MAX: they widen its sigma at most
    # 1.5x per order over the span), so at a subrange's T_ref it can be less certain than that subrange's own
    # estimate (its slope most): the two agree within both covariances, the campaign's check
    check = next(c for c in doc["campaign_checks"]["checks"] if c["check"] == "joint against subranges")
    assert check["passed"], check
    # the simulator's truth files carry temperature_curves (data-format.md): the curves against them
    tc = doc["truth_check"]["joint"]["joint"]
    assert tc["mode"] == "temperature_curves" and tc["max_abs_z"] < 4.0 and tc["fraction_within_2sigma"] > 0.9, tc
    # without them, each curve only against each subrange's own truth, inside that subrange's range
    bare = {n: replace(t, extra={k: v for k, v in t.extra.items() if k != "temperature_curves"})
            for n, t in run.truths.items()}
    tc = truth_check(run.joint, bare, run.summaries)
    assert tc["mode"] == "per-subrange" and tc["max_abs_z"] < 4.5 and tc["fraction_within_2sigma"] > 0.9, tc
    # the report's joint section (the rest of the report is tests/campaign/test_campaign.py's)
    figures = []
    sections = joint_sections(run, lambda f, caption: figures.append(caption) or H.figure(f, caption=caption))
    assert len(sections) == 1 and len(figures) == 4 and f"degree {entry['degrees']['gyro.bias']}" in figures[0]
    html = H.page("t", *sections)
    assert "Joint solver: one model over the whole range" in html and "Degree by evidence" in html
    # export and apply take the campaign's joint calibration like a stitched one
    assert main(["export", str(tmp_path / "out"), "--out", str(tmp_path / "joint.csv"), "--solver", "joint"]) == 0
    comp, prov = read_compensation(tmp_path / "out", solver="joint")
    assert isinstance(comp, JointCalibration) and prov["solver"] == "joint"
    comp2, _ = read_compensation(tmp_path / "out" / "joint.json")
    assert isinstance(comp2, JointCalibration) and set(comp2.curves) == set(comp.curves)
    # joint.json itself exports as its campaign's joint calibration (it ended in an AttributeError, exit 1)
    for source, name in ((tmp_path / "out" / "joint.json", "a.params"), (tmp_path / "out", "b.params")):
        argv = ["export", str(source), "--format", "px4", "--out", str(tmp_path / name)]
        assert main(argv + (["--solver", "joint"] if source.is_dir() else [])) == 0
    assert [ln for ln in (tmp_path / "a.params").read_text().splitlines() if not ln.startswith("#")] == \
        [ln for ln in (tmp_path / "b.params").read_text().splitlines() if not ln.startswith("#")]
    again = run_campaign(tmp_path / "data" / "campaign.toml", tmp_path / "out", options=opts)
    assert again.document["joint"]["joint"]["status"] == "cached"


def test_a_manifest_asking_for_an_unknown_solver_choice_is_refused(tmp_path):
    write_simulation(simulate("nav-campaign", rng=np.random.default_rng(2), hours=0.005), tmp_path)
    m = tmp_path / "campaign.toml"
    m.write_text(m.read_text() + '\n[solver]\nsolvers = "joint-only"\n')
    with pytest.raises(InputError, match=r"campaign\.toml.*solvers.*unknown solver 'joint-only': must be 'both'.*'per-subrange'.*joint"):
        io.read_manifest(m)
    m.write_text(m.read_text().replace('"joint-only"', '"factor-graph+joint"'))
    assert io.read_manifest(m).solver["solvers"] == "factor-graph+joint"
