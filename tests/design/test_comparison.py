"""Campaign procedures and their comparison: files, durations, the equal-accuracy interpolation, a small
predicted comparison (noise falls with length, the model error of each temperature model), the command's
refusals."""

import json

import numpy as np
import pytest

from graph_calib.cli import main
from graph_calib.design.comparison import TruthFamily, compare, equal_accuracy_duration
from graph_calib.design.procedures import parse_procedure, read_procedure
from graph_calib.errors import InputError
from graph_calib.model import ModelOptions
from graph_calib.reports.comparison_report import noise_text

STEPS = """format = "graph-calib-procedure"
version = 1
name = "st"
kind = "steps"
temperatures_degC = [0.0, 13.333333333333334, 26.666666666666668, 40.0]
soak_s = 3600.0
lengths_s = [600.0, 1200.0]
"""
RAMP = """format = "graph-calib-procedure"
version = 1
name = "rp"
kind = "ramp"
subranges_degC = [[0.0, 20.0], [20.0, 40.0]]
span_degC = 16.0
lengths_s = [600.0, 1200.0]
"""


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_shipped_procedures_read():
    for n in ("steps", "ramp", "ramp-full", "designed"):
        p = read_procedure(f"data/programs/procedure-{n}.toml")
        assert p.n_experiments in (6, 7)
    st = read_procedure("data/programs/procedure-steps.toml")
    assert st.duration_s(3600.0) == 7 * 3600.0 + 6 * 9000.0
    assert st.duration_s(3600.0, soak_s=3600.0) == 13 * 3600.0
    rp = read_procedure("data/programs/procedure-ramp.toml")
    assert rp.duration_s(3600.0) == 6 * 3600.0 and rp.exclude == ()
    assert "accel.bias_tc" in st.exclude


@pytest.mark.parametrize("edit, key, words", [
    (("graph-calib-procedure", "graph-calib-program"), "format", "not a procedure"),
    (("version = 1", "version = 2"), "version", "not supported"),
    (('kind = "steps"', 'kind = "stairs"'), "kind", "must be one of"),
    (("soak_s = 3600.0", "soak_s = -1.0"), "soak_s", "non-negative"),
    (("soak_s = 3600.0", "soak = 3600.0"), "soak", "unknown key"),
    (("lengths_s = [600.0, 1200.0]", "lengths_s = [100.0]"), "lengths_s", "at least 300 s"),
    (("lengths_s = [600.0, 1200.0]", "lengths_s = [600.0, -1.0]"), "lengths_s[1]", "positive"),
    (("temperatures_degC = [0.0, 13.333333333333334, 26.666666666666668, 40.0]", "temperatures_degC = [0.0]"),
     "temperatures_degC", "at least two"),
    (("temperatures_degC = [0.0, 13.333333333333334, 26.666666666666668, 40.0]", "temperatures_degC = [0.0, 40.0, 0.0]"),
     "temperatures_degC", "0 degC appear(s) more than once"),
    (("soak_s = 3600.0", "soak_s = 3600.0\ndiscarded_s = -5.0"), "discarded_s", "non-negative"),
    (("soak_s = 3600.0", "soak_s = 3600.0\ndiscarded_s = 400.0"), "lengths_s", "after the 400 s discarded"),
])
def test_bad_step_procedure_refused(tmp_path, edit, key, words):
    path = _write(tmp_path, "p.toml", STEPS.replace(*edit))
    with pytest.raises(InputError) as info:
        read_procedure(path)
    msg = str(info.value)
    assert words in msg and key in msg and "p.toml" in msg


@pytest.mark.parametrize("edit, key, words", [
    (("[[0.0, 20.0], [20.0, 40.0]]", "[[0.0, 20.0], [30.0, 20.0]]"), "subranges_degC[1]", "low < high"),
    (("span_degC = 16.0", "span_degC = 25.0"), "span_degC", "narrowest subrange"),
    (("[[0.0, 20.0], [20.0, 40.0]]", "[[0.0, 20.0], [0.0, 20.0]]"), "subranges_degC[1]", "more than once"),
    (('kind = "ramp"', 'kind = "program"'), "lengths_s", "unknown key"),
])
def test_bad_ramp_procedure_refused(tmp_path, edit, key, words):
    path = _write(tmp_path, "r.toml", RAMP.replace(*edit))
    with pytest.raises(InputError) as info:
        read_procedure(path)
    msg = str(info.value)
    assert words in msg and key in msg and "r.toml" in msg


def test_program_procedure_needs_its_program(tmp_path):
    doc = {"format": "graph-calib-procedure", "version": 1, "kind": "program", "subranges_degC": [[0.0, 10.0]]}
    with pytest.raises(InputError, match="program: must name a bench program"):
        parse_procedure(doc, path=tmp_path / "x.toml")
    doc["program"] = "missing.toml"
    with pytest.raises(InputError, match="missing.toml: no such file"):
        parse_procedure(doc, path=tmp_path / "x.toml")


def test_equal_accuracy_duration_on_a_power_law():
    d = np.array([1.0, 2.0, 4.0, 8.0])
    v = 3.0 / np.sqrt(d)
    dur, status = equal_accuracy_duration(3.0 / np.sqrt(3.0), d, v)
    assert status == "interpolated" and abs(dur - 3.0) < 1e-12
    assert equal_accuracy_duration(5.0, d, v) == (1.0, "below")
    dur, status = equal_accuracy_duration(3.0 / np.sqrt(20.0), d, v)
    assert status == "extrapolated" and abs(dur - 20.0) < 1e-9
    assert equal_accuracy_duration(3.0 / np.sqrt(100.0), d, v) == (None, "not reached")


def test_truth_family_sizes():
    t = TruthFamily().draw(np.random.default_rng(0), 200, center_degC=20.0, half_width_degC=30.0)
    c = t["accel.scale.x"]
    end = np.abs(c[:, 1] * 30.0**2) + 0.0
    assert 1e-6 <= end.min() and end.max() <= 4e-6            # the quadratic term's size at the range's end
    assert set(np.sign(t["gyro.bias.y"][:, 2])) == {-1.0, 1.0}


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    d = tmp_path_factory.mktemp("cmp")
    procs = [read_procedure(_write(d, "st.toml", STEPS)), read_procedure(_write(d, "rp.toml", RAMP))]
    return compare(procs, range_degC=(0.0, 40.0), draws=6, seed=3)


def test_predicted_noise_falls_with_length(small):
    for name in ("st", "rp"):
        a, b = small.points[name]
        for f in ("gyro.bias", "accel.bias"):
            assert b.metrics[f]["largest_sigma"] < 0.85 * a.metrics[f]["largest_sigma"]


def test_model_error_of_each_temperature_model(small):
    # four steps fix the cubic exactly: no model error; a linear model per 20 degC subrange leaves one
    for pt in small.points["st"]:
        for f in ("gyro.bias", "accel.bias", "gyro.scale", "accel.scale"):
            assert pt.metrics[f]["model_error_largest"] < 1e-6 * pt.metrics[f]["largest_sigma"] + 1e-15
    rp = small.points["rp"][0].metrics["accel.bias"]
    assert rp["model_error_largest"] > 0.5e-6                    # m/s^2: curvature inside 20 degC subranges
    assert rp["largest_total"] >= rp["largest_sigma"]


def test_ratios_follow_the_durations(small):
    rows = small.ratios["rp"]["3600"]["gyro.bias"]["rms_sigma"]
    for r in rows:
        if r["ratio"] is not None:
            assert abs(r["ratio"] - r["duration_s"] / r["reference_duration_s"]) < 1e-12
    doc = small.to_dict()
    json.dumps(doc)
    assert doc["campaigns"]["st"][0]["duration_s"]["3600"] == 4 * 600.0 + 3 * 3600.0


@pytest.mark.parametrize("argv, key, words", [
    (["P1"], "PROCEDURE.toml", "at least two procedures"),
    (["P1", "P2", "--soak-h", "-1"], "--soak-h", "non-negative"),
    (["P1", "P2", "--range-degc", "50", "-10"], "--range-degc", "LOW < HIGH"),
    (["P1", "P2", "--draws", "0"], "--draws", "at least 1"),
    (["P1", "P2", "--simulate", "3"], "--simulate-at", "name the campaigns"),
    (["P1", "P2", "--simulate", "3", "--simulate-at", "st"], "--simulate-at", "NAME:HOURS"),
    (["P1", "P2", "--simulate", "3", "--simulate-at", "xx:0.25"], "--simulate-at", "no procedure named 'xx'"),
    (["P1", "P2", "--simulate", "3", "--simulate-at", "st:0.3"], "--simulate-at", "not one of its lengths"),
    (["P1", "P1"], "PROCEDURE.toml", "names must be unique"),
    (["P1", "P2", "--accel-noise", "0"], "--accel-noise", "positive number"),
    (["P1", "P2", "--gyro-noise", "nan"], "--gyro-noise", "positive number"),
    (["P1", "P2", "--accel-noise", "2e-4", "--simulate", "3", "--simulate-at", "st:600"], "--simulate",
     "simulates the navigation grade's noise"),
    (["P1", "P2", "--grade", "tactical", "--simulate", "3", "--simulate-at", "st:600"], "--simulate",
     "simulates the navigation grade's noise"),
])
def test_compare_command_refuses_bad_input(tmp_path, capsys, argv, key, words):
    p1, p2 = _write(tmp_path, "st.toml", STEPS), _write(tmp_path, "rp.toml", RAMP)
    out = tmp_path / "out"
    args = [{"P1": str(p1), "P2": str(p2)}.get(a, a) for a in argv]
    assert main(["compare", *args, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert key in err and words in err and not out.exists()


def test_noise_options_set_the_compared_imu(tmp_path, small):
    """The accelerometer density given scales the accelerometer-bias sigmas (white noise: less than
    proportionally, the attitude shares the information) and barely moves the gyro's; the comparison states
    the densities it used."""
    procs = [read_procedure(_write(tmp_path, "st.toml", STEPS)), read_procedure(_write(tmp_path, "rp.toml", RAMP))]
    base = small.to_dict()["noise"]
    assert base["grade"] == "navigation" and base["given"] == []
    noisy = compare(procs, range_degC=(0.0, 40.0), draws=6, seed=3,
                    model=ModelOptions(accel_noise=4.0 * base["accel_noise"]))
    doc = noisy.to_dict()
    assert doc["noise"]["accel_noise"] == pytest.approx(4.0 * base["accel_noise"]) and doc["noise"]["given"] == [
        "accel_noise"]
    assert doc["noise"]["gyro_noise"] == pytest.approx(base["gyro_noise"])
    for name in ("st", "rp"):
        for a, b in zip(small.points[name], noisy.points[name]):
            k = b.metrics["accel.bias"]["largest_sigma"] / a.metrics["accel.bias"]["largest_sigma"]
            assert 2.0 < k <= 4.0 + 1e-9, (name, k)
            g = b.metrics["gyro.bias"]["largest_sigma"] / a.metrics["gyro.bias"]["largest_sigma"]
            assert abs(g - 1.0) < 0.1, (name, g)
    assert "accelerometer 8.16 micro-g/sqrt(Hz)" in noise_text(doc["noise"])


def test_discarded_start_counts_in_the_duration_not_the_data(tmp_path, small):
    """A step procedure that discards 300 s of its 1200 s steps predicts what 900 s steps predict, and its
    durations are the 1200 s steps'."""
    disc = read_procedure(_write(tmp_path, "d.toml", STEPS.replace("lengths_s = [600.0, 1200.0]",
                                                                   "lengths_s = [1200.0]\ndiscarded_s = 300.0")))
    short = read_procedure(_write(tmp_path, "s.toml", STEPS.replace("lengths_s = [600.0, 1200.0]",
                                                                    "lengths_s = [900.0]")))
    assert disc.duration_s(1200.0) == 4 * 1200.0 + 3 * 3600.0 and disc.to_dict()["discarded_s"] == 300.0
    rp = read_procedure(_write(tmp_path, "rp.toml", RAMP))
    a = compare([disc, rp], range_degC=(0.0, 40.0), draws=2, seed=3).points["st"][0].metrics
    b = compare([short, rp], range_degC=(0.0, 40.0), draws=2, seed=3).points["st"][0].metrics
    for f in ("gyro.bias", "accel.bias", "gyro.scale", "accel.scale"):
        assert a[f]["largest_sigma"] == pytest.approx(b[f]["largest_sigma"], rel=1e-12)


def test_report_and_study_page(small, tmp_path):
    from graph_calib.reports.comparison_report import comparison_report_html
    from graph_calib.reports.comparison_study import comparison_markdown

    doc = small.to_dict()
    html = comparison_report_html(doc, small)
    assert html.count("<img") == 4 and "Equal-accuracy ratios" in html
    # one self-contained file: every figure embedded, nothing to fetch when it opens in a browser
    assert html.count('src="data:image/png;base64,') == 4 and "http" not in html.replace("http-equiv", "")
    page = tmp_path / "study.md"
    text = comparison_markdown(doc, small, path=page, command="graph-calib compare st.toml rp.toml", closing="## Notes")
    assert page.read_text() == text and text.rstrip().endswith("## Notes")
    for name in ("study_accuracy.png", "study_accuracy_total.png", "study_ratios.png", "study_curves.png"):
        assert (tmp_path / "figures" / name).stat().st_size > 1000
    # every soak and family says where the candidate needs at most half and where not
    assert sum("rp, soak 1 h, gyro.bias:" in line for line in text.splitlines()) == 2


def _fake_metrics(small, scale, node_shape=(1.0, 1.0, 1.0, 1.0)):
    """``simulated_metrics`` stand-in for 16 realisations: errors whose sample covariance at the nodes is exactly
    ``scale^2`` times the predicted joint one (12 orthogonal columns of a 16 x 16 Hadamard matrix on a square
    root of it), optionally bent node by node."""
    from scipy.linalg import hadamard

    z = hadamard(16)[:, 1:13].astype(float)

    def fake(procedure, length_s, **kw):
        pt = next(p for p in small.points[procedure.name] if p.length_s == length_s)
        k = scale(procedure.name) if callable(scale) else scale
        out = {"failed": []}
        R = kw["realisations"]
        assert R == 16
        for f, m in pt.metrics.items():
            w, V = np.linalg.eigh(pt.node_covariance[f])
            e = (z @ (V * np.sqrt(np.clip(w, 0, None))).T).reshape(R, 3, 4)
            e = k * e * np.asarray(node_shape)
            out[f] = {"largest_sigma": m["largest_sigma"] * k, "sigma_axes": pt.sigma_axes[f] * k,
                      "rms_sigma": m["rms_sigma"] * k, "realisations": R, "node_errors": e}
        # every experiment's estimates with exactly the predicted covariance times k^2 (Hadamard columns again)
        names, C = pt.experiment_covariance
        rows = R * procedure.n_experiments
        zz = hadamard(rows)[:, 1:len(names) + 1].astype(float)
        w, V = np.linalg.eigh(C)
        X = k * zz @ (V * np.sqrt(np.clip(w, 0, None))).T
        out["estimates"] = [dict(zip(names, x)) for x in X]
        return out
    return fake


def test_node_covariance_is_the_stitched_curves(small):
    # the joint covariance's per-axis blocks are the stitched curves' own covariance at the nodes
    from graph_calib.design.comparison import check_nodes

    pt = small.points["rp"][0]
    nodes = check_nodes(small.range_degC)
    C = pt.node_covariance["gyro.bias"]
    assert C.shape == (12, 12) and np.all(np.linalg.eigvalsh(C) > -1e-12 * np.max(np.diag(C)))
    grid_sigma = pt.sigma_axes["gyro.bias"]
    for i in range(3):
        s_nodes = np.sqrt(np.diag(C)[4 * i:4 * i + 4])
        s_grid = np.interp(nodes, small.grid_degC, grid_sigma[i])
        assert np.allclose(s_nodes, s_grid, rtol=0.02), (i, s_nodes, s_grid)


def test_whitened_scale_has_its_stated_spread():
    from graph_calib.design.comparison_check import whitened_scale

    rng = np.random.default_rng(5)
    A = rng.normal(size=(12, 12))
    cov = A @ A.T + 0.1 * np.eye(12)                       # axes correlated
    L = np.linalg.cholesky(cov)
    scales, shapes = [], []
    for _ in range(400):
        e = (rng.standard_normal((10, 12)) @ L.T).reshape(10, 3, 4)
        ws = whitened_scale(e, cov)
        scales.append(ws["scale"])
        shapes.append(ws["shape_ok"])
    assert ws["dof"] == 120 and abs(ws["relative_se"] - 1 / np.sqrt(240)) < 1e-12
    assert abs(np.mean(scales) - 1.0) < 0.01 and abs(np.std(scales) / ws["relative_se"] - 1.0) < 0.15
    inside = np.mean([(ws["band"][0] <= s <= ws["band"][1]) for s in scales])
    assert 0.92 <= inside <= 0.98
    assert np.mean(shapes) >= 0.97                         # the node tests' false alarms at alpha = 1 %
    # one node's errors doubled (a stitching that bends the curve at one end): the shape test fails
    e = (rng.standard_normal((10, 12)) @ L.T).reshape(10, 3, 4)
    bent = e.copy()
    bent[..., 3] *= 2.0
    assert whitened_scale(e, cov)["shape_ok"] and not whitened_scale(bent, cov)["shape_ok"]


def test_simulated_check_fails_in_words_when_it_disagrees(small, monkeypatch, tmp_path):
    from graph_calib.design import comparison_check as cc

    # the candidate's simulated sigma far off
    monkeypatch.setattr(cc, "simulated_metrics", _fake_metrics(small, lambda name: 1.0 if name == "st" else 1.6))
    sc = cc.simulated_check(small, lengths={"st": [600.0], "rp": [600.0, 1200.0]}, realisations=16, work=tmp_path)
    assert not sc["verdict"]["passed"] and sc["verdict"]["text"].startswith("verdict: FAIL: ")
    assert "simulated ratio" in sc["verdict"]["text"]
    assert sc["campaigns"]["rp"]["600"]["gyro.bias"]["whitened"]["scale"] == pytest.approx(1.6)
    assert sc["campaigns"]["rp"]["600"]["gyro.bias"]["experiment"]["scale"] == pytest.approx(1.6)
    assert sc["campaigns"]["st"]["600"]["accel.bias"]["experiment"]["scale"] == pytest.approx(1.0)
    # the same scale everywhere: the ratios agree exactly and the check passes, with its standard errors
    monkeypatch.setattr(cc, "simulated_metrics", _fake_metrics(small, 0.9))
    sc = cc.simulated_check(small, lengths={"st": [600.0], "rp": [600.0, 1200.0]}, realisations=16, work=tmp_path)
    assert sc["verdict"]["passed"], sc["verdict"]["text"]
    rows = [r for f in ("gyro.bias", "accel.bias") for m in ("largest_sigma", "rms_sigma")
            for r in sc["ratios"][f][m] if r["agreement"] is not None]
    assert rows and all(abs(r["agreement"] - 1.0) < 1e-9 and 0.02 < r["relative_se"] < 0.5 for r in rows)
    # the right scale but the curve bent at one end of the range: the shape test fails in words
    monkeypatch.setattr(cc, "simulated_metrics", _fake_metrics(small, 1.0, node_shape=(1.0, 1.0, 1.0, 1.8)))
    sc = cc.simulated_check(small, lengths={"st": [600.0], "rp": [600.0, 1200.0]}, realisations=16, work=tmp_path)
    assert not sc["verdict"]["passed"] and "shape over temperature is not the predicted one" in sc["verdict"]["text"]
    # the report and the study page show the check: its scales, the node shape and the judged ratios
    from graph_calib.reports.comparison_report import comparison_report_html
    from graph_calib.reports.comparison_study import comparison_markdown

    doc = {**small.to_dict(), "simulated_check": sc}
    json.dumps(doc)
    html = comparison_report_html(doc, small)
    assert "scale at the nodes" in html and "standard error" in html
    text = comparison_markdown(doc, small, path=tmp_path / "study.md", command="graph-calib compare")
    assert "shape over temperature is not the predicted one" in text and "scale at the four nodes" in text
