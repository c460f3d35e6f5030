"""Experiment design (graph_calib.design.program_search, ``graph-calib design``): the reduced model against its limits
and against the program it builds, the optimum against its constraints, the command end to end on a
relaxed spec, and one test per bad-spec rule.  The full-size design and its confirmation by both solvers
are figures in docs/design.md (scripts/design_check.py)."""

import json
import math

import casadi
import numpy as np
import pytest

from graph_calib import constants as c
from graph_calib.cli import main
from graph_calib.errors import InputError
from graph_calib.sensors.params import grade
from graph_calib.design.program_search import (
    GYRO_TAU_S,
    DesignSpec,
    _dwell_information,
    build_program,
    cycle_seconds,
    optimise,
    read_spec,
    temperature_profile,
)
from graph_calib.simulation.program import BenchProgram, Dwell, Move, Setpoint, program_text


def test_dwell_information_limits():
    g = grade("navigation")
    N, sig_e, f = g.gyro_noise, g.encoder_noise, 10.0
    ell = sig_e / (N * math.sqrt(f))
    short = float(_dwell_information(0.01 * ell, N, ell))
    assert short == pytest.approx((0.01 * ell) ** 3 * f / (12 * sig_e**2), rel=1e-3)
    long = float(_dwell_information(1e4 * ell, N, ell))
    assert long == pytest.approx(1e4 * ell / N**2, rel=3e-4)


def test_reduced_temperatures_are_the_programs():
    spec = DesignSpec()
    L, rho = (300.0, 200.0, 900.0), 0.01
    prog = build_program(spec, L, rho)
    th = prog.thermal()
    t = np.arange(0.0, prog.duration_s, 0.5) + 0.25
    starts = [0.0, L[0] + cycle_seconds(spec), L[0] + L[1] + 2 * cycle_seconds(spec)]
    for i, tau in enumerate(GYRO_TAU_S):
        means, t_mean, top, D = temperature_profile(list(L), rho, cycle_s=cycle_seconds(spec), tau=tau)
        T = th.temperature(t)[:, i] - th.temperature([0.0])[0, i]
        assert float(D) == pytest.approx(prog.duration_s)
        assert float(t_mean) == pytest.approx(T.mean(), abs=2e-3)
        assert float(top) == pytest.approx(th.temperature([prog.duration_s])[0, i] - th.temperature([0.0])[0, i],
                                           abs=1e-9)
        for s, Li, m in zip(starts, L, means):
            sel = (t >= s) & (t < s + Li)
            assert float(m) == pytest.approx(T[sel].mean(), abs=2e-3)


def test_optimum_meets_its_constraints_and_trades_time_for_accuracy():
    spec = DesignSpec()
    sol = optimise(spec, 3)
    assert sol.status == "solved" and len(sol.stations_s) == 3
    assert min(sol.stations_s) >= spec.min_station_s - 1e-6
    assert max(sol.reduced_sigma_radps) * spec.confidence_sigma <= spec.gyro_target_radps * (1 + 1e-6)
    # the accuracy constraint is active: the optimum sits on the target
    assert max(sol.reduced_sigma_radps) * spec.confidence_sigma > 0.99 * spec.gyro_target_radps
    assert sol.ramp_degC_per_s <= spec.max_chamber_ramp_degC_per_s * (1 + 1e-6)
    loose = optimise(DesignSpec(gyro_target_radps=0.02 * c.DH_TO_RS), 3)
    slow = optimise(DesignSpec(max_chamber_ramp_degC_per_s=0.1 / 60.0), 3)
    assert loose.duration_s < 0.8 * sol.duration_s
    assert slow.duration_s > sol.duration_s
    # more information per second (eta) shortens the program
    assert optimise(spec, 3, eta=1.5).duration_s < sol.duration_s


SMALL = BenchProgram(
    name="small", chamber_start_degC=21.0, setpoints=(Setpoint(T_degC=24.0, ramp_degC_per_s=0.005),),
    steps=(Dwell(120.0), Move("outer", math.pi / 2, math.radians(20.0)), Dwell(60.0),
           Move("inner", math.pi / 2, math.radians(20.0)), Dwell(60.0)),
)


@pytest.mark.slow
def test_design_command_on_a_relaxed_spec(tmp_path):
    spec = tmp_path / "spec.toml"
    spec.write_text("[spec]\ngyro_target_radps = %r\nspan_degC = 2.0\nstations = [3]\n" % (0.05 * c.DH_TO_RS))
    base = tmp_path / "small.toml"
    base.write_text(program_text(SMALL))
    out = tmp_path / "design"
    assert main(["design", "--out", str(out), "--spec", str(spec), "--baseline", str(base)]) == 0
    for name in ("program.toml", "prediction.json", "design.json", "report.html"):
        assert (out / name).exists(), name
    doc = json.loads((out / "design.json").read_text())
    assert doc["targets_met"] and doc["structure"]["stations"] == 3
    assert max(doc["predicted_bound"]["gyro_radps"]["bound"]) <= 0.05 * c.DH_TO_RS
    assert doc["baseline"]["name"] == "small" and doc["duration_ratio_to_baseline"] > 0
    assert doc["reduced_model"]["solver"].startswith("casadi " + casadi.__version__)
    pred = json.loads((out / "prediction.json").read_text())
    assert pred["solver"] == "prediction"
    # the written program predicts what design.json states
    p2 = tmp_path / "again.json"
    assert main(["predict", str(out / "program.toml"), "--out", str(p2)]) == 0
    again = json.loads(p2.read_text())["remaining_error_bound"]["gyro_radps"]["bound"]
    assert np.allclose(again, doc["predicted_bound"]["gyro_radps"]["bound"], rtol=1e-6)
    assert "<svg" in (out / "report.html").read_text() or "data:image/png" in (out / "report.html").read_text()


@pytest.mark.parametrize("text, key, words", [
    ("[spec]\nspan_degC = -1.0\n", "spec.span_degC", "positive number"),
    ("[spec]\nstations = [1]\n", "spec.stations", "integers in 2..8"),
    ("[spec]\ngrade = 'consumer'\n", "spec.grade", "only 'navigation'"),
    ("[spec]\nspeed = 1.0\n", "spec.speed", "unknown key"),
    ("[other]\nx = 1\n", "", "one [spec] table"),
    ("[spec\n", "", "not valid TOML"),
    ("[spec]\nencoder_rate_hz = 1000\nrate_hz = 10\n", "spec.encoder_rate_hz", "faster than the IMU samples"),
    ("[spec]\nspan_degC = 500\n", "spec.span_degC", "beyond a thermal chamber's -70..150 degC"),
])
def test_bad_spec_refused(tmp_path, text, key, words):
    path = tmp_path / "spec.toml"
    path.write_text(text)
    with pytest.raises(InputError) as info:
        read_spec(path)
    msg = str(info.value)
    assert words in msg and key in msg and "spec.toml" in msg


def test_design_command_refuses_a_bad_spec(tmp_path, capsys):
    path = tmp_path / "spec.toml"
    path.write_text("[spec]\nstations = 3\n")
    out = tmp_path / "d"
    assert main(["design", "--out", str(out), "--spec", str(path)]) == 2
    assert "spec.stations" in capsys.readouterr().err and not out.exists()


def test_a_target_no_program_can_meet_is_refused_naming_it(tmp_path, capsys):
    """A target of 2e-5 deg/h asked for a program of years, whose full prediction ended in an out-of-memory message."""
    path = tmp_path / "spec.toml"
    path.write_text("[spec]\ngyro_target_radps = 1e-10\nstations = [2]\n")
    out = tmp_path / "d"
    assert main(["design", "--out", str(out), "--spec", str(path)]) == 2
    err = capsys.readouterr().err
    assert "spec.gyro_target_radps: the targets ask for a program of" in err and "relax the gyro target" in err
    assert "memory" not in err and not out.exists()
