"""The ``graph-calib`` command line itself: help, exit codes (cli.md: 0, 2 bad input or arguments, 1 internal
failure, 130 interrupted), one line on stderr and no traceback."""

import importlib
import subprocess
import sys
from pathlib import Path

import pytest

from graph_calib.cli import COMMANDS, main
from graph_calib.errors import InputError

ROOT = Path(__file__).resolve().parents[2]
#: The commands of cli.md.
SPEC_COMMANDS = ("simulate", "import", "calibrate", "campaign", "diagnose", "demo")
#: The project's commands beyond cli.md's (docs/compensation.md; predict, design and compare: docs/design.md;
#: crossval: docs/crossval.md).
FURTHER_COMMANDS = ("apply", "export", "predict", "design", "compare", "crossval")


def test_every_command_of_cli_md_has_a_module():
    assert set(COMMANDS) == set(SPEC_COMMANDS) | set(FURTHER_COMMANDS)
    for name in COMMANDS:
        module = importlib.import_module(f"graph_calib.commands.{name}_cmd")
        assert callable(module.add_arguments) and callable(module.run)


def test_help_lists_every_command():
    proc = subprocess.run([sys.executable, "-m", "graph_calib.cli", "--help"], cwd=ROOT, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    for name in SPEC_COMMANDS + FURTHER_COMMANDS:
        assert f"\n  {name} " in proc.stdout, name


@pytest.mark.parametrize("name", SPEC_COMMANDS + FURTHER_COMMANDS)
def test_command_help_exits_0(name, capsys):
    with pytest.raises(SystemExit) as e:
        main([name, "--help"])
    assert e.value.code == 0
    assert f"usage: graph-calib {name}" in capsys.readouterr().out


@pytest.fixture
def failing_simulate(monkeypatch):
    """``graph-calib simulate`` whose ``run`` raises what the test sets in ``failing_simulate.exc``."""
    module = importlib.import_module("graph_calib.commands.simulate_cmd")

    class Failing:
        exc = RuntimeError("boom")

    def run(args):
        raise Failing.exc

    monkeypatch.setattr(module, "run", run)
    monkeypatch.delenv("GRAPH_CALIB_DEBUG", raising=False)
    return Failing


def test_unexpected_exception_is_exit_1_with_one_line(failing_simulate, capsys):
    assert main(["simulate", "nav-subrange"]) == 1
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1, captured.err
    assert err[0].startswith("graph-calib simulate: ") and "RuntimeError: boom" in err[0]
    assert "Traceback" not in captured.err + captured.out


def test_an_input_that_asks_for_more_memory_than_there_is_is_exit_2(failing_simulate, capsys):
    """A program of 1e9 s dwells asked numpy for 745 GiB: the input's size, said in one line, not an internal error."""
    failing_simulate.exc = MemoryError("Unable to allocate 745. GiB for an array with shape (100000000000,)")
    assert main(["simulate", "nav-subrange"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["graph-calib simulate: error: the input asks for more memory than this machine has (MemoryError: "
                   "Unable to allocate 745. GiB for an array with shape (100000000000,)): shorten the record or "
                   "program"]


def test_a_multi_line_message_still_gives_one_line(failing_simulate, capsys):
    failing_simulate.exc = ValueError("first line\nsecond line\nthird")
    assert main(["simulate", "nav-subrange"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "ValueError: first line" in err[0] and "second line" not in err[0]


def test_debug_environment_variable_reraises(failing_simulate, monkeypatch):
    monkeypatch.setenv("GRAPH_CALIB_DEBUG", "1")
    with pytest.raises(RuntimeError, match="boom"):
        main(["simulate", "nav-subrange"])


def test_input_error_is_exit_2(failing_simulate, capsys):
    failing_simulate.exc = InputError("no such file", path="x.h5")
    assert main(["simulate", "nav-subrange"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("graph-calib simulate: error: ") and "x.h5" in err[0]


def test_keyboard_interrupt_is_exit_130(failing_simulate, capsys):
    failing_simulate.exc = KeyboardInterrupt()
    assert main(["simulate", "nav-subrange"]) == 130
    assert "interrupted" in capsys.readouterr().err


@pytest.mark.parametrize("argv", [
    ["frobnicate"],                                          # unknown command
    ["calibrate", "x.h5"],                                   # missing --out
    ["calibrate", "x.h5", "--out", "o", "--solver", "magic"],  # bad choice
    ["calibrate", "x.h5", "--out", "o", "--keyframe", "one"],  # not a number
    ["simulate", "--no-such-option"],                        # unknown option
])
def test_bad_arguments_are_exit_2_with_one_line(argv, capsys):
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "error:" in err[0], err


def _summary(doc):
    import io as _io
    from types import SimpleNamespace

    from graph_calib.commands.campaign_cmd import print_summary

    base = {"imu_id": "X", "timing": {"tasks_computed": 0, "tasks_cached": 0, "tasks_failed": 0, "total_seconds": 1.0},
            "primary_solver": "factor-graph", "stitch_model": "cubic", "validation": [], "campaign_checks": None}
    run = SimpleNamespace(document={**base, **doc}, stitched={}, out="o", report_path=None, failed=[],
                          verdict_failed=[])
    buf = _io.StringIO()
    print_summary(run, out=buf)
    return buf.getvalue()


def test_the_campaign_summary_says_what_ran():
    """One per-subrange solver: no 'its solvers agree'; the joint solver alone: no T_ref nan, no per-subrange pass;
    a note that most elements are held by their priors is shown (a pass hid it)."""
    verdict = {"passed": True, "fit_chi2_per_dof": {"factor-graph": 1.0}, "problems": [],
               "notes": ["factor-graph: 34 of 39 elements are held by their priors (sigma above 0.7 of the prior's)"]}
    one = _summary({"solvers": ["factor-graph"], "experiments": [{"name": "e1", "t_ref_degC": 20.0,
                                                                   "verdict": verdict}]})
    assert "verdict: pass: every experiment converged and its residuals are consistent" in one
    assert "note: factor-graph: 34 of 39 elements are held by their priors" in one
    joint = _summary({"solvers": [], "experiments": [{"name": "e1"}]})
    assert "e1: no per-subrange result" in joint and "nan" not in joint
    assert "verdict: pass: the campaign's checks pass (no per-subrange solver ran)" in joint


@pytest.mark.parametrize("flag", [["--hand-accel", "0.1"], ["--cut"], ["--pivot", "0.1"]])
def test_a_hand_held_flag_on_a_table_scenario_is_refused_by_its_name(tmp_path, capsys, flag):
    """It named the scenario's keyword (hand_accel_mps2) and listed keywords that are no flags."""
    assert main(["simulate", "nav-subrange-short", "--out", str(tmp_path / "s"), *flag]) == 2
    err = capsys.readouterr().err
    assert f"{flag[0]}: scenario 'nav-subrange-short' does not take {flag[0]} (it takes: consumer-handheld" in err
    assert "_mps2" not in err and not (tmp_path / "s").exists()
