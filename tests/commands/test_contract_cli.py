"""Exit codes of ``graph_calib.cli.main`` against ``shared/spec/cli.md``.

cli.md: 0 success, 2 bad input or arguments (one line, no traceback), 1 on an internal failure,
3 when the work finished but its verdict failed.  Exit 2 is covered command by command in the other
modules; here exit 1, the verdict line and exit 3.
"""

import importlib

import pytest

from graph_calib.cli import main


@pytest.mark.parametrize("command, argv", [
    ("calibrate", ["calibrate", "exp.h5", "--out", "out"]),
    ("simulate", ["simulate", "nav-subrange-short", "--out", "out"]),
])
def test_unexpected_exception_is_exit_1_with_one_line(command, argv, monkeypatch, tmp_path, capsys):
    module = importlib.import_module(f"graph_calib.commands.{command}_cmd")

    def broken(args):
        raise RuntimeError("something the code did not expect")

    monkeypatch.setattr(module, "run", broken)
    monkeypatch.chdir(tmp_path)
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == 1
    lines = [ln for ln in err.strip().splitlines() if ln]
    assert len(lines) == 1, err
    assert "something the code did not expect" in lines[0]
    assert "Traceback" not in err


# ---------------------------------------------------------------------------
# the verdict of a command that calibrates (cli.md)
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def experiment_file(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim")
    assert main(["simulate", "nav-subrange-short", "--out", str(out), "--seed", "5", "--hours", "0.05"]) == 0
    (path,) = out.glob("*.h5")
    return path


def test_calibrate_ends_with_a_verdict_line(experiment_file, tmp_path, capsys):
    assert main(["calibrate", str(experiment_file), "--out", str(tmp_path)]) == 0
    last = [ln for ln in capsys.readouterr().out.splitlines() if ln.strip()][-1]
    for word in ("converged", "agree", "consistent"):
        assert word in last, last


def test_calibrate_exit_3_when_the_solvers_disagree(experiment_file, tmp_path, monkeypatch):
    import graph_calib.solvers.orchestration as calibrate_module

    real_compare = calibrate_module.compare

    def disagreeing(*args, **kwargs):
        doc = real_compare(*args, **kwargs)
        doc["summary"]["agree"] = False
        return doc

    monkeypatch.setattr(calibrate_module, "compare", disagreeing)
    rc = main(["calibrate", str(experiment_file), "--out", str(tmp_path)])
    for f in ("sqrt-kf.json", "factor-graph.json", "comparison.json"):
        assert (tmp_path / f).is_file(), f
    assert rc == 3
