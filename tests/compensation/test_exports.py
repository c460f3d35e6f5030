"""``graph-calib export --format px4|ardupilot|kalibr|openvins``: each file evaluated by its consumer's own equation.

The consumers' equations are written here from their documentation (PX4's thermal
compensation, ArduPilot's AP_InertialSensor temperature calibration, Kalibr's
scale-misalignment IMU model, OpenVINS's kalibr intrinsics model), independently of
the writers: parsing the written file, applying the equation to raw readings that the
full model produces, and comparing with the truth.  The error must stay within the loss
the export reports, and the largest error over the reported grid and envelope must be
that loss (a direct evaluation).
"""

from __future__ import annotations

import json
import re
import shutil

import numpy as np
import pytest
import yaml

from graph_calib import cli
from graph_calib import constants as c
from graph_calib.compensation.exports import load_source
from graph_calib.compensation.exports.projection import envelope, grid


def _export(source, fmt, out, capsys, *extra):
    code = cli.main(["export", str(source), "--format", fmt, "--out", str(out), *map(str, extra)])
    text = capsys.readouterr().out
    assert code == 0, text
    m = re.search(r"gyro ([0-9.e+-]+) deg/h .* accel ([0-9.e+-]+) micro-g", text)
    return float(m.group(1)), float(m.group(2)), text


def _raw(source, T, omega, f):
    eg, ea = source.errors(T, omega, f)
    return omega + eg, f + ea


def _grid_signals(source):
    T = grid(source.range_degC)
    omega, f = envelope()
    m = omega.shape[0]
    return np.repeat(T, m), np.tile(omega, (T.size, 1)), np.tile(f, (T.size, 1))


def _worst(dg, da):
    return np.abs(dg).max() * c.RS_TO_DH, np.abs(da).max() * c.MPS2_TO_UG


# ---------------------------------------------------------------------------
# the consumers' equations, from their documentation
# ---------------------------------------------------------------------------

def px4_correct(params, n, T, raw_gyro, raw_accel):
    """PX4: offset = sum_i X_i (clamp(T, TMIN, TMAX) - TREF)^i per axis; corrected = raw - offset."""
    out = []
    for kind, raw in (("G", raw_gyro), ("A", raw_accel)):
        p = {k[len(f"TC_{kind}{n}_"):]: v for k, v in params.items() if k.startswith(f"TC_{kind}{n}_")}
        dT = np.clip(T, p["TMIN"], p["TMAX"]) - p["TREF"]
        offset = np.column_stack([sum(p[f"X{i}_{a}"] * dT ** i for i in range(4)) for a in range(3)])
        out.append(raw - offset)
    return out


def ardupilot_correct(params, n, T, t_cal, offsets, raw_gyro, raw_accel):
    """ArduPilot: v -= p(T - 35) - p(T_cal - 35), p(d) = (c1 + (c2 + c3 d) d) d 1e-6; then the offsets."""
    pre = f"INS_TCAL{n}_"
    lo, hi = params[pre + "TMIN"], params[pre + "TMAX"]
    out = []
    for kind, raw in (("GYR", raw_gyro), ("ACC", raw_accel)):
        cf = np.array([[params[f"{pre}{kind}{i}_{a}"] for a in "XYZ"] for i in (1, 2, 3)])

        def p(d):
            d = np.asarray(d, dtype=float)[:, None]
            return (cf[0] + (cf[1] + cf[2] * d) * d) * d * 1e-6
        d = np.clip(T, lo, hi) - 35.0
        dc = np.full_like(T, np.clip(t_cal, lo, hi) - 35.0)
        out.append(raw - p(d) + p(dc) - offsets[kind])
    return out


def _read_params(path, sep="\t"):
    params = {}
    for line in path.read_text().splitlines():
        if line.startswith("#") or not line.strip():
            continue
        cells = line.split(sep) if sep else line.split()
        name, value = (cells[2], cells[3]) if sep else (cells[0], cells[1])
        params[name] = float(value)
    return params


# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def sources(campaign):
    camp = campaign[1]
    return {"campaign": camp, "result": camp / "sub3_10_20" / "factor-graph.json"}


@pytest.mark.parametrize("which", ["campaign", "result"])
def test_px4_parameters_evaluated_by_px4s_equation(sources, which, tmp_path, capsys):
    src = sources[which]
    loss_g, loss_a, text = _export(src, "px4", tmp_path / "tc.params", capsys, "--gyro-id", 2490378)
    assert "left out:" in text and "gyro.scale" in text
    params = _read_params(tmp_path / "tc.params")
    assert params["TC_G_ENABLE"] == 1 and params["TC_G0_ID"] == 2490378
    source = load_source(src)
    T, omega, f = _grid_signals(source)
    rg, ra = _raw(source, T, omega, f)
    cg, ca = px4_correct(params, 0, T, rg, ra)
    worst_g, worst_a = _worst(cg - omega, ca - f)
    assert worst_g == pytest.approx(loss_g, rel=1e-3) and worst_a == pytest.approx(loss_a, rel=1e-3)
    # off the grid, at random temperatures and signals inside the envelope: within the reported loss
    rng = np.random.default_rng(1)
    n = 500
    T = rng.uniform(*source.range_degC, n)
    omega = rng.normal(size=(n, 3))
    omega *= (rng.uniform(0, 100, n) * c.DEG_TO_RAD / np.linalg.norm(omega, axis=1))[:, None]
    f = rng.normal(size=(n, 3))
    f *= (c.G0 / np.linalg.norm(f, axis=1))[:, None]
    rg, ra = _raw(source, T, omega, f)
    cg, ca = px4_correct(params, 0, T, rg, ra)
    g, a = _worst(cg - omega, ca - f)
    assert g <= loss_g * 1.001 and a <= loss_a * 1.001


def test_px4_holds_the_bias_curve_itself(sources, tmp_path, capsys):
    """At zero rate and zero force the PX4 offsets reproduce the campaign's bias curve to the cubic's fit."""
    _export(sources["campaign"], "px4", tmp_path / "tc.params", capsys)
    params = _read_params(tmp_path / "tc.params")
    source = load_source(sources["campaign"])
    T = np.linspace(*source.range_degC, 30)
    z = np.zeros((T.size, 3))
    bg, ba = source.errors(T, z, z)
    cg, ca = px4_correct(params, 0, T, bg, ba)
    assert np.abs(cg).max() * c.RS_TO_DH < 1e-3 and np.abs(ca).max() * c.MPS2_TO_UG < 1.0


@pytest.mark.parametrize("which", ["campaign", "result"])
def test_ardupilot_parameters_evaluated_by_ardupilots_equation(sources, which, tmp_path, capsys):
    src = sources[which]
    loss_g, loss_a, text = _export(src, "ardupilot", tmp_path / "tcal.parm", capsys)
    params = _read_params(tmp_path / "tcal.parm", sep=None)
    assert params["INS_TCAL1_ENABLE"] == 1
    source = load_source(src)
    t_cal = float(re.search(r"offsets taken as measured at ([0-9.+-]+) degC", text).group(1))
    z = np.zeros((1, 3))
    og, oa = source.errors(np.full(1, t_cal), z, z)        # what ArduPilot measures as offsets at T_cal
    offsets = {"GYR": og[0], "ACC": oa[0]}
    T, omega, f = _grid_signals(source)
    rg, ra = _raw(source, T, omega, f)
    cg, ca = ardupilot_correct(params, 1, T, t_cal, offsets, rg, ra)
    worst_g, worst_a = _worst(cg - omega, ca - f)
    assert worst_g == pytest.approx(loss_g, rel=2e-3) and worst_a == pytest.approx(loss_a, rel=2e-3)


def _kalibr_forward(M_g, C, A, M_a, b_g, b_a, omega_k, f_k):
    """Kalibr's scale-misalignment model: omega_m = M_g C_gyro_i omega + A a + b_g, a_m = M_a a + b_a."""
    return omega_k @ (M_g @ C).T + f_k @ A.T + b_g, f_k @ M_a.T + b_a


@pytest.mark.parametrize("fmt", ["kalibr", "openvins"])
def test_estimator_intrinsics_evaluated_by_their_model(sources, fmt, tmp_path, capsys):
    out = tmp_path / "imu.yaml"
    loss_g, loss_a, text = _export(sources["campaign"], fmt, out, capsys, "--rate-hz", 100)
    body = out.read_text()
    if fmt == "openvins":
        assert body.startswith("%YAML:1.0\n")
        body = body.split("\n", 1)[1]
        doc = yaml.safe_load(body)["imu0"]
        assert doc["model"] == "kalibr" and np.allclose(doc["R_IMUtoACC"], np.eye(3))
        M_g, C, A, M_a = (np.array(doc[k]) for k in ("Tw", "R_IMUtoGYRO", "Tg", "Ta"))
    else:
        doc = yaml.safe_load(body)
        assert doc["model"] == "scale-misalignment"
        M_g, C, A = (np.array(doc["gyroscopes"][k]) for k in ("M", "C_gyro_i", "A"))
        M_a = np.array(doc["accelerometers"]["M"])
    assert doc["update_rate"] == 100.0 and doc["rostopic"] == "/imu0"
    assert np.allclose(np.triu(M_g, 1), 0) and np.allclose(np.triu(M_a, 1), 0)
    assert np.allclose(C @ C.T, np.eye(3), atol=1e-12)
    R = np.array(json.loads(re.search(r"R_body_to_imu = (\[\[.*?\]\])", body).group(1)))
    source = load_source(sources["campaign"])
    T, omega, f = _grid_signals(source)
    rg, ra = _raw(source, T, omega, f)
    z = np.zeros_like(omega)
    bg, ba = source.errors(T, z, z)                       # the estimator's online biases
    pg, pa = _kalibr_forward(M_g, C, A, M_a, bg, ba, omega @ R.T, f @ R.T)
    worst_g, worst_a = _worst(rg - pg, ra - pa)
    assert worst_g == pytest.approx(loss_g, rel=1e-3) and worst_a == pytest.approx(loss_a, rel=1e-3)
    # the estimator's correction (OpenVINS: a = Ta^-1 (a_m - b_a), w = R_IMUtoGYRO^T Tw^-1 (w_m - b_g - Tg a))
    a_hat = (ra - ba) @ np.linalg.inv(M_a).T
    w_hat = (rg - bg - a_hat @ A.T) @ np.linalg.inv(M_g).T @ C
    g, a = _worst(w_hat - omega @ R.T, a_hat - f @ R.T)
    assert g <= loss_g * 1.01 + 1e-9 and a <= loss_a * 1.01 + 1e-6


def test_noise_figures_come_from_the_results_noise_block(sources, tmp_path, capsys):
    res = json.loads(sources["result"].read_text())
    res["noise"].update(gyro_rad_per_sqrt_s=1.5e-6, accel_mps_per_sqrt_s=3.0e-5,
                        gyro_random_walk_rad_per_s_per_sqrt_s=2.0e-8, accel_random_walk_mps2_per_sqrt_s=4.0e-6,
                        source={"gyro": "identified", "accel": "identified"})
    folder = tmp_path / "r"
    folder.mkdir()
    shutil.copy(sources["campaign"].parent / "sim" / res["source"], folder / res["source"])
    (folder / "factor-graph.json").write_text(json.dumps(res))
    _, _, text = _export(folder / "factor-graph.json", "kalibr", tmp_path / "imu.yaml", capsys)
    doc = yaml.safe_load((tmp_path / "imu.yaml").read_text())
    assert doc["gyroscope_noise_density"] == 1.5e-6 and doc["accelerometer_noise_density"] == 3.0e-5
    assert doc["gyroscope_random_walk"] == 2.0e-8 and doc["accelerometer_random_walk"] == 4.0e-6
    assert "note:" not in text
    assert doc["update_rate"] == 100.0          # the calibrated record's rate, found beside the result
    # without the random walks: the grade's figures, said in a note
    del res["noise"]["gyro_random_walk_rad_per_s_per_sqrt_s"]
    (folder / "factor-graph.json").write_text(json.dumps(res))
    _, _, text = _export(folder / "factor-graph.json", "kalibr", tmp_path / "imu2.yaml", capsys)
    assert "note: gyroscope_random_walk: the result has no gyro_random_walk_rad_per_s_per_sqrt_s" in text


@pytest.mark.parametrize("args, pattern", [
    (["--format", "json", "--out", "x.yaml"], r"--out: ends in '\.yaml', the suffix of kalibr or openvins, but the "
                                               r"format is json"),
    (["--out", "x.yaml"], r"--format: a \.yaml file is written by kalibr or openvins: give --format"),
    (["--format", "px4", "--out", "x.parm"], r"the suffix of ardupilot"),
])
def test_export_refuses_a_file_named_for_another_format(sources, tmp_path, capsys, args, pattern):
    argv = ["export", str(sources["campaign"])] + [str(tmp_path / a) if a.startswith("x.") else a for a in args]
    assert cli.main(argv) == 2
    assert re.search(pattern, capsys.readouterr().err)
    assert not list(tmp_path.glob("x.*"))


def test_export_of_a_table_is_refused_naming_the_remedy(sources, tmp_path, capsys):
    table = tmp_path / "t.json"
    assert cli.main(["export", str(sources["campaign"]), "--out", str(table)]) == 0
    assert cli.main(["export", str(table), "--format", "px4", "--out", str(tmp_path / "t.params")]) == 2
    assert "export from the campaign folder or the result file" in capsys.readouterr().err


@pytest.mark.parametrize("fmt", ["json", "csv", "c-header"])
def test_a_table_format_of_a_single_result_names_what_it_needs(sources, tmp_path, capsys, fmt):
    out = tmp_path / f"t.{ {'json': 'json', 'csv': 'csv', 'c-header': 'h'}[fmt] }"
    assert cli.main(["export", str(sources["result"]), "--format", fmt, "--out", str(out)]) == 2
    assert (f"--format: --format {fmt} writes a compensation table over temperature, made from a campaign (its "
            "folder or campaign.json); a single result exports as px4, ardupilot, kalibr, openvins"
            ) in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize("fmt, extra, message", [
    ("px4", ["--instance", "-1"], "--instance: px4 numbers its instances 0 to 3, got -1"),
    ("px4", ["--instance", "4"], "--instance: px4 numbers its instances 0 to 3, got 4"),
    ("ardupilot", ["--instance", "0"], "--instance: ardupilot numbers its instances 1 to 3, got 0"),
    ("kalibr", ["--rate-hz", "nan"], "--rate-hz: must be a positive sample rate in Hz, got nan"),
    ("openvins", ["--rate-hz", "-5"], "--rate-hz: must be a positive sample rate in Hz, got -5.0"),
])
def test_an_instance_or_rate_the_consumer_cannot_take_is_refused(sources, tmp_path, capsys, fmt, extra, message):
    out = tmp_path / {"px4": "x.params", "ardupilot": "x.parm", "kalibr": "x.yaml", "openvins": "x.yaml"}[fmt]
    assert cli.main(["export", str(sources["result"]), "--format", fmt, "--out", str(out), *extra]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_a_table_of_a_campaign_that_failed_its_checks_needs_force(sources, campaign, tmp_path, capsys):
    """json, csv and c-header tabulate the campaign: the same failed-verdict guard as the other formats (they were
    written without a word, and apply then took the table)."""
    import shutil
    camp = tmp_path / "camp"
    shutil.copytree(sources["campaign"], camp)
    doc = json.loads((camp / "campaign.json").read_text())
    doc["verdict"] = {"passed": False, "failed": [], "campaign_checks_failed": ["validation v.h5: not met"]}
    (camp / "campaign.json").write_text(json.dumps(doc))
    out = tmp_path / "t.json"
    assert cli.main(["export", str(camp), "--format", "json", "--out", str(out)]) == 2
    assert ("verdict: its verdict failed (validation v.h5: not met); a table of a campaign that failed its own checks "
            "is not written without --force") in capsys.readouterr().err
    assert not out.exists()
    assert cli.main(["export", str(camp), "--format", "json", "--out", str(out), "--force"]) == 0
    # the table carries the campaign's verdict: apply refuses it as it refuses the campaign
    assert json.loads(out.read_text())["verdict"]["passed"] is False
    record, corrected = campaign[0] / "sub2_0_10.h5", tmp_path / "c.h5"
    capsys.readouterr()
    assert cli.main(["apply", str(out), str(record), "--out", str(corrected)]) == 2
    assert "verdict: its verdict failed (validation v.h5: not met)" in capsys.readouterr().err
    assert not corrected.exists()
    assert cli.main(["apply", str(out), str(record), "--out", str(corrected), "--force"]) == 0


def test_a_failed_result_exported_with_force_says_so_in_its_file(sources, tmp_path, capsys):
    """The file goes to an autopilot: its first line names the failed verdict, and a warning says it."""
    result = tmp_path / "factor-graph.json"
    doc = json.loads(sources["result"].read_text())
    doc["verdict"] = {"passed": False, "text": "verdict: FAIL: made up", "failed": ["made up"]}
    result.write_text(json.dumps(doc))
    out = tmp_path / "x.params"
    assert cli.main(["export", str(result), "--format", "px4", "--out", str(out)]) == 2
    assert cli.main(["export", str(result), "--format", "px4", "--out", str(out), "--force"]) == 0
    captured = capsys.readouterr()
    assert "warning: exporting" in captured.err and "whose verdict failed" in captured.err
    first = out.read_text().splitlines()[0]
    assert first.startswith("# PX4") and "WHOSE VERDICT FAILED" in first and "exported with --force" in first


def test_export_never_writes_over_the_file_it_exports_from(sources, tmp_path, capsys):
    camp = tmp_path / "camp"
    shutil.copytree(sources["campaign"], camp)
    before = (camp / "campaign.json").read_bytes()
    for source in (camp, camp / "campaign.json"):
        assert cli.main(["export", str(source), "--out", str(camp / "campaign.json"), "--force"]) == 2
        assert "--out: is the file being exported from" in capsys.readouterr().err
    assert (camp / "campaign.json").read_bytes() == before


def test_a_prediction_is_not_a_calibration(sources, campaign, tmp_path, capsys):
    pred = tmp_path / "pred.json"
    assert cli.main(["predict", str(campaign[0] / "sub2_0_10.h5"), "--out", str(pred)]) == 0
    capsys.readouterr()
    assert cli.main(["export", str(pred), "--format", "px4", "--out", str(tmp_path / "p.params")]) == 2
    assert "is a prediction (graph-calib predict)" in capsys.readouterr().err
    assert cli.main(["apply", str(pred), str(campaign[0] / "sub2_0_10.h5"), "--out", str(tmp_path / "p.h5")]) == 2
    assert "is a prediction (graph-calib predict)" in capsys.readouterr().err
    assert not (tmp_path / "p.params").exists() and not (tmp_path / "p.h5").exists()


@pytest.mark.parametrize("fmt", ["kalibr", "openvins"])
def test_an_estimator_file_of_a_campaign_names_the_temperature_dependence_it_leaves_out(sources, tmp_path, capsys,
                                                                                       fmt):
    """Its intrinsics are one temperature's: the scale curves' change over the range is named as left out (it said
    'left out: nothing' beside a remaining error that was that change)."""
    out = tmp_path / "imu.yaml"
    *_, text = _export(sources["campaign"], fmt, out, capsys)
    line = next(ln for ln in text.splitlines() if "left out:" in ln)
    assert "over temperature (held at" in line and "accel.scale" in line, line
    assert line.strip() in out.read_text()


def test_a_table_whose_grid_departs_from_the_calibration_is_refused_naming_a_step(sources, tmp_path, capsys):
    """A 100 degC grid put the table 170 sigma off the curves with only a remark; now exit 2 with a step that fits."""
    out = tmp_path / "t.json"
    assert cli.main(["export", str(sources["campaign"]), "--out", str(out), "--step-degc", "100", "--force"]) == 2
    err = capsys.readouterr().err
    m = re.search(r"--step-degc: linear interpolation on a 100 degC grid departs from the calibration by ([0-9.e+]+) "
                  r"sigma .*a step of ([0-9.]+) degC or less keeps it under 0.1 sigma", err)
    assert m and float(m.group(1)) > 1.0 and not out.exists(), err
    assert cli.main(["export", str(sources["campaign"]), "--out", str(out), "--step-degc", m.group(2),
                     "--force"]) == 0
    assert "remark" not in capsys.readouterr().err


def test_an_export_names_the_elements_its_result_holds_at_their_priors(sources, tmp_path, capsys):
    result = tmp_path / "factor-graph.json"
    doc = json.loads(sources["result"].read_text())
    doc["prior_dominated"] = {"gyro.bias_tc.x": 0.9, "accel.bias_tc.y": 0.8}
    result.write_text(json.dumps(doc))
    assert cli.main(["export", str(result), "--format", "px4", "--out", str(tmp_path / "x.params")]) == 0
    assert ("note: 2 element(s) of the result are held by their priors (the record informs little of them; their "
            "values are the priors'): accel.bias_tc.y, gyro.bias_tc.x") in capsys.readouterr().err


def test_an_estimator_export_of_a_campaign_task_takes_the_rate_from_its_summary(sources, tmp_path, capsys):
    """The task's record lives elsewhere; its summary.json beside the result has the rate."""
    folder = tmp_path / "sub3_10_20"
    folder.mkdir()
    for name in ("factor-graph.json", "summary.json"):
        shutil.copy(sources["result"].parent / name, folder / name)
    out = tmp_path / "imu.yaml"
    _export(folder / "factor-graph.json", "kalibr", out, capsys)
    rate = json.loads((folder / "summary.json").read_text())["rate_hz"]
    assert yaml.safe_load(out.read_text())["update_rate"] == rate
