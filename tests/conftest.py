"""Small shared fixtures: a valid synthetic experiment factory and the measured data folder; the threads a
campaign leaves behind stopped after each test module."""

import json
import sys
import tomllib
from importlib.metadata import EntryPoint
from pathlib import Path

from concurrent.futures import ThreadPoolExecutor

import pytest
from _shared import REAL_DATA, make_experiment, require_real  # noqa: F401  (tests import them from _shared)

from graph_calib import cli
from graph_calib.calibrate import build_problem
from graph_calib.importers import import_xsens
from graph_calib.model import ModelOptions
from graph_calib.options import CalibrationOptions
from graph_calib.solvers import registry

@pytest.fixture
def experiment_factory():
    """The :func:`make_experiment` factory (keyword arguments as documented there)."""
    return make_experiment


@pytest.fixture(scope="session")
def real_data():
    """Folder of the measured recordings; the test fails when it is absent."""
    return require_real(REAL_DATA)


@pytest.fixture(scope="module")
def xsens_consumer():
    """``(problem, options)`` of IMU-TK's Xsens session at the consumer grade (the measured record the
    solvers' iteration tests run on)."""
    exp = import_xsens(require_real(REAL_DATA / "imu_tk_xsens" / "xsens_acc.mat"),
                       require_real(REAL_DATA / "imu_tk_xsens" / "xsens_gyro.mat"))
    opts = CalibrationOptions(model=ModelOptions(grade="consumer"))
    return build_problem(exp, options=opts), opts


@pytest.fixture(scope="session", autouse=True)
def solvers_of_this_checkout():
    """Every solver entry point pyproject.toml declares, also when the venv's editable-install metadata predates
    one (``pip install -e .`` refreshes it): the tests test this checkout's solvers, not the venv's list."""
    declared = tomllib.loads((Path(__file__).resolve().parents[1] / "pyproject.toml").read_text())
    declared = declared["project"]["entry-points"][registry.ENTRY_POINT_GROUP]
    installed = dict(registry._entry_points())
    missing = {n: EntryPoint(name=n, value=v, group=registry.ENTRY_POINT_GROUP)
               for n, v in declared.items() if n not in installed}
    if not missing:
        yield
        return
    original = registry._entry_points
    registry._entry_points = lambda: {**installed, **missing}
    registry.get_solver.cache_clear()
    yield
    registry._entry_points = original
    registry.get_solver.cache_clear()


@pytest.fixture(scope="module", autouse=True)
def no_threads_left_behind():
    """After each test module, the Python threads a campaign run in this process left behind are stopped.

    ``calibrate`` forks its filter worker only from a process without other threads
    (:func:`graph_calib.solvers.concurrent.fork_available`); a user's ``graph-calib calibrate`` process has
    none, but a test process that ran a Dask campaign before keeps distributed's offload thread
    (``Dask-Offload``, a thread pool distributed creates on first use and never ends).  It is replaced here
    by a fresh pool (its thread starts on first use again), so that the forked path is tested in the full
    suite as users run it (tests/solvers/test_concurrent.py fails, not skips, when a thread is left).
    """
    yield
    utils = sys.modules.get("distributed.utils")
    if utils is not None and isinstance(getattr(utils, "_offload_executor", None), ThreadPoolExecutor):
        old = utils._offload_executor
        utils._offload_executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="Dask-Offload")
        old.shutdown(wait=True)
    tqdm_std = sys.modules.get("tqdm.std")
    monitor = getattr(getattr(tqdm_std, "tqdm", None), "monitor", None)
    if monitor is not None:
        monitor.exit()
        tqdm_std.tqdm.monitor = None


COMPENSATION_EFFECTS = ("gyro.g_sensitivity", "time_lag.accel")


@pytest.fixture(scope="session")
def campaign(tmp_path_factory):
    """The compensation tests' campaign: ``(simulation folder, campaign folder)`` of a short campaign, factor graph
    only, run through the CLI (one for the table, apply and export tests)."""
    root = tmp_path_factory.mktemp("compensation")
    sim, camp = root / "sim", root / "camp"
    argv = ["simulate", "nav-campaign", "--hours", "0.02", "--seed", "5", "--out", sim]
    for e in COMPENSATION_EFFECTS:
        argv += ["--effect", e]
    assert cli.main([str(a) for a in argv]) == 0
    manifest = sim / "campaign.toml"
    manifest.write_text(manifest.read_text() + f"\n[model]\neffects = {json.dumps(list(COMPENSATION_EFFECTS))}\n")
    # the declared model and the two effects, without the closed loop: the loop is not this file's subject
    # (tests/campaign/test_campaign_loop.py, tests/campaign/test_campaign_pooled.py), and on these 72 s subranges the campaign's
    # pooled test adopts accel.nonlinearity (common value 15.6 > 13.4, 2 dof), whose second-order terms the
    # bounds and the apply-twice check below do not cover
    assert cli.main(["campaign", str(manifest), "--out", str(camp), "--workers", "0", "--solver", "factor-graph",
                     "--no-report", "--quiet", "--no-diagnose"]) == 0
    return sim, camp
