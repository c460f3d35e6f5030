"""Applying a calibration and the compensation table: graph-calib apply and graph-calib export.

One short simulated campaign (six subranges of 72 s, factor graph only, with two further
effects modelled: ``gyro.g_sensitivity``, stitched as a constant, and ``time_lag.accel``,
which the stitching leaves out) is run once through the command line; everything else
reads its files.
"""

import json
import re
import shutil
from dataclasses import replace

import h5py
import numpy as np
import pytest

from graph_calib import cli, io
from graph_calib.compensation.calibration import Calibration, correct_record, prepare, triad_errors
from graph_calib.compensation import (
    BENCH_PARAMETERS, INTERPOLATION, PROVENANCE_ATTRIBUTE, TABLE_VERSION, CompensationTable, StitchedCalibration,
    TableCurve, correction_of, element_identifier, interpolate, read_table, write_table,
)
from graph_calib.constants import DH_TO_RS
from graph_calib.sensors.params import Layout



def _cli(argv, capsys):
    code = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def stitched(campaign):
    return StitchedCalibration.from_campaign(campaign[1])


@pytest.fixture(scope="module")
def tables(campaign, stitched, tmp_path_factory):
    """The campaign exported through the CLI in every format, ``{format: path}``."""
    out = tmp_path_factory.mktemp("tables")
    paths = {}
    for fmt, name in (("json", "table.json"), ("csv", "table.csv"), ("c-header", "table.h")):
        paths[fmt] = out / name
        assert cli.main(["export", str(campaign[1]), "--out", str(paths[fmt]), "--format", fmt]) == 0
    return paths


def _on_grid(experiment, grid, lo, hi):
    """The experiment with every temperature channel stepping through grid temperatures inside [lo, hi]."""
    temps = grid[(grid >= lo) & (grid <= hi)]
    n = experiment.n_samples
    k = (np.arange(n) * temps.size) // n
    T = np.column_stack([temps[(k + c) % temps.size] for c in range(experiment.temperature.shape[1])])
    return replace(experiment, temperature=T)


# ---------------------------------------------------------------------------
# the interpolation the table assumes
# ---------------------------------------------------------------------------


def test_interpolation_is_linear_exact_at_grid_points_and_holds_the_ends():
    grid = np.array([-10.0, 0.0, 10.0, 20.0])
    v = np.array([3.0, 1.0e-7, -2.5e-6, 7.0])
    assert interpolate(grid, v, grid).tolist() == v.tolist()                      # the grid values themselves
    expected = [0.5 * (1e-7 - 2.5e-6), -2.5e-6 + 0.25 * (7 + 2.5e-6)]
    np.testing.assert_allclose(interpolate(grid, v, [5.0, 12.5]), expected, rtol=1e-15)
    assert interpolate(grid, v, [-50.0, 99.0]).tolist() == [3.0, 7.0]            # end values held outside


def test_per_sample_vectors_are_the_model_inverse_bit_for_bit(experiment_factory):
    """correct_record with equal rows is sensor_model.correct itself; with rows it is the per-sample inverse."""
    layout = Layout(("gyro.bias", "gyro.scale", "gyro.misalignment", "accel.bias", "accel.scale",
                     "accel.misalignment", "gyro.scale_asym", "accel.nonlinearity", "time_lag.accel"))
    rng = np.random.default_rng(2)
    x = rng.normal(0.0, 1e-4, layout.size)
    exp = experiment_factory(n=400)
    record = prepare(exp, t_ref_degC=22.0)
    w1, f1 = Calibration(layout=layout, x=x, t_ref_degC=22.0).correct(exp)
    w2, f2 = correct_record(layout, np.tile(x, (exp.n_samples, 1)), record)
    np.testing.assert_array_equal(w1, w2)
    np.testing.assert_array_equal(f1, f2)
    X = x + rng.normal(0.0, 1e-5, (exp.n_samples, layout.size))
    w3, f3 = correct_record(layout, X, record)
    for j in (0, 199, 399):
        wj, fj = correct_record(layout, X[j], record)
        assert w3[j].tolist() == wj[j].tolist() and f3[j].tolist() == fj[j].tolist()


# ---------------------------------------------------------------------------
# export
# ---------------------------------------------------------------------------


def test_stitched_calibration_is_the_campaigns_stitching(campaign, stitched):
    doc = json.loads((campaign[1] / "campaign.json").read_text())
    stored = doc["stitching"]["factor-graph"]["elements"]
    assert set(stitched.stitched.curves) == set(stored)
    for name, cv in stitched.stitched.curves.items():
        for kind, fit in cv.fits.items():
            assert fit.theta.tolist() == stored[name]["fits"][kind]["theta"]       # recomputed bit for bit
    assert stitched.info["stitch_model"] == doc["stitch_model"] == "cubic"
    # misalignments and g-sensitivity are constant fits; the table lag, which the stitching leaves out, a constant too
    assert "gyro.misalignment.xy" in stitched.constants and "gyro.g_sensitivity.zz" in stitched.constants
    assert "time_lag.accel" in stitched.constants
    assert stitched.constants["time_lag.accel"][1] > 0
    assert {"gyro.bias.x", "accel.scale.z"} <= set(stitched.curve_elements())
    params = {n.rsplit(".", 1)[0] for n in stitched.elements()}
    assert not any(p.startswith(BENCH_PARAMETERS) for p in params) and not any("_tc" in n for n in stitched.elements())


def test_export_every_format_reads_back_the_same_numbers(stitched, tables):
    table = stitched.table(step_degC=1.0)
    assert table.grid_degC.tolist() == np.arange(table.grid_degC[0], table.grid_degC[-1] + 1).tolist()
    lo, hi = table.info["calibrated_range_degC"]
    assert table.grid_degC[0] <= lo < table.grid_degC[0] + 1 and table.grid_degC[-1] - 1 < hi <= table.grid_degC[-1]
    for fmt in ("json", "csv"):
        back = read_table(tables[fmt])
        assert back.grid_degC.tolist() == table.grid_degC.tolist()
        assert list(back.curves) == list(table.curves)
        for n, c in table.curves.items():
            assert back.curves[n].values.tolist() == c.values.tolist()
            assert back.curves[n].sigmas.tolist() == c.sigmas.tolist()
            assert back.curves[n].interpolation_error == c.interpolation_error
        assert back.constants == table.constants
        assert back.info["solver"] == "factor-graph" and back.info["imu_id"] == "SIM-NAV 0001"
    # the C header: plain arrays and scalars holding the same numbers, units in comments
    text = tables["c-header"].read_text()
    assert INTERPOLATION in text and f"#define GC_TABLE_VERSION {TABLE_VERSION}" in text
    arrays = {m.group(1): [float(v) for v in m.group(2).split(",")]
              for m in re.finditer(r"static const double (\w+)\[GC_N_GRID\] = \{([^}]*)\};", text)}
    scalars = {m.group(1): float(m.group(2)) for m in re.finditer(r"static const double (\w+) = ([^;]+);", text)}
    assert arrays["gc_grid_degC"] == table.grid_degC.tolist()
    for n, c in table.curves.items():
        assert arrays[element_identifier(n)] == c.values.tolist()
        assert arrays[element_identifier(n) + "_sigma"] == c.sigmas.tolist()
        assert re.search(rf"/\* {re.escape(n)}: \S+, at the \w+\.[xyz] temperature", text)
    for n, (v, s) in table.constants.items():
        assert scalars[element_identifier(n)] == v and scalars[element_identifier(n) + "_sigma"] == s
    assert len(arrays) == 1 + 2 * len(table.curves) and len(scalars) == 2 * len(table.constants)


def test_table_holds_the_stitched_values_and_states_its_interpolation_error(stitched):
    table = stitched.table(step_degC=1.0)
    for n, c in table.curves.items():
        v, s = stitched.curve_values(n, table.grid_degC)
        assert c.values.tolist() == v.tolist() and c.sigmas.tolist() == s.tolist()
        e = c.interpolation_error
        assert 0 < e["max_abs"] and e["max_in_sigma"] < 0.1                 # 1 degC is fine for these curves
    coarse = stitched.table(step_degC=10.0)
    def worst(t):
        return max(c.interpolation_error["max_in_sigma"] for c in t.curves.values())

    assert worst(coarse) > 10 * worst(table)                                # h^2: a coarse grid follows worse


def test_linear_model_tabulates_every_stitched_element(campaign):
    lin = StitchedCalibration.from_campaign(campaign[1], model="linear")
    assert "gyro.misalignment.xy" in lin.curve_elements()                     # subrange values interpolated
    assert set(lin.constants) == {"time_lag.accel"}


# ---------------------------------------------------------------------------
# apply: the table against the stitched calibration itself
# ---------------------------------------------------------------------------


def test_apply_table_equals_applying_the_stitched_calibration_at_grid_temperatures(campaign, stitched, tables):
    """At grid temperatures both hold the same numbers: the corrections agree to 1e-12 of themselves (exactly)."""
    raw = io.read_experiment(campaign[0] / "sub3_10_20.h5")
    table = read_table(tables["json"])
    lo, hi = table.info["calibrated_range_degC"]
    exp = _on_grid(raw, table.grid_degC, lo, hi)
    w_st, f_st = stitched.correct(exp)
    dt = exp.dt[:, None]
    for path in (tables["json"], tables["csv"]):
        w_tab, f_tab = read_table(path).correct(exp)
        for a, b, m in ((w_tab, w_st, exp.dtheta / dt), (f_tab, f_st, exp.dv / dt)):
            correction = np.abs(m - b).max()
            assert correction > 0
            assert np.abs(a - b).max() <= 1e-12 * correction


def test_between_grid_points_the_difference_is_the_stated_interpolation_error(campaign, stitched, tables):
    exp = io.read_experiment(campaign[0] / "sub3_10_20.h5")        # sensor temperatures between grid points
    table = read_table(tables["json"])
    T = exp.sensor_temperatures()
    v_tab, v_st = table.element_values(T), stitched.element_values(T)
    for n, c in table.curves.items():
        assert np.abs(v_tab[n] - v_st[n]).max() <= c.interpolation_error["max_abs"] * (1 + 1e-9)
    for n in table.constants:
        assert v_tab[n].tolist() == v_st[n].tolist()
    # through the model, d s = -(I + D)^-1 Phi(s) dx with D = diag(scale) + M the signal slope of the error:
    # |d s| <= v + d/(1-d) max(v), v = sum over terms |feature| |d element|, d = largest row sum of |D|
    layout = table.layout
    dX = np.abs(table.rows(T) - stitched.rows(T))
    X = np.abs(stitched.rows(T))
    w_tab, f_tab = table.correct(exp)
    w_st, f_st = stitched.correct(exp)
    for triad, s, other, diff in (("gyro", w_st, f_st, np.abs(w_tab - w_st)),
                                  ("accel", f_st, w_st, np.abs(f_tab - f_st))):
        v = triad_errors(layout, dX, triad, np.abs(s), other=np.abs(other))
        d = triad_errors(layout, X, triad, np.ones_like(s)) - triad_errors(layout, X, triad, np.zeros_like(s))
        d = d.max()
        assert 0 < d < 0.01
        # plus the rounding of the two corrections (a few tens of ulps of the largest signal: the quantization's
        # merge moved one gyro sample's difference 1.1e-15 rad/s above the bound with 1e-15 |s|max = 5e-16 slack)
        assert np.all(diff <= v + d / (1 - d) * v.max(axis=1, keepdims=True) + 1e-14 * np.abs(s).max())
    assert np.abs(w_tab - w_st).max() > 0                                # not vacuous: the temperatures are off-grid


def test_apply_command_agrees_with_the_python_objects(campaign, stitched, tables, tmp_path, capsys):
    src = campaign[0] / "sub2_0_10.h5"
    raw = io.read_experiment(src)
    result_file = campaign[1] / "sub2_0_10" / "factor-graph.json"
    cases = {"result": (result_file, Calibration.from_result(io.read_result(result_file))),
             "table": (tables["csv"], read_table(tables["csv"])),
             "campaign": (campaign[1], stitched)}
    for name, (cal_path, obj) in cases.items():
        out = tmp_path / f"{name}.h5"
        code, stdout, err = _cli(["apply", cal_path, src, "--out", out], capsys)
        assert code == 0, err
        assert "mean correction" in stdout and str(out) in stdout
        got = io.read_experiment(out)
        w, f = obj.correct(raw)
        dt = raw.dt[:, None]
        assert got.dtheta.tolist() == (w * dt).tolist() and got.dv.tolist() == (f * dt).tolist()


# ---------------------------------------------------------------------------
# the corrected record
# ---------------------------------------------------------------------------


def test_corrected_record_is_a_valid_experiment_with_its_provenance(campaign, tables, tmp_path, capsys):
    src = campaign[0] / "sub4_20_30.h5"
    out = tmp_path / "corrected.h5"
    assert _cli(["apply", tables["json"], src, "--out", out], capsys)[0] == 0
    raw, got = io.read_experiment(src), io.read_experiment(out)          # read_experiment validates it
    for field in ("t", "temperature", "temperature_map"):
        assert getattr(got, field).tolist() == getattr(raw, field).tolist()
    assert got.table.t.tolist() == raw.table.t.tolist() and got.table.valid.tolist() == raw.table.valid.tolist()
    assert (got.imu_id, got.rate_hz, got.latitude_rad, got.gravity_mps2) == \
        (raw.imu_id, raw.rate_hz, raw.latitude_rad, raw.gravity_mps2)
    assert not np.array_equal(got.dtheta, raw.dtheta) and not np.array_equal(got.dv, raw.dv)
    first = got.description.splitlines()[0]
    assert first.startswith("corrected with the compensation table of SIM-NAV 0001") and "table.json" in first
    assert got.description.endswith(raw.description)
    prov = correction_of(out)
    assert prov["kind"] == "table" and prov["file"] == str(tables["json"].resolve())
    assert prov["sha256"] == __import__("hashlib").sha256(tables["json"].read_bytes()).hexdigest()
    assert prov["samples"] == raw.n_samples and prov["outside"] == 0 and prov["input"] == str(src)
    assert correction_of(src) is None
    assert sorted(p.name for p in tmp_path.iterdir()) == ["corrected.h5"]        # no temporary left behind


def test_recalibrating_a_record_corrected_by_its_own_result_finds_near_zero_errors(campaign, tmp_path, capsys):
    src = campaign[0] / "sub3_10_20.h5"
    res_file = campaign[1] / "sub3_10_20" / "factor-graph.json"
    out = tmp_path / "own.h5"
    assert _cli(["apply", res_file, src, "--out", out], capsys)[0] == 0
    assert _cli(["calibrate", out, "--out", tmp_path / "recal", "--solver", "factor-graph"], capsys)[0] == 0
    before = io.read_result(res_file)
    after = io.read_result(tmp_path / "recal" / "factor-graph.json")
    sensor = [n for n in after.values if not n.startswith(BENCH_PARAMETERS)]
    z_after = max(abs(after.values[n]) / after.sigmas[n] for n in sensor)
    z_before = max(abs(before.values[n]) / before.sigmas[n] for n in sensor)
    assert z_before > 20 and z_after < 1.0          # prior-limited elements keep a fraction of their sigma
    for n in ("mount.x", "lever_arm.z"):            # the bench set-up is not a sensor correction
        assert abs(after.values[n] - before.values[n]) < 3 * before.sigmas[n]


def test_applying_twice_is_refused_and_visibly_wrong_when_forced(campaign, tables, tmp_path, capsys):
    src = campaign[0] / "sub1_m10_0.h5"
    once, twice = tmp_path / "once.h5", tmp_path / "twice.h5"
    assert _cli(["apply", tables["json"], src, "--out", once], capsys)[0] == 0
    code, _, err = _cli(["apply", tables["json"], once, "--out", twice], capsys)
    assert code == 2 and not twice.exists()
    assert len(err.strip().splitlines()) == 1 and "already corrected" in err and "--again" in err
    assert _cli(["apply", tables["json"], once, "--out", twice, "--again"], capsys)[0] == 0
    raw, e1, e2 = (io.read_experiment(p) for p in (src, once, twice))
    c1 = np.mean(raw.dtheta - e1.dtheta, axis=0)
    c2 = np.mean(e1.dtheta - e2.dtheta, axis=0)
    np.testing.assert_allclose(c2, c1, rtol=1e-3)          # the same errors subtracted a second time
    assert correction_of(twice)["previously"]["file"] == str(tables["json"].resolve())


# ---------------------------------------------------------------------------
# the table on the campaign's validation record
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def validated(tmp_path_factory):
    """A campaign validated on an independent record, run through the CLI: the worked example of
    docs/compensation.md (``nav-campaign --hours 0.05 --seed 3``, factor graph) with a 2 h record at 10 Hz
    sweeping the whole range (``simulate_validation_record``, seed 4, its truth as the reference).

    Returns ``{"record", "camp", "entry"}``: the record's path, the campaign folder, campaign.json's
    ``validation[0]``.
    """
    from graph_calib.simulation import simulate, write_simulation
    from graph_calib.evaluation.validation import simulate_validation_record

    root = tmp_path_factory.mktemp("validated")
    sim_dir, camp = root / "sim", root / "camp"
    sim = simulate("nav-campaign", rng=np.random.default_rng(3), hours=0.05, tag="seed 3")  # = simulate --seed 3
    write_simulation(sim, sim_dir, tag="seed 3")
    se = simulate_validation_record(sim, hours=2.0, rate_hz=10.0, seed=4)
    record = sim_dir / "validation.h5"
    io.write_experiment(se.experiment, record)
    io.write_result(se.truth, sim_dir / "validation.truth.json")
    rc = cli.main(["campaign", str(sim_dir / "campaign.toml"), "--out", str(camp), "--workers", "0",
                   "--solver", "factor-graph", "--no-report", "--quiet", "--validate", str(record)])
    doc = json.loads((camp / "campaign.json").read_text())
    # 3-minute subranges do not meet the validation record named on the command line: exit 3 (cli.md), files written
    assert rc == 3 and any("validation on validation.h5" in f for f in doc["verdict"]["campaign_checks_failed"])
    entry = doc["validation"][0]
    assert entry["reference_kind"] == "truth"
    return {"record": record, "camp": camp, "entry": entry}


def _figures(summary):
    """The headline figures of a validation summary, per axis: largest static gyro error (rad/s), largest
    accelerometer error over all windows (m/s^2), the verdict."""
    return (np.array(summary["gyro_radps"]["static"]["max"]), np.array(summary["accel_mps2"]["all"]["max"]),
            summary["pass"])


def _propagated(table, windows):
    """The table's stated interpolation errors through the sensor errors, per window, (W, 3) per triad:
    ``sum |d element| |feature|`` with ``|d element|`` each temperature-dependent element's
    ``interpolation_error.max_abs`` (constants hold the stitched values exactly), widened by 1 %: the stated
    error is the largest over 16 points per grid interval, which the departure between them exceeds by up to
    0.08 % on this record (docs/compensation.md)."""
    from graph_calib.evaluation.validation import sensor_errors

    dx = {n: 1.01 * c.interpolation_error["max_abs"] for n, c in table.curves.items()}
    return sensor_errors(dx, np.abs(windows["omega"]), np.abs(windows["f"]))


def test_the_exported_table_reproduces_the_campaigns_validation_figures(validated, tmp_path, capsys):
    """validate(record, table, reference) against campaign.json's validation summary: the same windows, the
    largest errors per axis within the table's stated interpolation error propagated, the same verdict."""
    from graph_calib.evaluation.validation import truth_reference, validate, window_means

    entry = validated["entry"]
    doc = json.loads((validated["camp"] / "campaign.json").read_text())
    solver, model = doc["primary_solver"], doc["stitch_model"]
    campaign_summary = entry["results"][solver][model]
    record = io.read_experiment(validated["record"])
    reference = truth_reference(io.read_result(entry["reference"]))    # what the campaign validates against
    w = window_means(record)
    # the campaign's figures come back bit for bit from the stitching export recomputes
    st = validate(record, StitchedCalibration.from_campaign(validated["camp"]).stitched, reference, model=model,
                  windows=w, record_name=validated["record"].name)
    assert json.loads(json.dumps(st.summary())) == campaign_summary
    g_c, a_c, pass_c = _figures(campaign_summary)
    diffs = {}
    for step in (1.0, 4.0):     # the coarser one as coarse as export writes (its error under 1 sigma)
        out = tmp_path / f"table-{step:g}.json"
        # the validation is not met (three-minute subranges): the table is written with --force
        assert _cli(["export", validated["camp"], "--out", out, "--step-degc", step, "--force"], capsys)[0] == 0
        table = read_table(out)
        v = validate(record, table, reference, model=model, windows=w, record_name=validated["record"].name)
        s = v.summary()
        for key in ("record", "reference", "model", "window_s", "temperature_range_degC", "calibrated_range_degC",
                    "sensor_calibrated_range_degC", "fraction_inside", "thresholds", "gyro_criterion"):
            assert s[key] == campaign_summary[key], key                  # the same windows, selected alike
        assert s["gyro_radps"]["static"]["windows_per_axis"] == campaign_summary["gyro_radps"]["static"][
            "windows_per_axis"]
        # per window on the grid, the table's remaining error departs from the stitched one by at most the
        # propagated bound (beyond the grid the table holds its end values, the stitched curve extrapolates;
        # every window the figures count lies inside the calibrated range, so on the grid)
        bg, ba = _propagated(table, w)
        on_grid = (w["T"] >= table.grid_degC[0]) & (w["T"] <= table.grid_degC[-1])
        assert np.all(on_grid[v.inside]) and not np.all(on_grid)
        assert np.all((np.abs(v.de_gyro - st.de_gyro) <= bg)[on_grid[:, :3]])
        assert np.all((np.abs(v.de_accel - st.de_accel) <= ba)[on_grid[:, 3:]])
        # and so the largest per axis (a largest |x| moves by at most the largest change of x)
        g, a, passed = _figures(s)
        sel_g = w["static"][:, None] & v.inside[:, :3]
        sel_a = v.inside[:, 3:]
        bound_g = np.array([bg[sel_g[:, i], i].max() for i in range(3)])
        bound_a = np.array([ba[sel_a[:, i], i].max() for i in range(3)])
        assert np.all(np.abs(g - g_c) <= bound_g)
        assert np.all(np.abs(a - a_c) <= bound_a)
        assert passed == pass_c
        diffs[step] = (np.abs(g - g_c).max(), np.abs(a - a_c).max(), bound_g.max(), bound_a.max())
        if step == 1.0:                      # docs/compensation.md: gyro 9.6e-6 deg/h, accel 7.1e-9 m/s^2
            assert diffs[step][0] < 2e-5 * DH_TO_RS and diffs[step][1] < 2e-8
            assert abs(s["largest_z"]["gyro"] - campaign_summary["largest_z"]["gyro"]) < 0.01
            with pytest.raises(ValueError, match="holds the cubic stitched model"):
                validate(record, table, reference, model="linear", windows=w)
    assert 0 < diffs[1.0][0] < diffs[4.0][0] and 0 < diffs[1.0][1] < diffs[4.0][1]   # not vacuous: h^2
    assert diffs[4.0][2] > 8 * diffs[1.0][2]             # h^2 = 16


def _window_average(x, experiment):
    """Mean of per-sample ``x`` (N, k) over the windows of :func:`graph_calib.evaluation.validation.window_means` (1 s),
    weighted by the sample intervals as its rates are."""
    m = round(float(experiment.rate_hz))
    W = experiment.n_samples // m
    dt = experiment.dt[:W * m].reshape(W, m, 1)
    return (x[:W * m].reshape(W, m, -1) * dt).sum(axis=1) / dt.sum(axis=1)


def test_applying_the_table_and_measuring_against_the_reference_gives_the_same_figures(validated, tmp_path,
                                                                                         capsys):
    """The INS path: ``graph-calib apply TABLE RECORD`` writes corrected increments; the remaining error of the
    corrected record is its window means less those of the record corrected with the reference (the truth, in
    the same sensor model).  Per window this is validate's ``e_ref - e_table``, except for products of two small
    errors (exactly: ``(u_t - u_r) - de = -D_t (u_t - u_r) + (D_r - D_t)(u_r - m)`` per sample, ``D`` the
    scale-and-misalignment matrix, ``u`` the corrected and ``m`` the measured signal); the figures agree."""
    from graph_calib.evaluation.validation import ResultCalibration, Validation, sensor_errors, validate, window_means

    entry = validated["entry"]
    campaign_summary = entry["results"]["factor-graph"]["cubic"]
    table_file = tmp_path / "table.json"
    corrected_file = tmp_path / "validation.corrected.h5"
    # the validation is not met (three-minute subranges): the table is written with --force
    assert _cli(["export", validated["camp"], "--out", table_file, "--force"], capsys)[0] == 0
    assert _cli(["apply", table_file, validated["record"], "--out", corrected_file, "--force"], capsys)[0] == 0
    raw = io.read_experiment(validated["record"])
    corrected = io.read_experiment(corrected_file)
    reference = ResultCalibration(io.read_result(entry["reference"]))
    by_reference = reference.calibration.corrected(raw)
    w = window_means(raw)                              # the campaign's windows: static ones, temperatures
    wc, wr = window_means(corrected), window_means(by_reference)
    de_g, de_a = wc["omega"] - wr["omega"], wc["f"] - wr["f"]
    table = read_table(table_file)
    v = validate(raw, table, reference, model="cubic", windows=w, record_name=validated["record"].name)
    # the second-order terms, per sample, window-averaged
    T = raw.sensor_temperatures()
    dt = raw.dt[:, None]
    m_g, m_a = raw.dtheta / dt, raw.dv / dt
    u_t = (corrected.dtheta / dt, corrected.dv / dt)
    u_r = (by_reference.dtheta / dt, by_reference.dv / dt)
    vt, vr = table.evaluate(T), reference.evaluate(T)
    slopes = {n: x for n, x in vt.items() if ".bias." not in n}
    ones = np.ones_like(m_g)
    d_t = [np.max(e, axis=1) for e in sensor_errors({n: np.abs(x) for n, x in slopes.items()}, ones, ones)]
    d_d = [np.max(e, axis=1) for e in sensor_errors({n: np.abs(vr[n] - x) for n, x in slopes.items()}, ones, ones)]
    bounds = []
    for i, (de, de_v, m) in enumerate(((de_g, v.de_gyro, m_g), (de_a, v.de_accel, m_a))):
        per_sample = d_t[i] * np.abs(u_t[i] - u_r[i]).max(axis=1) + d_d[i] * np.abs(u_r[i] - m).max(axis=1)
        bound = 1.02 * np.broadcast_to(_window_average(per_sample[:, None], raw), de.shape)
        inside = v.inside[:, 3 * i:3 * i + 3]
        # on the windows the figures count (inside the calibrated range; outside, a sensor temperature can
        # straddle the grid's end, where the table's held end value kinks, within one window): the measured
        # ratio to the bound is at most 0.97 (gyro), 0.996 (accel); 2 % allowed for the window means
        assert np.all((np.abs(de - de_v) <= bound)[inside])
        assert np.abs(de - de_v).max() < 1e-3 * np.abs(de_v).max()        # 1.9e-4 (gyro), 3.2e-4 (accel) measured
        bounds.append(bound)
    e2e = Validation(record=validated["record"].name, reference=reference.label, model="cubic", windows=w,
                     de_gyro=de_g, de_accel=de_a, inside=v.inside).summary()
    g, a, passed = _figures(e2e)
    g_v, a_v, passed_v = _figures(v.summary())
    g_c, a_c, passed_c = _figures(campaign_summary)
    sel_g = w["static"][:, None] & v.inside[:, :3]
    sel_a = v.inside[:, 3:]
    second_g = np.array([bounds[0][sel_g[:, i], i].max() for i in range(3)])
    second_a = np.array([bounds[1][sel_a[:, i], i].max() for i in range(3)])
    assert np.all(np.abs(g - g_v) <= second_g) and np.all(np.abs(a - a_v) <= second_a)
    assert np.abs(g - g_v).max() < 3e-5 * DH_TO_RS and np.abs(a - a_v).max() < 2e-6   # 1.1e-5 deg/h, 9.6e-7 m/s^2
    assert passed == passed_v == passed_c
    bg, ba = _propagated(table, w)
    interp_g = np.array([bg[sel_g[:, i], i].max() for i in range(3)])
    interp_a = np.array([ba[sel_a[:, i], i].max() for i in range(3)])
    assert np.all(np.abs(g - g_c) <= interp_g + second_g) and np.all(np.abs(a - a_c) <= interp_a + second_a)


# ---------------------------------------------------------------------------
# bad input: exit 2, one line, nothing written
# ---------------------------------------------------------------------------


def _newer(tables, tmp_path, fmt):
    if fmt == "json":
        doc = json.loads(tables["json"].read_text())
        doc["version"] = TABLE_VERSION + 1
        p = tmp_path / "newer.json"
        p.write_text(json.dumps(doc))
    else:
        p = tmp_path / "newer.csv"
        p.write_text(tables["csv"].read_text().replace(f"# version = {TABLE_VERSION}\n",
                                                       f"# version = {TABLE_VERSION + 1}\n", 1))
    return p


@pytest.mark.parametrize("case, pattern", [
    ("missing calibration", r"nope\.json: file not found"),
    ("missing experiment", r"nope\.h5: file not found"),
    ("not a result", r"summary\.json: format: is None: not a result file"),
    ("a manifest", r"campaign\.toml: not a result file, a compensation table"),
    ("newer json table", r"newer\.json: version: version 2 is newer than this graph-calib reads \(up to 1\)"),
    ("newer csv table", r"newer\.csv: version: version 2 is newer than this graph-calib reads \(up to 1\)"),
    ("c header", r"table\.h: a C header table is written for an INS, not read back"),
    ("edited unit", r"unit\.json: elements\.gyro\.bias\.x: unit 'deg/h', graph-calib's is 'rad/s'"),
    ("out is the input", r"--out: is the input record"),
    ("solver for a table", r"--solver: --solver and --model choose among a campaign's stitchings"),
])
def test_apply_bad_input(case, pattern, campaign, tables, tmp_path, capsys):
    src = campaign[0] / "sub2_0_10.h5"
    cal = tables["json"]
    out = tmp_path / "out.h5"
    extra = []
    if case == "missing calibration":
        cal = tmp_path / "nope.json"
    elif case == "missing experiment":
        src = tmp_path / "nope.h5"
    elif case == "not a result":
        cal = campaign[1] / "sub2_0_10" / "summary.json"
    elif case == "a manifest":
        cal = campaign[0] / "campaign.toml"
    elif case.startswith("newer"):
        cal = _newer(tables, tmp_path, case.split()[1])
    elif case == "c header":
        cal = tables["c-header"]
    elif case == "edited unit":
        doc = json.loads(tables["json"].read_text())
        doc["elements"]["gyro.bias.x"]["unit"] = "deg/h"
        cal = tmp_path / "unit.json"
        cal.write_text(json.dumps(doc))
    elif case == "out is the input":
        src = tmp_path / "copy.h5"
        shutil.copy(campaign[0] / "sub2_0_10.h5", src)
        out = src
    elif case == "solver for a table":
        extra = ["--solver", "sqrt-kf"]
    before = sorted(p.name for p in tmp_path.iterdir())
    code, _, err = _cli(["apply", cal, src, "--out", out, *extra], capsys)
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert re.search(pattern, err), err
    assert sorted(p.name for p in tmp_path.iterdir()) == before               # nothing written


@pytest.mark.parametrize("case, pattern", [
    ("no campaign", r"campaign\.json: no campaign here"),
    ("newer campaign", r"campaign\.json: version: version 2 is not one this graph-calib reads"),
    ("changed result", r"campaign\.json: stitching\.factor-graph\.elements\.gyro\.bias\.x: the \w+ fit recomputed"),
    ("missing result", r"factor-graph\.json: file not found"),
    ("step", r"--step-degc: must be a positive number of degC"),
    ("solver", r"stitching: no stitching of solver 'sqrt-kf'; the campaign stitched factor-graph"),
])
def test_export_bad_input(case, pattern, campaign, tmp_path, capsys):
    camp = tmp_path / "camp"
    shutil.copytree(campaign[1], camp)
    extra = []
    if case == "no campaign":
        camp = campaign[0]
    elif case == "newer campaign":
        doc = json.loads((camp / "campaign.json").read_text())
        doc["version"] = 2
        (camp / "campaign.json").write_text(json.dumps(doc))
    elif case == "changed result":
        p = camp / "sub3_10_20" / "factor-graph.json"
        doc = json.loads(p.read_text())
        doc["estimates"]["gyro.bias.x"]["value"] += 1e-7
        p.write_text(json.dumps(doc))
    elif case == "missing result":
        (camp / "sub3_10_20" / "factor-graph.json").unlink()
    elif case == "step":
        extra = ["--step-degc", "0"]
    elif case == "solver":
        extra = ["--solver", "sqrt-kf"]
    out = tmp_path / "tables" / "t.json"
    code, _, err = _cli(["export", camp, "--out", out, *extra], capsys)
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert re.search(pattern, err), err
    assert not out.exists()


def test_table_document_refuses_what_it_cannot_evaluate():
    grid = np.array([0.0, 10.0])
    good = CompensationTable(grid, {"gyro.bias.x": TableCurve(np.zeros(2), np.ones(2))}, {})
    doc = good.to_dict()
    assert CompensationTable.from_dict(doc).curves["gyro.bias.x"].values.tolist() == [0.0, 0.0]
    for key, edit, message in [
        ("format", lambda d: d.update(format="imu-calibration-result"), "expected 'imu-compensation-table'"),
        ("sensor", lambda d: d["elements"]["gyro.bias.x"].update(sensor="gyro.y"), "evaluates gyro.bias.x at 'gyro.x'"),
        ("values", lambda d: d["elements"]["gyro.bias.x"].update(values=[0.0]), "1 numbers for a grid of 2"),
        ("grid", lambda d: d.update(grid_degC=[10.0, 0.0]), "strictly increasing"),
        ("tc", lambda d: d["elements"].update({"gyro.bias_tc.x": d["elements"]["gyro.bias.x"]}),
         "not an element of a compensation"),
        ("nan", lambda d: d["elements"]["gyro.bias.x"].update(values=[0.0, float("nan")]), "finite"),
    ]:
        bad = json.loads(json.dumps(doc))
        edit(bad)
        with pytest.raises(io.InputError, match=re.escape(message)):
            CompensationTable.from_dict(bad, path="t.json")


def test_written_tables_are_atomic_and_bench_parameters_stay_out(stitched, tmp_path):
    table = stitched.table(step_degC=2.0)
    p = write_table(table, tmp_path / "t.json")
    doc = json.loads(p.read_text())
    assert set(doc["not_in_table"]) == set(BENCH_PARAMETERS)
    assert doc["interpolation"] == INTERPOLATION and doc["step_degC"] == 2.0
    with pytest.raises(io.InputError):
        write_table(table, tmp_path / "missing-folder" / "t.json")
    assert sorted(x.name for x in tmp_path.iterdir()) == ["t.json"]
    with h5py.File(tmp_path / "x.h5", "w") as f:           # a raw HDF5 file has no provenance attribute
        f.attrs["format"] = "x"
    assert correction_of(tmp_path / "x.h5") is None and PROVENANCE_ATTRIBUTE == "corrected_by"


def test_a_result_of_another_imu_is_not_applied_without_force(campaign, tmp_path, capsys):
    """One unit's errors are not another's: a result names its IMU (imu_id), and apply compares it with the record's."""
    result = campaign[1] / "sub2_0_10" / "factor-graph.json"
    doc = json.loads(result.read_text())
    src = campaign[0] / "sub2_0_10.h5"
    assert doc["imu_id"] == io.read_experiment(src).imu_id
    doc["imu_id"] = "SIM-MEMS 0002"
    other = tmp_path / "other.json"
    other.write_text(json.dumps(doc))
    out = tmp_path / "out.h5"
    code, _, err = _cli(["apply", other, src, "--out", out], capsys)
    assert code == 2 and not out.exists()
    assert (f"sub2_0_10.h5: imu_id: is a record of IMU {doc_id(src)!r}, the calibration is of IMU 'SIM-MEMS 0002': "
            "one unit's errors are not another's (--force applies it anyway)") in err
    code, _, err = _cli(["apply", other, src, "--out", out, "--force"], capsys)
    assert code == 0 and "warning: applied with --force to a record of IMU" in err


def doc_id(path):
    return io.read_experiment(path).imu_id


def test_a_campaign_or_table_of_another_imu_is_not_applied_without_force(campaign, tmp_path, capsys):
    """The same guard for a campaign folder and its table (it read the result's imu_id alone)."""
    src = campaign[0] / "sub2_0_10.h5"
    camp = tmp_path / "camp"
    shutil.copytree(campaign[1], camp)
    doc = json.loads((camp / "campaign.json").read_text())
    doc["imu_id"] = "SIM-MEMS 0002"
    (camp / "campaign.json").write_text(json.dumps(doc))
    table = tmp_path / "t.json"
    assert _cli(["export", camp, "--out", table], capsys)[0] == 0
    for calibration in (camp, table):
        out = tmp_path / "out.h5"
        code, _, err = _cli(["apply", calibration, src, "--out", out], capsys)
        assert code == 2 and not out.exists(), err
        assert "the calibration is of IMU 'SIM-MEMS 0002'" in err


def test_a_record_that_names_no_imu_is_applied_with_a_note(campaign, tmp_path, capsys):
    result = campaign[1] / "sub2_0_10" / "factor-graph.json"
    doc = json.loads(result.read_text())
    doc["imu_id"] = ""
    bare = tmp_path / "bare.json"
    bare.write_text(json.dumps(doc))
    code, _, err = _cli(["apply", bare, campaign[0] / "sub2_0_10.h5", "--out", tmp_path / "o.h5"], capsys)
    assert code == 0 and "note: the calibration name(s) no IMU (imu_id empty)" in err


def test_a_campaign_task_file_carries_its_experiments_verdict(campaign, tmp_path, capsys):
    """A campaign's per-experiment result file holds no verdict (the campaign judges the experiment's solvers
    together): apply and export read the experiment's verdict from campaign.json and refuse a failed one."""
    camp = tmp_path / "camp"
    shutil.copytree(campaign[1], camp)
    doc = json.loads((camp / "campaign.json").read_text())
    entry = next(e for e in doc["experiments"] if e["name"] == "sub2_0_10")
    entry["verdict"] = {**entry["verdict"], "passed": False, "text": "verdict: FAIL: made up for the test"}
    (camp / "campaign.json").write_text(json.dumps(doc))
    result, src, out = camp / "sub2_0_10" / "factor-graph.json", campaign[0] / "sub2_0_10.h5", tmp_path / "o.h5"
    assert "verdict" not in json.loads(result.read_text())
    code, _, err = _cli(["apply", result, src, "--out", out], capsys)
    assert code == 2 and "its verdict failed (verdict: FAIL: made up for the test)" in err and not out.exists()
    code, _, err = _cli(["export", result, "--format", "px4", "--out", tmp_path / "x.params"], capsys)
    assert code == 2 and "made up for the test" in err
    # another experiment of the same campaign passed: applied as before
    assert _cli(["apply", camp / "sub3_10_20" / "factor-graph.json", campaign[0] / "sub3_10_20.h5", "--out", out],
                capsys)[0] == 0


def test_a_task_file_a_re_solve_wave_superseded_is_refused_naming_the_final_one(campaign, tmp_path, capsys):
    """After a pooled wave the experiment's first-wave file stays beside the final one (pooled/<wave>/): apply and
    export named neither and took the first."""
    camp = tmp_path / "camp"
    shutil.copytree(campaign[1], camp)
    final = camp / "sub2_0_10" / "pooled" / "2" / "factor-graph.json"
    final.parent.mkdir(parents=True)
    shutil.copy(camp / "sub2_0_10" / "factor-graph.json", final)
    doc = json.loads((camp / "campaign.json").read_text())
    entry = next(e for e in doc["experiments"] if e["name"] == "sub2_0_10")
    entry["results"]["factor-graph"]["file"] = "sub2_0_10/pooled/2/factor-graph.json"
    (camp / "campaign.json").write_text(json.dumps(doc))
    src, out = campaign[0] / "sub2_0_10.h5", tmp_path / "o.h5"
    code, _, err = _cli(["apply", camp / "sub2_0_10" / "factor-graph.json", src, "--out", out], capsys)
    assert code == 2 and "a re-solve wave of its campaign superseded it" in err and str(final) in err
    code, _, err = _cli(["export", camp / "sub2_0_10" / "factor-graph.json", "--format", "px4", "--out",
                         tmp_path / "x.params"], capsys)
    assert code == 2 and "superseded" in err
    assert _cli(["apply", final, src, "--out", out], capsys)[0] == 0
