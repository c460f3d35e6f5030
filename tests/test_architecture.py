"""The package's layers as docs/architecture.md draws them: imports point down, no circle, no long module."""

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _checker():
    spec = importlib.util.spec_from_file_location("check_layers", ROOT / "scripts" / "check_layers.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_imports_follow_the_layers_without_circles():
    problems = _checker().check()
    assert problems == [], "\n".join(problems)


def test_the_checker_sees_an_upward_import(tmp_path, monkeypatch):
    """Not vacuous: a model module importing a solver is reported."""
    mod = _checker()
    assert mod.layer("graph_calib.model.factors") < mod.layer("graph_calib.solvers.factor_graph")
    src = tmp_path / "graph_calib" / "model"
    src.mkdir(parents=True)
    (tmp_path / "graph_calib" / "__init__.py").write_text("")
    (src / "__init__.py").write_text("")
    (src / "bad.py").write_text("def f():\n    from graph_calib.solvers.factor_graph import solve\n")
    (tmp_path / "kf_reference").mkdir()
    monkeypatch.setattr(mod, "ROOT", tmp_path)
    assert any("graph_calib/model/bad.py:2" in p and "layer 4 imports graph_calib.solvers.factor_graph" in p
               for p in mod.check())


def _copy_packages(tmp_path):
    """This checkout's two packages (sources only) under ``tmp_path``: a tree the checker can be pointed at."""
    import shutil

    for top in ("graph_calib", "kf_reference"):
        shutil.copytree(ROOT / top, tmp_path / top, ignore=shutil.ignore_patterns("__pycache__", "*.nbi", "*.nbc"))
    return tmp_path


def test_the_copied_tree_passes_so_the_planted_imports_below_are_what_fails(tmp_path):
    assert _checker().check(_copy_packages(tmp_path)) == []


def test_the_checker_catches_the_filter_importing_the_factor_graph(tmp_path):
    """The reference filter must stay independent of the batch solvers although the layers allow the import
    (both are layer 7): a planted ``kf_reference -> factor_graph`` import is reported, also inside a function."""
    mod = _checker()
    root = _copy_packages(tmp_path)
    assert mod.layer("kf_reference.passes") == mod.layer("graph_calib.solvers.factor_graph")
    passes = root / "kf_reference" / "passes.py"
    n = len(passes.read_text().splitlines())
    passes.write_text(passes.read_text() + "\n\ndef _start():\n    from graph_calib.solvers.factor_graph import "
                      "FactorGraphSolver\n    return FactorGraphSolver\n")
    problems = mod.check(root)
    assert len(problems) == 1, problems
    assert (f"kf_reference/passes.py:{n + 4}: kf_reference.passes imports graph_calib.solvers.factor_graph" in
            problems[0] and "must not depend on graph_calib.solvers.factor_graph" in problems[0]), problems


def test_the_checker_catches_the_filter_importing_the_joint_solver_as_a_submodule(tmp_path):
    mod = _checker()
    root = _copy_packages(tmp_path)
    (root / "kf_reference" / "planted.py").write_text("from graph_calib.solvers import joint\n")
    problems = mod.check(root)
    assert len(problems) == 1 and "kf_reference/planted.py:1" in problems[0], problems
    assert "must not depend on graph_calib.solvers.joint" in problems[0]


def test_the_command_line_checker_exits_1_on_the_planted_import(tmp_path):
    import subprocess
    import sys

    root = _copy_packages(tmp_path)
    (root / "kf_reference" / "planted.py").write_text("import graph_calib.solvers.factor_graph as fg\n")
    run = subprocess.run([sys.executable, str(ROOT / "scripts" / "check_layers.py"), str(root)],
                         capture_output=True, text=True)
    assert run.returncode == 1 and "kf_reference/planted.py:1" in run.stdout, run.stdout
