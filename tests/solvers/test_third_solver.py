"""A third solver registered from outside the package runs through calibrate, campaign and diagnose.

The solver (:class:`PriorSolver`, defined here) returns the prior calibration with the prior covariance; it is
registered through the registry's entry-point table only (the ``third_solver`` fixture): no file of the package
names it, and the commands, the manifest, the campaign's tasks and the diagnosis find it by name.
"""

from importlib.metadata import EntryPoint

import numpy as np
import pytest

from graph_calib import io
from graph_calib.calibrate import calibrate
from graph_calib.cli import main
from graph_calib.options import CalibrationOptions
from graph_calib.solvers import registry
from graph_calib.solvers.interface import WHITENED_RESIDUAL, SolverOutput

NAME = "prior"


class PriorSolver:
    """The trivial solver: the prior calibration and covariance, the keyframe attitudes dead-reckoned from the
    alignment with it (or the given ones)."""

    name = NAME

    def solve(self, problem, *, options, progress=None, initial=None):
        model = problem.model
        x, sigma = model.prior()
        if initial is not None:
            R = np.asarray(initial[0], dtype=float)
        else:
            R = model.propagate(model.segment_priors(problem.q_nb0), model.preintegrate(x), x)
        return SolverOutput(solver=NAME, layout=model.layout, x=np.array(x, dtype=float),
                            covariance=np.diag(np.asarray(sigma, dtype=float) ** 2), t_key=model.t_key, attitudes=R,
                            residuals={}, residual_quantity=WHITENED_RESIDUAL, iterations=0, converged=True,
                            final_cost=0.0, seconds=0.0)


@pytest.fixture
def third_solver(monkeypatch):
    """``prior`` registered beside the package's solvers (the registry's entry points, nothing else)."""
    known = dict(registry._entry_points())
    ep = EntryPoint(name=NAME, value=f"{__name__}:PriorSolver", group=registry.ENTRY_POINT_GROUP)
    monkeypatch.setattr(registry, "_entry_points", lambda: {**known, NAME: ep})
    registry.get_solver.cache_clear()
    yield NAME
    registry.get_solver.cache_clear()


@pytest.fixture(scope="module")
def record(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim")
    assert main(["simulate", "nav-subrange-short", "--out", str(out), "--seed", "5", "--hours", "0.05"]) == 0
    (path,) = out.glob("*.h5")
    return path


@pytest.fixture(scope="module")
def small_campaign(tmp_path_factory):
    from graph_calib.simulation import simulate, write_simulation

    d = tmp_path_factory.mktemp("campaign")
    write_simulation(simulate("nav-campaign", rng=np.random.default_rng(3), hours=0.03), d)
    return d / "campaign.toml"


def test_it_is_listed_and_unknown_without_the_registration(third_solver):
    assert NAME in registry.solver_names() and NAME in registry.experiment_solvers()
    assert registry.parse_choice(f"{NAME}+factor-graph") == (("factor-graph", NAME), ())
    with pytest.raises(ValueError, match=f"unknown solver '{NAME}x'"):
        registry.parse_choice(f"{NAME}x")


def test_python_calibrate_with_the_third_solver(third_solver, record):
    exp = io.read_experiment(record)
    run = calibrate(exp, options=CalibrationOptions(), solvers=(NAME,))
    x, _ = run.problem.model.prior()
    assert list(run.results) == [NAME] and run.comparison is None
    assert np.allclose(list(run.results[NAME].values.values()), x)
    # the prior is no calibration of these data: the residual test says so, in the verdict and in the file
    assert run.verdict.converged == {NAME: True} and not run.verdict.passed
    assert run.results[NAME].extra["verdict"]["passed"] is False
    assert any("chi2/redundancy" in p for p in run.verdict.problems), run.verdict.problems
    # beside the factor graph: compared with it (the prior is far from the data's answer: they disagree)
    both = calibrate(exp, options=CalibrationOptions(), solvers=registry.parse_choice(f"{NAME}+factor-graph")[0])
    assert both.comparison["solvers"] == ["factor-graph", NAME]
    assert both.verdict.agree is False and not both.verdict.passed


def test_calibrate_command_with_the_third_solver(third_solver, record, tmp_path, capsys):
    # the work finishes (exit 3, not 1 or 2): its file written, its verdict failed on the residuals
    assert main(["calibrate", str(record), "--out", str(tmp_path), "--solver", NAME]) == 3
    res = io.read_result(tmp_path / f"{NAME}.json")
    assert res.solver == NAME and not (tmp_path / "comparison.json").exists()
    assert "verdict: FAIL" in capsys.readouterr().out


def test_an_unregistered_solver_is_refused_with_exit_2(record, tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        main(["calibrate", str(record), "--out", str(tmp_path / "o"), "--solver", NAME])
    assert e.value.code == 2
    assert f"unknown solver '{NAME}'" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_diagnose_command_with_the_third_solver_beside_the_graph(third_solver, record, tmp_path):
    rc = main(["diagnose", str(record), "--out", str(tmp_path), "--solver", f"factor-graph+{NAME}", "--max-added", "1"])
    assert rc == 3                                   # the prior disagrees with the graph: said, files written
    doc = _json(tmp_path / "diagnosis.json")
    assert doc["context"]["solvers"] == ["factor-graph", NAME]
    assert NAME in doc["before"]["residuals"]
    assert not doc["verdict"]["passed"] and doc["verdict"]["agree"] is False
    assert _json(tmp_path / "comparison.json")["solvers"] == ["factor-graph", NAME]
    assert io.read_result(tmp_path / f"{NAME}.json").solver == NAME


def test_diagnose_in_python_with_the_third_solver_as_the_primary(third_solver, record):
    from graph_calib.diagnosis import DiagnosisOptions, diagnose

    diag = diagnose(io.read_experiment(record), options=CalibrationOptions(),
                    diagnosis=DiagnosisOptions(solvers=(NAME,), max_added=0))
    assert diag.before.primary == NAME and list(diag.before.outputs) == [NAME]
    assert np.allclose(diag.before.solution.x, diag.before.problem.model.prior()[0])
    assert NAME in diag.to_json()["before"]["residual_rms"]


@pytest.mark.slow
def test_campaign_command_with_the_third_solver(third_solver, small_campaign, tmp_path):
    out = tmp_path / "camp"
    rc = main(["campaign", str(small_campaign), "--out", str(out), "--workers", "0", "--solver", NAME,
               "--no-report", "--quiet"])
    assert rc == 3                                   # computed, and the prior fails the residual test
    doc = _json(out / "campaign.json")
    assert doc["solvers"] == [NAME] and doc["primary_solver"] == NAME
    for e in doc["experiments"]:
        assert e["results"][NAME]["status"] == "computed" and e["verdict"]["passed"] is False
        assert io.read_result(out / e["results"][NAME]["file"]).solver == NAME
        assert e["loop"] is not None                 # the closed loop ran (the graph tests, the prior is run)


@pytest.mark.slow
def test_campaign_in_python_with_the_third_solver_without_the_loop(third_solver, small_campaign, tmp_path):
    from graph_calib.campaign import CampaignOptions, run_campaign

    run = run_campaign(small_campaign, tmp_path / "camp", options=CampaignOptions(
        workers=0, solvers=f"factor-graph+{NAME}", diagnose=False, report=False, progress=False))
    assert run.document["solvers"] == ["factor-graph", NAME]
    for name, res in run.results.items():
        assert set(res) == {"factor-graph", NAME}
        cmp_ = _json(tmp_path / "camp" / name / "comparison.json")
        assert cmp_["solvers"] == ["factor-graph", NAME] and cmp_["summary"]["agree"] is False
    assert run.verdict_failed                        # said, not hidden: the prior disagrees with the graph


def _json(path):
    import json

    return json.loads(path.read_text(encoding="utf-8"))
