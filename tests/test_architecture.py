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
