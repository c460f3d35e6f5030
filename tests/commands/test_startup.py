"""Start-up of ``graph-calib calibrate``: what it imports (docs/performance.md, 'Start-up').

The command imports only its own module: not scipy.signal or scipy.stats (which ``campaign``, ``diagnose``,
``apply`` and ``export`` need and which were most of its start-up), and every command still parses.
"""
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

PROBE = """
import sys
from graph_calib.cli import main
try:
    main(["calibrate", "--help"])
except SystemExit as e:
    assert e.code == 0, e.code
heavy = sorted(m for m in ("scipy.signal", "scipy.stats", "graph_calib.diagnosis", "graph_calib.campaign",
                           "graph_calib.compensation", "graph_calib.stitching") if m in sys.modules)
print("HEAVY", heavy)
"""


def test_calibrate_imports_no_other_command():
    out = subprocess.run([sys.executable, "-c", PROBE], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    assert "HEAVY []" in out, out


def test_a_command_outside_the_list_is_still_refused_by_the_full_parser(capsys):
    from graph_calib.cli import main
    try:
        main(["calibrat", "x.h5"])
    except SystemExit as e:
        assert e.code == 2
    assert "invalid choice" in capsys.readouterr().err


def test_the_solvers_load_no_sparse_algebra():
    """scipy.sparse is the factor graph's rare covariance fallback only (docs/performance.md, session 6)."""
    probe = ("import sys, graph_calib.commands.calibrate_cmd, graph_calib.solvers.factor_graph, kf_reference.passes; "
             "print('SPARSE', 'scipy.sparse' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    assert "SPARSE False" in out, out


def test_only_the_command_line_itself_freezes_the_objects_for_a_quick_exit(tmp_path, monkeypatch, capsys):
    """``main()`` on the command line freezes every object before the process ends (no final collection
    through numba's and gtsam's objects); ``main(argv)`` from Python code freezes nothing."""
    import gc

    from graph_calib.cli import main

    argv = ["calibrate", str(tmp_path / "missing.h5"), "--out", str(tmp_path / "out")]
    gc.unfreeze()
    try:
        assert main(argv) == 2 and gc.get_freeze_count() == 0
        monkeypatch.setattr(sys, "argv", ["graph-calib", *argv])
        assert main() == 2 and gc.get_freeze_count() > 0
    finally:
        gc.unfreeze()
    assert "no such file" in capsys.readouterr().err
