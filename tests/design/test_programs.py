"""Bench programs (graph_calib.simulation.program, docs/programs.md): round trip, scenarios as programs, the
commands that run them, and one test per bad-input rule."""

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from graph_calib import io
from graph_calib.calibrate import CalibrationOptions, build_problem
from graph_calib.cli import main
from graph_calib.errors import InputError
from graph_calib.design.prediction import predict
from graph_calib.simulation import simulate
from graph_calib.simulation.program import (
    BenchProgram,
    Dwell,
    Move,
    Setpoint,
    nominal_experiment,
    parse_program,
    program_simulation,
    program_text,
    read_program,
    scenario_program,
)
from graph_calib.simulation.turntable import encoder_axes_f

import tomllib

SMALL = BenchProgram(
    name="small", chamber_start_degC=21.0, setpoints=(Setpoint(T_degC=23.0, ramp_degC_per_s=0.002, hold_s=10.0),),
    steps=(Dwell(60.0), Move("outer", math.pi / 2, math.radians(20.0)), Dwell(20.0),
           Move("inner", -math.pi, math.radians(15.0), ramp_s=0.5), Dwell(20.0)),
    encoder_valid="all", description='a "small" program',
)


def test_program_text_round_trip(tmp_path):
    path = tmp_path / "small.toml"
    path.write_text(program_text(SMALL))
    back = read_program(path)
    assert back == SMALL and back.source == str(path)
    tp = back.table_program()
    assert tp.duration == pytest.approx(60 + (90 / 20 + 1) + 20 + (180 / 15 + 0.5) + 20, abs=0.02)
    assert np.degrees(tp.final_angles).round(9).tolist() == [90.0, -180.0]
    tb, Tb = back.chamber_profile()
    assert tb.tolist() == pytest.approx([0.0, 1000.0, 1010.0]) and Tb.tolist() == [21.0, 23.0, 23.0]


@pytest.fixture(scope="module")
def short_scenario():
    sim = simulate("nav-subrange-short", rng=np.random.default_rng(7), hours=0.1, noise=False, errors=False)
    return sim, sim.plans[0].run()


def test_scenario_as_program_reproduces_its_motion_and_chamber(short_scenario):
    sim, se = short_scenario
    prog = scenario_program(sim, name="short")
    tp, ref = prog.table_program(), se.signals.motion.program
    assert tp.n_ticks == ref.n_ticks == se.experiment.n_samples
    for key in ("axis", "start_tick", "ramp_ticks", "cruise_ticks"):
        assert np.array_equal(getattr(tp, key), getattr(ref, key)), key
    assert np.allclose(tp.angle, ref.angle, rtol=0, atol=1e-12)
    tb, Tb = prog.chamber_profile()
    assert np.allclose(tb, se.thermal.chamber_t, atol=1e-6) and np.allclose(Tb, se.thermal.chamber_T, atol=1e-9)
    # simulated from the program: the same table readings and rotation increments (the IMU is ideal here)
    exp = program_simulation(prog, rng=np.random.default_rng(1), noise=False, errors=False).run()[0].experiment
    assert np.array_equal(exp.table.valid, se.experiment.table.valid)
    assert np.allclose(exp.table.q_nf, se.experiment.table.q_nf, atol=1e-12)
    assert np.allclose(exp.dtheta, se.experiment.dtheta, rtol=0, atol=1e-12)


def test_scenario_as_program_matches_its_prediction(short_scenario):
    sim, se = short_scenario
    prog = scenario_program(sim, name="short")
    opts = CalibrationOptions()
    # the scenario's noiseless readings with the table's axes, as nominal_experiment gives a program's
    # (without them no reading scatters and every direction would sit at the floor: docs/model.md)
    tab = se.experiment.table
    exp = replace(se.experiment, table=replace(tab, axes_f=encoder_axes_f(se.signals.motion, tab.t)))
    p_scn = predict(build_problem(exp, options=opts)).sigmas()
    # with the scenario's own sensor channels the program makes the same record: the same prediction
    same = predict(build_problem(nominal_experiment(prog, channels=se.thermal), options=opts)).sigmas()
    assert same.keys() == p_scn.keys()
    ratio = np.array([same[n] / p_scn[n] for n in p_scn])
    assert np.all(np.abs(ratio - 1) < 1e-6), (ratio.min(), ratio.max())
    # with the nominal channels (a program's default) only the temperature-dependent elements (bias and
    # scale factor with their coefficients, tied through T_ref) move; on this 6 min record by up to 50 %
    nominal = predict(build_problem(nominal_experiment(prog), options=opts)).sigmas()
    ratio = np.array([nominal[n] / p_scn[n] for n in p_scn])
    thermal = np.array([n.startswith(("gyro.bias", "accel.bias", "gyro.scale", "accel.scale")) for n in p_scn])
    assert np.all(np.abs(ratio[~thermal] - 1) < 0.01), ratio[~thermal]
    assert not np.all(np.abs(ratio[thermal] - 1) < 1e-3)


def test_data_programs_read_and_match_their_scenario_length():
    from pathlib import Path

    folder = Path(__file__).resolve().parents[2] / "data" / "programs"
    for name, hours in (("nav-subrange", 1.5), ("nav-subrange-short", 0.3)):
        prog = read_program(folder / f"{name}.toml")
        assert prog.name == name and prog.duration_s == pytest.approx(hours * 3600.0, abs=1e-6)
        assert sum(isinstance(s, Move) for s in prog.steps) >= 20


def test_simulate_and_predict_a_program(tmp_path):
    path = tmp_path / "small.toml"
    path.write_text(program_text(SMALL))
    out = tmp_path / "sim"
    assert main(["simulate", "--program", str(path), "--out", str(out), "--seed", "3"]) == 0
    exp = io.read_experiment(out / "small.h5")
    assert exp.n_samples == SMALL.table_program().n_ticks and np.all(exp.table.valid)
    truth = io.read_result(out / "small.truth.json")
    assert truth.solver == "truth" and "gyro.bias.x" in truth.values
    assert (out / "campaign.toml").exists()
    # the same seed makes the same files; the program fixes the temperatures whatever the seed
    out2 = tmp_path / "sim2"
    assert main(["simulate", "--program", str(path), "--out", str(out2), "--seed", "4"]) == 0
    exp2 = io.read_experiment(out2 / "small.h5")
    assert not np.array_equal(exp.dtheta, exp2.dtheta)
    pred = tmp_path / "prediction.json"
    assert main(["predict", str(path), "--out", str(pred)]) == 0
    doc = json.loads(pred.read_text())
    assert doc["solver"] == "prediction" and doc["grade"] == "navigation"
    assert doc["estimates"]["gyro.bias.x"]["sigma"] > 0


def _doc():
    return tomllib.loads(program_text(SMALL))


def _bad(mutate):
    d = _doc()
    mutate(d)
    return d


@pytest.mark.parametrize("mutate, key, words", [
    (lambda d: d.update(format="other"), "format", "not a bench program"),
    (lambda d: d.update(version=2), "version", "not supported"),
    (lambda d: d.update(extra=1), "extra", "unknown key"),
    (lambda d: d.update(name="a/b"), "name", "file-name-safe"),
    (lambda d: d["bench"].update(rate_hz=0.0), "bench.rate_hz", "must be positive"),
    (lambda d: d["bench"].update(latitude_rad=2.0), "bench.latitude_rad", "+-pi/2"),
    (lambda d: d["bench"].update(encoder_valid="moving"), "bench.encoder_valid", "'static' or 'all'"),
    (lambda d: d["bench"].update(grade="consumer"), "bench.grade", "only 'navigation'"),
    (lambda d: d.pop("chamber"), "chamber", "missing"),
    (lambda d: d["chamber"].pop("start_degC"), "chamber.start_degC", "missing"),
    (lambda d: d["chamber"]["setpoint"][0].update(ramp_degC_per_s=0.0), "chamber.setpoint[0].ramp_degC_per_s",
     "must be positive"),
    (lambda d: d["chamber"]["setpoint"][0].update(hold_s=-1.0), "chamber.setpoint[0].hold_s", "must not be negative"),
    (lambda d: d.update(step=[]), "step", "at least one"),
    (lambda d: d["step"][0].update(dwell_s=float("nan")), "step[0].dwell_s", "finite number"),
    (lambda d: d["step"][1].update(axis="middle"), "step[1].axis", "'outer' or 'inner'"),
    (lambda d: d["step"][1].update(rate_rad_per_s=-0.1), "step[1].rate_rad_per_s", "must be positive"),
    (lambda d: d["step"][1].pop("angle_rad"), "step[1].angle_rad", "missing"),
])
def test_bad_program_refused(mutate, key, words):
    with pytest.raises(InputError) as info:
        parse_program(_bad(mutate), path="p.toml")
    msg = str(info.value)
    assert words in msg and key in msg and "p.toml" in msg


def test_bad_program_file_refused_by_the_commands(tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text("format = 'graph-calib-program'\nversion = [\n")
    out = tmp_path / "out"
    assert main(["simulate", "--program", str(path), "--out", str(out)]) == 2
    assert "not valid TOML" in capsys.readouterr().err and not out.exists()
    pred = tmp_path / "p.json"
    assert main(["predict", str(path), "--out", str(pred)]) == 2
    assert "not valid TOML" in capsys.readouterr().err and not pred.exists()
    assert main(["simulate", "nav-subrange", "--program", str(path), "--out", str(out)]) == 2
    assert "not both" in capsys.readouterr().err
