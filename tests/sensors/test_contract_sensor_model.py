"""``sensor_model.measure`` against the equations of ``shared/spec/model.md``, written out by hand.

The simulator and both solvers share ``sensor_model``; a convention swapped inside it (say
``gyro.misalignment.xy`` read as row y, column x) would pass every test that checks code
against code.  Here every expected value is built with numpy from the spec's text only:
no call to ``correct``, no use of ``term_rows``, index conventions typed in from the spec's
tables.  Where an element's index is the point, one element at a time is nonzero.

model.md (declared model, rate form)::

    omega_meas = (I + diag(gyro.scale + gyro.scale_tc dT) + M_g) @ omega_ib_b + gyro.bias + gyro.bias_tc dT
    f_meas     = (I + diag(accel.scale + accel.scale_tc dT) + M_a) @ f_b + accel.bias + accel.bias_tc dT

``M_g[i, j]`` = ``gyro.misalignment.ij`` (row i, column j); ``M_a`` strictly lower-triangular.
``measure``'s documented context: ``dT``, ``dTdt`` of the triad's own three sensors (column i for
axis i); ``other`` = true ``f_b`` for the gyros (``g_sensitivity``) and true ``omega_nb_b`` for the
accelerometers (``size_effect``); ``domega`` the angular acceleration; ``dsignal`` ``d signal/dt``.
"""

import numpy as np
import pytest

from graph_calib.sensors.effects import DECLARED, FURTHER_EFFECTS
from graph_calib.sensors.params import Layout
from graph_calib.sensors.sensor_model import measure

N = 64
TOL = 1e-12  # absolute; signals are O(1-10), effects O(1e-3)
AXIS = {"x": 0, "y": 1, "z": 2}

# Index conventions typed in from model.md (not derived from the code's parsing)
GYRO_MISALIGNMENT = {"xy": (0, 1), "xz": (0, 2), "yx": (1, 0), "yz": (1, 2), "zx": (2, 0), "zy": (2, 1)}
ACCEL_MISALIGNMENT = {"yx": (1, 0), "zx": (2, 0), "zy": (2, 1)}
NINE = {"xx": (0, 0), "xy": (0, 1), "xz": (0, 2), "yx": (1, 0), "yy": (1, 1), "yz": (1, 2),
        "zx": (2, 0), "zy": (2, 1), "zz": (2, 2)}
# accel.size_effect: element "ac" is component c of the offset d_a of accel a
SIZE = {"yx": (1, 0), "yy": (1, 1), "yz": (1, 2), "zx": (2, 0), "zy": (2, 1), "zz": (2, 2)}


def _context(seed, triad):
    """Random signal and context; every column different so that an axis swap shows."""
    rng = np.random.default_rng(seed)
    if triad == "gyro":
        signal = rng.uniform(-1.0, 1.0, (N, 3))                    # rad/s, both signs on every axis
    else:
        signal = np.array([0.5, -0.3, 9.8]) + rng.uniform(-3.0, 3.0, (N, 3))   # m/s^2
    signal[:N // 2] *= -1.0
    ctx = {
        "dT": np.array([-4.0, 1.5, 3.0]) + rng.uniform(-1.0, 1.0, (N, 3)),        # degC, per sensor
        "dTdt": np.array([2e-3, -1e-3, 5e-3]) + rng.uniform(-1e-3, 1e-3, (N, 3)),  # degC/s
        "other": rng.uniform(-2.0, 2.0, (N, 3)) + (np.array([0.3, -0.2, 9.8]) if triad == "gyro" else 0.0),
        "domega": rng.uniform(-1.5, 1.5, (N, 3)),                                # rad/s^2
        "dsignal": rng.uniform(-5.0, 5.0, (N, 3)),
    }
    return signal, ctx


def _measure(layout, x, triad, signal, ctx):
    return measure(layout, x, triad, signal, dT=ctx["dT"], dTdt=ctx["dTdt"], other=ctx["other"],
                   domega=ctx["domega"], dsignal=ctx["dsignal"])


def _declared_by_hand(layout, x, triad, signal, dT):
    """model.md's declared equation for one triad, sample by sample."""
    v = layout.to_dict(x)
    p = lambda name: np.array([v[f"{triad}.{name}.{a}"] for a in "xyz"])
    M = np.zeros((3, 3))
    for el, (i, j) in (GYRO_MISALIGNMENT if triad == "gyro" else ACCEL_MISALIGNMENT).items():
        M[i, j] = v[f"{triad}.misalignment.{el}"]
    out = np.empty_like(signal)
    for k in range(signal.shape[0]):
        A = np.eye(3) + np.diag(p("scale") + p("scale_tc") * dT[k]) + M
        out[k] = A @ signal[k] + p("bias") + p("bias_tc") * dT[k]
    return out


def _check(actual, expected):
    np.testing.assert_allclose(actual, expected, rtol=0, atol=TOL)


# ---------------------------------------------------------------------------
# the declared model
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("triad", ["gyro", "accel"])
def test_declared_model_all_parameters_at_once(triad):
    layout = Layout.declared()
    rng = np.random.default_rng(101)
    x = rng.uniform(-1e-3, 1e-3, layout.size)
    signal, ctx = _context(102, triad)
    expected = _declared_by_hand(layout, x, triad, signal, ctx["dT"])
    _check(_measure(layout, x, triad, signal, ctx), expected)
    # the model is an error model: zero parameters measure the truth
    _check(_measure(layout, layout.zeros(), triad, signal, ctx), signal)


@pytest.mark.parametrize("element", sorted(GYRO_MISALIGNMENT))
def test_gyro_misalignment_is_row_then_column(element):
    """``gyro.misalignment.ij`` is M_g[i, j]: gyro i sees rate about axis j (``xy`` -> M_g[0, 1])."""
    layout = Layout.declared()
    signal, ctx = _context(200 + sorted(GYRO_MISALIGNMENT).index(element), "gyro")
    p = np.random.default_rng(7).uniform(1e-3, 2e-3)
    x = layout.zeros()
    x[layout.index(f"gyro.misalignment.{element}")] = p
    M = np.zeros((3, 3))
    M[GYRO_MISALIGNMENT[element]] = p
    _check(_measure(layout, x, "gyro", signal, ctx), signal + signal @ M.T)


@pytest.mark.parametrize("element", sorted(ACCEL_MISALIGNMENT))
def test_accel_misalignment_is_strictly_lower_triangular(element):
    layout = Layout.declared()
    signal, ctx = _context(300 + sorted(ACCEL_MISALIGNMENT).index(element), "accel")
    p = np.random.default_rng(8).uniform(1e-3, 2e-3)
    x = layout.zeros()
    x[layout.index(f"accel.misalignment.{element}")] = p
    M = np.zeros((3, 3))
    M[ACCEL_MISALIGNMENT[element]] = p
    assert np.all(np.triu(M) == 0.0)
    _check(_measure(layout, x, "accel", signal, ctx), signal + signal @ M.T)


def test_accel_misalignment_has_only_the_three_lower_elements():
    layout = Layout.declared()
    s = layout.slice("accel.misalignment")
    assert s.stop - s.start == 3
    for upper in ("xy", "xz", "yz"):
        with pytest.raises(KeyError):
            layout.index(f"accel.misalignment.{upper}")


@pytest.mark.parametrize("triad", ["gyro", "accel"])
@pytest.mark.parametrize("name", ["bias", "bias_tc", "scale", "scale_tc"])
@pytest.mark.parametrize("axis", "xyz")
def test_per_axis_declared_terms_one_element_at_a_time(triad, name, axis):
    """Element ``a`` acts on sensor ``a`` only, with the temperature of sensor ``a`` (column a of dT)."""
    layout = Layout.declared()
    i = AXIS[axis]
    signal, ctx = _context(400 + i, triad)
    p = 1.3e-3
    x = layout.zeros()
    x[layout.index(f"{triad}.{name}.{axis}")] = p
    dT = ctx["dT"][:, i]
    extra = {"bias": p, "bias_tc": p * dT, "scale": p * signal[:, i], "scale_tc": p * dT * signal[:, i]}[name]
    expected = signal.copy()
    expected[:, i] += extra
    _check(_measure(layout, x, triad, signal, ctx), expected)


@pytest.mark.parametrize("triad", ["gyro", "accel"])
def test_one_triad_parameters_do_not_touch_the_other_triad(triad):
    other_triad = "accel" if triad == "gyro" else "gyro"
    layout = Layout.declared(extra=FURTHER_EFFECTS)
    x = layout.zeros()
    for name in layout.names:
        if name.startswith(other_triad + ".") or name == "time_lag.accel" and triad == "gyro":
            x[layout.slice(name)] = 1e-3
    signal, ctx = _context(500, triad)
    _check(_measure(layout, x, triad, signal, ctx), signal)


@pytest.mark.parametrize("triad", ["gyro", "accel"])
def test_mounting_lever_arm_table_lag_and_damping_are_not_sensor_errors(triad):
    """``mount``, ``lever_arm``, ``time_lag.table`` enter the motion and the encoders, not the sensor outputs;
    ``damping.stiffness`` tilts the whole block (docs/model.md): none changes what ``measure`` adds."""
    layout = Layout.declared(extra=("damping.stiffness",))
    x = layout.zeros()
    for name in ("mount", "lever_arm", "time_lag.table", "damping.stiffness"):
        x[layout.slice(name)] = 1e-2
    signal, ctx = _context(510, triad)
    _check(_measure(layout, x, triad, signal, ctx), signal)


# ---------------------------------------------------------------------------
# further effects, each with model.md's equation
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("triad", ["gyro", "accel"])
@pytest.mark.parametrize("name", ["bias_tc2", "scale_tc2", "bias_dtdt", "bias_tc3"])
@pytest.mark.parametrize("axis", "xyz")
def test_temperature_effects(triad, name, axis):
    """bias_tc2: ``p dT^2``; scale_tc2: scale error ``p dT^2``; bias_dtdt: ``p dT/dt`` (sensor ``a``'s own);
    bias_tc3 (the project's cubic term, docs/model.md): ``p dT^3``."""
    layout = Layout.declared(extra=(f"{triad}.{name}",))
    i = AXIS[axis]
    signal, ctx = _context(600 + i, triad)
    p = 2.1e-3
    x = layout.zeros()
    x[layout.index(f"{triad}.{name}.{axis}")] = p
    dT, dTdt = ctx["dT"][:, i], ctx["dTdt"][:, i]
    extra = {"bias_tc2": p * dT**2, "scale_tc2": p * dT**2 * signal[:, i], "bias_dtdt": p * dTdt,
             "bias_tc3": p * dT**3}[name]
    expected = signal.copy()
    expected[:, i] += extra
    _check(_measure(layout, x, triad, signal, ctx), expected)


@pytest.mark.parametrize("axis", "xyz")
def test_gyro_scale_asymmetry(axis):
    """Gyro ``i``'s scale error gains ``p_i sign(omega_i)``: output gains ``p_i sign(omega_i) omega_i``."""
    layout = Layout.declared(extra=("gyro.scale_asym",))
    i = AXIS[axis]
    signal, ctx = _context(700 + i, "gyro")
    assert np.any(signal[:, i] > 0) and np.any(signal[:, i] < 0)
    p = 1.7e-3
    x = layout.zeros()
    x[layout.index(f"gyro.scale_asym.{axis}")] = p
    expected = signal.copy()
    expected[:, i] += p * np.sign(signal[:, i]) * signal[:, i]
    _check(_measure(layout, x, "gyro", signal, ctx), expected)


@pytest.mark.parametrize("element", sorted(NINE))
def test_gyro_g_sensitivity_is_G_times_specific_force(element):
    """Gyro bias gains ``G @ f_b`` with ``G[i, j]`` = element ``ij``; ``f_b`` is ``measure``'s ``other``."""
    layout = Layout.declared(extra=("gyro.g_sensitivity",))
    signal, ctx = _context(800 + sorted(NINE).index(element), "gyro")
    G = np.zeros((3, 3))
    G[NINE[element]] = 3.1e-4
    x = layout.zeros()
    x[layout.index(f"gyro.g_sensitivity.{element}")] = G[NINE[element]]
    f_b = ctx["other"]
    _check(_measure(layout, x, "gyro", signal, ctx), signal + f_b @ G.T)


@pytest.mark.parametrize("axis", "xyz")
def test_accel_nonlinearity(axis):
    """Accel ``i``'s output gains ``p_i f_i^2``."""
    layout = Layout.declared(extra=("accel.nonlinearity",))
    i = AXIS[axis]
    signal, ctx = _context(900 + i, "accel")
    p = 2.3e-5
    x = layout.zeros()
    x[layout.index(f"accel.nonlinearity.{axis}")] = p
    expected = signal.copy()
    expected[:, i] += p * signal[:, i] ** 2
    _check(_measure(layout, x, "accel", signal, ctx), expected)


def _extra_specific_force(w, dw, d):
    """Specific force of a point offset by ``d`` (in b) on a rigid body turning at ``w`` with ``w' = dw``."""
    return np.cross(dw, d) + np.cross(w, np.cross(w, d))


@pytest.mark.parametrize("element", sorted(SIZE))
def test_accel_size_effect_one_offset_component(element):
    """Accel y (z) sits at ``lever_arm + d_y`` (``+ d_z``): it gains that axis's component of
    ``w' x d + w x (w x d)`` (``w`` = ``omega_nb_b``, ``measure``'s ``other``); accel x sits at the lever arm."""
    layout = Layout.declared(extra=("accel.size_effect",))
    signal, ctx = _context(1000 + sorted(SIZE).index(element), "accel")
    sensor, comp = SIZE[element]
    d = np.zeros(3)
    d[comp] = 0.013  # m
    x = layout.zeros()
    x[layout.index(f"accel.size_effect.{element}")] = d[comp]
    expected = signal.copy()
    expected[:, sensor] += _extra_specific_force(ctx["other"], ctx["domega"], d)[:, sensor]
    _check(_measure(layout, x, "accel", signal, ctx), expected)


def test_accel_size_effect_both_offsets():
    layout = Layout.declared(extra=("accel.size_effect",))
    signal, ctx = _context(1100, "accel")
    rng = np.random.default_rng(1101)
    d_y, d_z = rng.uniform(-0.02, 0.02, 3), rng.uniform(-0.02, 0.02, 3)
    x = layout.from_dict({**{f"accel.size_effect.y{c}": d_y[k] for k, c in enumerate("xyz")},
                          **{f"accel.size_effect.z{c}": d_z[k] for k, c in enumerate("xyz")}})
    expected = signal.copy()
    expected[:, 1] += _extra_specific_force(ctx["other"], ctx["domega"], d_y)[:, 1]
    expected[:, 2] += _extra_specific_force(ctx["other"], ctx["domega"], d_z)[:, 2]
    _check(_measure(layout, x, "accel", signal, ctx), expected)


def test_accel_time_lag():
    """Accel samples stamped ``t`` measure at ``t - p``: ``f(t - p) ~= f(t) - p df/dt`` (``dsignal``)."""
    layout = Layout.declared(extra=("time_lag.accel",))
    signal, ctx = _context(1200, "accel")
    p = 2.5e-3  # s
    x = layout.zeros()
    x[layout.index("time_lag.accel")] = p
    _check(_measure(layout, x, "accel", signal, ctx), signal - p * ctx["dsignal"])


def test_accel_time_lag_on_a_sine_is_a_delay():
    """The lag's sign against a real delay: a sine sampled late by ``p`` (to first order in ``p``)."""
    layout = Layout.declared(extra=("time_lag.accel",))
    t = np.linspace(0.0, 2.0, N)
    om = 2 * np.pi * 0.7
    f = np.column_stack([np.sin(om * t), 2 * np.cos(om * t), 9.8 + np.sin(2 * om * t)])
    df = np.column_stack([om * np.cos(om * t), -2 * om * np.sin(om * t), 2 * om * np.cos(2 * om * t)])
    p = 1e-6
    f_late = np.column_stack([np.sin(om * (t - p)), 2 * np.cos(om * (t - p)), 9.8 + np.sin(2 * om * (t - p))])
    x = layout.zeros()
    x[layout.index("time_lag.accel")] = p
    np.testing.assert_allclose(measure(layout, x, "accel", f, dsignal=df), f_late, rtol=0, atol=1e-10)


# ---------------------------------------------------------------------------
# everything at once: the effects add to the declared model
# ---------------------------------------------------------------------------


def _everything_by_hand(layout, x, triad, signal, ctx):
    v = layout.to_dict(x)
    vec = lambda name: np.array([v[f"{name}.{a}"] for a in "xyz"])
    dT, dTdt = ctx["dT"], ctx["dTdt"]
    out = _declared_by_hand(layout, x, triad, signal, dT)
    out += vec(f"{triad}.bias_tc2") * dT**2 + vec(f"{triad}.bias_dtdt") * dTdt + vec(f"{triad}.bias_tc3") * dT**3
    out += vec(f"{triad}.scale_tc2") * dT**2 * signal
    if triad == "gyro":
        out += vec("gyro.scale_asym") * np.sign(signal) * signal
        G = np.zeros((3, 3))
        for el, ij in NINE.items():
            G[ij] = v[f"gyro.g_sensitivity.{el}"]
        out += ctx["other"] @ G.T
    else:
        out += vec("accel.nonlinearity") * signal**2
        for sensor in (1, 2):
            d = np.array([v[f"accel.size_effect.{'xyz'[sensor]}{c}"] for c in "xyz"])
            out[:, sensor] += _extra_specific_force(ctx["other"], ctx["domega"], d)[:, sensor]
        out -= v["time_lag.accel"] * ctx["dsignal"]
    return out


@pytest.mark.parametrize("triad", ["gyro", "accel"])
def test_declared_model_and_every_further_effect_at_once(triad):
    layout = Layout.declared(extra=FURTHER_EFFECTS)
    assert set(DECLARED) <= set(layout.names)
    rng = np.random.default_rng(1300)
    x = rng.uniform(-1e-3, 1e-3, layout.size)
    for name, scale in (("accel.nonlinearity", 1e-5), ("accel.size_effect", 20.0), ("time_lag.accel", 3.0)):
        x[layout.slice(name)] *= scale
    signal, ctx = _context(1301, triad)
    _check(_measure(layout, x, triad, signal, ctx), _everything_by_hand(layout, x, triad, signal, ctx))
