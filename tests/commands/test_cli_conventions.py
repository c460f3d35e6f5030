"""The command line's conventions: an overview with examples and exit codes, help on every option, output paths
checked before the work, a closed pipe that is not an internal error."""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

import pytest

from graph_calib import cli

ROOT = Path(__file__).resolve().parents[2]


def test_bare_and_help_show_every_command_with_an_example_and_the_exit_codes(capsys):
    assert cli.main([]) == 2
    bare = capsys.readouterr().out
    assert cli.main(["--help"]) == 0
    assert capsys.readouterr().out == bare
    for name in cli.COMMANDS:
        assert f"  {name} " in bare and f"e.g. graph-calib {name} " in bare
    assert "exit codes:\n  0    success\n  2    bad input or arguments" in bare
    assert "  3    the work finished but its verdict failed" in bare
    assert "import formats: xsens, mpu6050, csv, rosbag, ulog" in bare


def test_every_option_of_every_command_has_help():
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    missing = [f"{name} {a.option_strings or a.dest}" for name, p in sub.choices.items() for a in p._actions
               if not isinstance(a, argparse._HelpAction) and not a.help]
    assert missing == []


def test_option_names_are_lower_case():
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    odd = [o for p in sub.choices.values() for a in p._actions for o in a.option_strings if o != o.lower()]
    assert odd == []


@pytest.mark.parametrize("argv, kind", [
    (["calibrate", "x.h5"], "folder"), (["diagnose", "x.h5"], "folder"), (["campaign", "m.toml"], "folder"),
    (["design"], "folder"), (["demo"], "folder"), (["simulate", "nav-subrange"], "folder"),
    (["import", "csv", "a.csv"], "file"), (["predict", "x.h5"], "file"), (["apply", "r.json", "x.h5"], "file"),
    (["export", "camp"], "file"),
])
def test_an_output_path_of_the_wrong_kind_is_refused_before_any_work(tmp_path, capsys, argv, kind):
    out = tmp_path / "out"
    if kind == "folder":
        out.write_text("a file where a folder is written")
        expected = "is a file; it names the folder to write into"
    else:
        out.mkdir()
        expected = "is a folder; it names the file to write"
    assert cli.main(argv + ["--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{out}: --out: {expected}" in err and "internal error" not in err


@pytest.mark.parametrize("argv", [["import", "csv", "a.csv"], ["predict", "x.h5"], ["apply", "r.json", "x.h5"],
                                  ["export", "camp"]])
def test_an_output_file_that_is_a_pipe_or_device_is_refused_before_any_work(tmp_path, capsys, argv):
    """The atomic write's rename would replace the node itself (``/dev/full``, ``/dev/stdout`` for root)."""
    out = tmp_path / "fifo"
    os.mkfifo(out)
    assert cli.main(argv + ["--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{out}: --out: is not a regular file (a device, a pipe or a socket)" in err, err
    assert out.is_fifo()


def test_a_symbolic_link_is_written_through_not_replaced(tmp_path):
    from graph_calib.io import atomic_write_text

    target = tmp_path / "real" / "target.txt"
    target.parent.mkdir()
    target.write_text("old")
    link = tmp_path / "link.txt"
    link.symlink_to(target)
    atomic_write_text(link, "new")
    assert link.is_symlink() and target.read_text() == "new"


@pytest.mark.parametrize("argv", [["calibrate", "x.h5"], ["diagnose", "x.h5"], ["crossval", "x.h5"],
                                  ["import", "csv", "a.csv"], ["apply", "r.json", "x.h5"], ["export", "camp"]])
def test_an_output_place_that_takes_no_files_is_refused_before_any_work(tmp_path, capsys, monkeypatch, argv):
    """A read-only folder (tried by making a file there: permission bits do not tell for root)."""
    import tempfile

    def refuse(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(tempfile, "NamedTemporaryFile", refuse)
    out = tmp_path / "ro" / ("out.h5" if argv[0] in ("import", "apply") else "out.json" if argv[0] == "export" else "o")
    assert cli.main(argv + ["--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{out}: --out: cannot be written: {tmp_path} takes no new files (Permission denied)" in err, err
    assert not (tmp_path / "ro").exists()


@pytest.mark.parametrize("command", ["calibrate", "diagnose", "crossval", "predict"])
@pytest.mark.parametrize("option, value", [("--keyframe", "nan"), ("--t-ref", "inf"), ("--keyframe", "-inf")])
def test_a_number_option_that_is_not_finite_is_refused(capsys, command, option, value):
    with pytest.raises(SystemExit) as exc:
        cli.main([command, "x.h5", "--out", "o", f"{option}={value}"])
    assert exc.value.code == 2
    assert f"argument {option}: must be a finite number, got '{value}'" in capsys.readouterr().err


def test_a_closed_pipe_is_not_an_internal_error():
    """``graph-calib ... | head``: the reader closes the pipe before the command writes."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "graph_calib.cli", "simulate", "--list"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env=env)
    proc.stdout.close()
    err = proc.stderr.read().decode()
    assert proc.wait() == 0, err
    assert "internal error" not in err and "BrokenPipeError" not in err


def test_a_closed_pipe_on_both_streams_leaves_the_work_done(tmp_path):
    """``graph-calib simulate ... 2>&1 | head -1``: the reader goes after the first line; the files are still written."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "graph_calib.cli", "simulate", "consumer-ferraris", "--seed", "1",
                             "--out", str(tmp_path / "sim")], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env)
    proc.stdout.close()
    assert proc.wait() == 0
    assert (tmp_path / "sim" / "ferraris.h5").exists() and (tmp_path / "sim" / "ferraris.truth.json").exists()


def test_the_sway_term_is_reachable_from_the_command_line():
    from graph_calib.commands import calibrate_cmd
    p = cli.build_parser(only="calibrate")
    args = p.parse_args(["calibrate", "x.h5", "--out", "o", "--sway-sigma", "estimate"])
    assert calibrate_cmd.options_from_args(args).model.sway_sigma == "estimate"
    args = p.parse_args(["calibrate", "x.h5", "--out", "o", "--sway-sigma", "0.02"])
    assert calibrate_cmd.options_from_args(args).model.sway_sigma == 0.02
    args = p.parse_args(["calibrate", "x.h5", "--out", "o", "--sway-sigma", "lots"])
    from graph_calib.errors import InputError
    with pytest.raises(InputError, match="--sway-sigma: must be 'estimate' or a non-negative number of m/s"):
        calibrate_cmd.options_from_args(args)


@pytest.mark.parametrize("command", ["calibrate", "crossval"])
def test_the_moving_sigma_is_reachable_from_the_command_line(command):
    from graph_calib.commands import calibrate_cmd
    from graph_calib.errors import InputError
    p = cli.build_parser(only=command)
    args = p.parse_args([command, "x.h5", "--out", "o", "--moving-sigma", "estimate"])
    assert calibrate_cmd.options_from_args(args).model.moving_sigma == "estimate"
    args = p.parse_args([command, "x.h5", "--out", "o", "--moving-sigma", "0.1"])
    assert calibrate_cmd.options_from_args(args).model.moving_sigma == 0.1
    args = p.parse_args([command, "x.h5", "--out", "o", "--moving-sigma", "small"])
    with pytest.raises(InputError, match="--moving-sigma: must be 'estimate' or a non-negative number of m/s"):
        calibrate_cmd.options_from_args(args)


def test_files_of_an_earlier_run_in_the_output_folder_are_named(tmp_path, capsys):
    """A second calibrate with one solver into the folder of a run with two: the other solver's file is not this run's."""
    data = tmp_path / "sim"
    assert cli.main(["simulate", "nav-subrange-short", "--seed", "3", "--hours", "0.05", "--out", str(data)]) == 0
    (h5,) = data.glob("*.h5")
    out = tmp_path / "cal"
    out.mkdir()
    (out / "sqrt-kf.json").write_text("{}")
    (out / "comparison.json").write_text("{}")
    (out / "notes.json").write_text("{}")                     # not a file the command writes: not named
    capsys.readouterr()
    assert cli.main(["calibrate", str(h5), "--out", str(out), "--solver", "factor-graph"]) in (0, 3)
    err = capsys.readouterr().err
    assert f"note: {out} also holds comparison.json, sqrt-kf.json of an earlier run, not this one's" in err
    # diagnose names them too (it left another record's files beside its own without a word)
    assert cli.main(["diagnose", str(h5), "--out", str(out), "--solver", "factor-graph", "--max-added", "0"]) in (0, 3)
    err = capsys.readouterr().err
    assert f"note: {out} also holds comparison.json, sqrt-kf.json of an earlier run, not this one's" in err


def test_a_reference_temperature_far_from_the_data_is_refused(tmp_path, capsys):
    """1000 degC for a record near 20 degC ended in an indeterminate system (an internal error)."""
    data = tmp_path / "sim"
    assert cli.main(["simulate", "nav-subrange-short", "--seed", "3", "--hours", "0.05", "--out", str(data)]) == 0
    (h5,) = data.glob("*.h5")
    capsys.readouterr()
    assert cli.main(["calibrate", str(h5), "--out", str(tmp_path / "cal"), "--t-ref", "1000"]) == 2
    err = capsys.readouterr().err
    assert "t_ref_degC: 1000 degC lies beyond 125 degC of the record's temperatures" in err
    assert not (tmp_path / "cal").exists()
