"""Stitching over temperature and validation on a record: exact cases, statistics, the error model."""

import numpy as np
import pytest

from graph_calib import constants as c
from graph_calib.records.experiment import Experiment, Result
from graph_calib.stitching import (
    boundary_temperature,
    family,
    family_z_limit,
    is_stitched,
    sensor_of,
    stitch,
)
from graph_calib.evaluation.validation import (
    ACCEL_ACCURACY_MPS2,
    GYRO_ACCURACY_RADPS,
    ResultCalibration,
    sensor_errors,
    validate,
    window_means,
)

T_REFS = (-5.0, 5.0, 15.0, 25.0, 35.0, 45.0)
HALF_SPAN = 4.0


def _result(t_ref, coefs, covs, *, name="sub"):
    """A result holding, per base element, ``coefs[el] = (value, tc[, tc2])`` with covariance ``covs[el]``."""
    values, names, blocks = {}, [], []
    for el, co in coefs.items():
        base, axis = el.rsplit(".", 1)
        nm = [el] + [f"{base}{suf}.{axis}" for suf in ("_tc", "_tc2")[: len(co) - 1]]
        values.update(dict(zip(nm, co)))
        names += nm
        blocks.append(np.asarray(covs[el], dtype=float))
    n = len(names)
    cov = np.zeros((n, n))
    k = 0
    for b in blocks:
        cov[k:k + b.shape[0], k:k + b.shape[0]] = b
        k += b.shape[0]
    sig = dict(zip(names, np.sqrt(np.diag(cov))))
    effects = tuple(dict.fromkeys(nm.rsplit(".", 1)[0] for nm in names))
    return Result(source=name, solver="factor-graph", t_ref_degC=t_ref,
                  temperature_range_degC=(t_ref - HALF_SPAN, t_ref + HALF_SPAN), effects=effects, values=values,
                  sigmas=sig, covariance_names=tuple(names), covariance=cov)


def _campaign(curve, dcurve, cov, *, rng=None, t_refs=T_REFS, element="gyro.bias.x"):
    out = []
    for t in t_refs:
        y = np.array([curve(t), dcurve(t)])
        if rng is not None:
            y = y + np.linalg.cholesky(cov) @ rng.standard_normal(2)
        out.append(_result(t, {element: y}, {element: cov}, name=f"s{t:g}"))
    return out


def test_names_sensors_families():
    assert sensor_of("gyro.bias.x") == 0 and sensor_of("accel.scale_tc.z") == 5
    assert sensor_of("gyro.misalignment.zx") == 2 and sensor_of("accel.misalignment.yx") == 4
    assert sensor_of("lever_arm.x") is None and sensor_of("time_lag.table") is None
    assert family("gyro.bias") == ("gyro.bias", {1: "gyro.bias_tc", 2: "gyro.bias_tc2", 3: "gyro.bias_tc3",
                                                 4: "gyro.bias_tc4", 5: "gyro.bias_tc5"})
    assert family("accel.scale_tc") == ("accel.scale", {k: "accel.scale_tc" + ("" if k == 1 else str(k))
                                                        for k in range(1, 6)})
    assert is_stitched("gyro.bias") and is_stitched("accel.misalignment")
    assert not is_stitched("gyro.bias_tc") and not is_stitched("mount")


def test_cubic_recovers_a_cubic_exactly():
    p = np.array([1.0e-7, 2.0e-9, -3.0e-11, 4.0e-13])

    def f(t):
        return p[0] + p[1] * t + p[2] * t**2 + p[3] * t**3

    def df(t):
        return p[1] + 2 * p[2] * t + 3 * p[3] * t**2

    cov = np.diag([1e-18, 1e-20])
    st = stitch(_campaign(f, df, cov), names=[f"s{t:g}" for t in T_REFS])
    cv = st.curves["gyro.bias.x"]
    T = np.linspace(-9, 49, 50)
    v, s = cv.evaluate(T, "cubic")
    np.testing.assert_allclose(v, f(T), rtol=0, atol=1e-9 * 1e-7)
    assert cv.fits["cubic"].chi2 < 1e-12 and cv.fits["cubic"].dof == 8
    assert np.all(s > 0)


def test_linear_recovers_a_piecewise_linear_curve_with_knots_at_the_boundaries():
    # knots where the stitch puts them: the ends of the covered range and the boundaries between subranges
    knots = np.array([T_REFS[0] - HALF_SPAN] + [0.5 * (a + b) for a, b in zip(T_REFS[:-1], T_REFS[1:])]
                     + [T_REFS[-1] + HALF_SPAN])
    vals = np.array([3.0, 1.0, 2.0, 2.5, 0.5, -1.0, 0.0]) * 1e-4

    def f(t):
        return np.interp(t, knots, vals)

    def df(t):
        j = np.clip(np.searchsorted(knots, t, side="right") - 1, 0, knots.size - 2)
        return (vals[j + 1] - vals[j]) / (knots[j + 1] - knots[j])

    cov = np.diag([1e-12, 1e-14])
    st = stitch(_campaign(f, df, cov, element="accel.bias.y"), names=[f"s{t:g}" for t in T_REFS])
    cv = st.curves["accel.bias.y"]
    np.testing.assert_allclose(cv.fits["linear"].knots, knots, atol=1e-12)
    T = np.linspace(knots[0], knots[-1], 200)
    np.testing.assert_allclose(cv.evaluate(T, "linear")[0], f(T), atol=1e-12)


def test_boundary_temperature_is_the_middle_of_the_gap():
    pts = stitch(_campaign(lambda t: 0.0 * t, lambda t: 0.0 * t, np.eye(2) * 1e-18),
                 names=[f"s{t:g}" for t in T_REFS]).curves["gyro.bias.x"].points
    assert boundary_temperature(pts[0], pts[1]) == pytest.approx(0.0)
    assert boundary_temperature(pts[3], pts[4]) == pytest.approx(30.0)


def test_bands_are_honest_monte_carlo():
    """Noisy subranges of a quadratic truth: the stitched error over its sigma is about N(0, 1)."""
    rng = np.random.default_rng(7)

    def f(t):
        return 1e-7 + 2e-9 * (t - 20) + 3e-11 * (t - 20) ** 2

    def df(t):
        return 2e-9 + 6e-11 * (t - 20)

    cov = np.array([[4e-18, 5e-20], [5e-20, 4e-21]])  # value and slope correlated
    zs = {"cubic": [], "linear": []}
    bz = []
    T = np.array([-7.0, 2.0, 20.0, 33.0, 48.0])
    for _ in range(300):
        st = stitch(_campaign(f, df, cov, rng=rng), names=[f"s{t:g}" for t in T_REFS])
        cv = st.curves["gyro.bias.x"]
        for m in zs:
            fit = cv.fits[m]
            v, s = fit.evaluate(T)
            # undo the Birge scaling to test the nominal covariance
            zs[m].append((v - f(T)) / (s / max(fit.birge, 1.0)))
        bz += [b.z for b in cv.boundaries]
    z = np.array(zs["cubic"])
    assert 0.85 < np.sqrt(np.mean(z**2)) < 1.15
    zl = np.array(zs["linear"])
    assert np.sqrt(np.mean(zl**2)) < 1.3  # plus the (small) curvature the segments cannot follow
    bz = np.array(bz)
    assert 0.85 < np.sqrt(np.mean(bz**2)) < 1.15


def test_boundary_check_flags_a_jump_and_passes_consistent_lines():
    def f(t):
        return 1e-4 + 2e-6 * t

    def df(t):
        return 2e-6 + 0.0 * t

    cov = np.diag([1e-12, 1e-14])
    res = _campaign(f, df, cov, element="accel.bias.z")
    st = stitch(res, names=[r.source for r in res])
    sm = st.boundary_summary()
    assert sm["consistent"] and sm["max_abs_z"] < 1e-6
    # shift the fourth subrange by 10 sigma
    r = res[3]
    vals = dict(r.values)
    vals["accel.bias.z"] += 1e-5
    res[3] = Result(**{**r.__dict__, "values": vals})
    sm = stitch(res, names=[x.source for x in res]).boundary_summary()
    assert not sm["consistent"]
    assert sm["beyond_limit"] == 2
    flagged = [b for b in sm["boundaries"] if b["beyond_limit"]]
    assert {b["upper"] for b in flagged} | {b["lower"] for b in flagged} >= {res[3].source}


def test_family_limit():
    assert family_z_limit(1) == pytest.approx(3.0)  # never below the per-check limit
    assert family_z_limit(105) == pytest.approx(3.90, abs=0.02)
    assert family_z_limit(1000) > family_z_limit(105)


def test_constant_model_for_parameters_without_a_coefficient():
    res = []
    rng = np.random.default_rng(3)
    for t in T_REFS:
        v = 1e-5 + 1e-7 * rng.standard_normal()
        res.append(_result(t, {"gyro.misalignment.xy": np.array([v])}, {"gyro.misalignment.xy": [[1e-14]]},
                           name=f"s{t:g}"))
    cv = stitch(res, names=[r.source for r in res]).curves["gyro.misalignment.xy"]
    assert not cv.temperature_dependent and cv.default_model == "constant"
    mean = np.mean([r.values["gyro.misalignment.xy"] for r in res])
    v, s = cv.evaluate([0.0, 60.0])
    np.testing.assert_allclose(v, mean, rtol=1e-12)
    assert s[0] == pytest.approx(1e-7 / np.sqrt(6) * max(1.0, cv.fits["constant"].birge), rel=1e-6)
    # the piecewise-linear interpolates and holds the end values outside
    lv, _ = cv.evaluate([T_REFS[0] - 10, T_REFS[2], T_REFS[-1] + 10], "linear")
    np.testing.assert_allclose(lv, [res[0].values["gyro.misalignment.xy"], res[2].values["gyro.misalignment.xy"],
                                    res[-1].values["gyro.misalignment.xy"]], rtol=1e-9)


# ---------------------------------------------------------------------------
# validation
# ---------------------------------------------------------------------------


def test_sensor_errors_match_the_model_equations():
    rng = np.random.default_rng(0)
    vals = {f"gyro.bias.{a}": rng.normal() for a in "xyz"}
    vals.update({f"gyro.scale.{a}": rng.normal() for a in "xyz"})
    vals.update({f"gyro.misalignment.{e}": rng.normal() for e in ("xy", "xz", "yx", "yz", "zx", "zy")})
    vals.update({f"accel.bias.{a}": rng.normal() for a in "xyz"})
    vals.update({f"accel.scale.{a}": rng.normal() for a in "xyz"})
    vals.update({f"accel.misalignment.{e}": rng.normal() for e in ("yx", "zx", "zy")})
    w, f = rng.normal(size=(4, 3)), rng.normal(size=(4, 3))
    eg, ea = sensor_errors(vals, w, f)
    Mg = np.array([[vals["gyro.scale.x"], vals["gyro.misalignment.xy"], vals["gyro.misalignment.xz"]],
                   [vals["gyro.misalignment.yx"], vals["gyro.scale.y"], vals["gyro.misalignment.yz"]],
                   [vals["gyro.misalignment.zx"], vals["gyro.misalignment.zy"], vals["gyro.scale.z"]]])
    Ma = np.array([[vals["accel.scale.x"], 0, 0],
                   [vals["accel.misalignment.yx"], vals["accel.scale.y"], 0],
                   [vals["accel.misalignment.zx"], vals["accel.misalignment.zy"], vals["accel.scale.z"]]])
    bg = np.array([vals[f"gyro.bias.{a}"] for a in "xyz"])
    ba = np.array([vals[f"accel.bias.{a}"] for a in "xyz"])
    np.testing.assert_allclose(eg, bg + w @ Mg.T, rtol=1e-13)
    np.testing.assert_allclose(ea, ba + f @ Ma.T, rtol=1e-13)


def test_result_calibration_uses_coefficients_and_the_truth_remainder():
    truth = Result(source="t", solver="truth", t_ref_degC=20.0, temperature_range_degC=(15, 25),
                   effects=("gyro.bias", "gyro.bias_tc"),
                   values={"gyro.bias.y": 1e-7, "gyro.bias_tc.y": 2e-9},
                   extra={"simulation": {"unmodelled": {"gyro.bias_tc2.y": 3e-11}}})
    T = np.zeros((2, 6))
    T[:, 1] = [20.0, 30.0]
    v = ResultCalibration(truth).evaluate(T)["gyro.bias.y"]
    np.testing.assert_allclose(v, [1e-7, 1e-7 + 2e-8 + 3e-9])


def _static_record(n_windows=40, rate=10.0, T0=0.0, T1=40.0):
    n = int(n_windows * rate)
    t = np.arange(1, n + 1) / rate
    lat = 0.9
    C_nb = np.eye(3)
    w_b = C_nb.T @ c.omega_ie_n(lat)
    g = 9.81
    dtheta = np.tile(w_b / rate, (n, 1))
    dv = np.tile(np.array([0.0, 0.0, g]) / rate, (n, 1))
    dtheta[n // 2: n // 2 + int(5 * rate), 2] += np.radians(10.0) / rate  # a 5 s turn about the vertical
    T = np.linspace(T0, T1, n)[:, None]
    return Experiment(t=t, dtheta=dtheta, dv=dv, temperature=T, temperature_names=("imu",),
                      temperature_map=np.zeros(6, dtype=int), rate_hz=rate, latitude_rad=lat, gravity_mps2=g)


def test_window_means_and_static_windows():
    exp = _static_record()
    w = window_means(exp)
    assert w["omega"].shape == (40, 3)
    np.testing.assert_allclose(w["f"][:, 2], 9.81)
    # the turn about the vertical leaves the accelerometers alone but is not static (nor its neighbours)
    assert not np.any(w["static"][19:26]) and w["static"][:18].all() and w["static"][27:].all()


def test_validation_of_a_calibration_against_itself_is_zero_and_against_a_shifted_one_is_the_shift():
    exp = _static_record()
    truth = Result(source="t", solver="truth", t_ref_degC=20.0, temperature_range_degC=(0, 40),
                   effects=("gyro.bias", "gyro.bias_tc", "gyro.scale", "accel.bias"),
                   values={"gyro.bias.x": 1e-7, "gyro.bias_tc.x": 2e-9, "gyro.scale.z": 1e-5,
                           "accel.bias.y": 1e-4})
    v = validate(exp, ResultCalibration(truth), truth)
    assert np.max(np.abs(v.de_gyro)) < 1e-20 and np.max(np.abs(v.de_accel)) < 1e-20
    s = v.summary()
    assert s["pass"]["all"]
    est = Result(**{**truth.__dict__, "solver": "factor-graph", "sigmas": dict.fromkeys(truth.values, 1e-9),
                    "values": {**truth.values, "gyro.bias.x": 1e-7 + 0.02 * c.DH_TO_RS,
                               "accel.bias.y": 1e-4 + 1e-5}})
    s = validate(exp, ResultCalibration(est), truth).summary()
    assert s["gyro_radps"]["static"]["max"][0] == pytest.approx(0.02 * c.DH_TO_RS, rel=1e-9)
    assert s["accel_mps2"]["all"]["max"][1] == pytest.approx(1e-5, rel=1e-9)
    assert not s["pass"]["gyro"] and s["pass"]["accel"]
    assert GYRO_ACCURACY_RADPS == pytest.approx(0.01 * c.DH_TO_RS) and ACCEL_ACCURACY_MPS2 == 2e-4


def test_values_only_at_constant_temperatures_still_give_a_temperature_model():
    """A traditional calibration (steps at constant temperature, no coefficients): interpolate, fit a cubic."""
    def f(t):
        return 1e-4 + 2e-6 * t - 3e-8 * t**2

    res = []
    for t in (-10.0, 0.0, 10.0, 20.0, 30.0, 40.0, 50.0):
        r = _result(t, {"accel.bias.x": np.array([f(t)])}, {"accel.bias.x": [[1e-14]]}, name=f"s{t:g}")
        res.append(Result(**{**r.__dict__, "temperature_range_degC": (t - 0.1, t + 0.1)}))
    cv = stitch(res, names=[r.source for r in res]).curves["accel.bias.x"]
    assert cv.temperature_dependent and not cv.boundaries
    T = np.array([-10.0, 5.0, 33.0, 50.0])
    np.testing.assert_allclose(cv.evaluate(T, "cubic")[0], f(T), atol=1e-12)
    np.testing.assert_allclose(cv.evaluate([0.0, 10.0], "linear")[0], f(np.array([0.0, 10.0])), atol=1e-15)
