r"""The simulator: synthetic experiments with exact kinematics and a known truth.

Modules
-------
:mod:`~graph_calib.simulation.turntable`
    Two-axis table (outer axis horizontal, inner axis on the outer gimbal),
    programmes of dwells and cosine-ramped moves, exact ``C_nf``, rates and
    angular accelerations, encoder readings.
:mod:`~graph_calib.simulation.handheld`
    Hand-held poses joined by smooth rotations (no table).
:mod:`~graph_calib.simulation.thermal`
    Chamber profile and first-order-lag temperature channels, in closed form.
:mod:`~graph_calib.simulation.truth`
    Truth parameters per grade, smooth (quadratic) temperature curves,
    further-effect sizes.
:mod:`~graph_calib.simulation.imu`
    True rates and specific force, sensor errors through
    :func:`graph_calib.sensors.sensor_model.measure`, Gauss-Legendre increments.
:mod:`~graph_calib.simulation.design`
    The rotation design of a table experiment and its turntable programme.
:mod:`~graph_calib.simulation.experiments`
    The turntable and hand-held experiment builders and their truth.
:mod:`~graph_calib.simulation.scenarios`
    The scenario catalogue, its registry and :func:`simulate`.
:mod:`~graph_calib.simulation.writing`
    :func:`write_simulation`: experiment files, truth files and the manifest.

``docs/simulator.md`` describes the whole and its accuracy.

Examples
--------
>>> import numpy as np
>>> sim = simulate("nav-subrange-short", rng=np.random.default_rng(1), hours=0.02)
>>> [se.experiment.n_samples for se in sim.run()]
[7200]
"""

from graph_calib.simulation.experiments import SimulatedExperiment
from graph_calib.simulation.imu import SignalModel, simulate_increments
from graph_calib.simulation.scenarios import (
    SCENARIOS,
    ExperimentPlan,
    Scenario,
    Simulation,
    get_scenario,
    scenario_names,
    simulate,
)
from graph_calib.simulation.thermal import ThermalModel
from graph_calib.simulation.truth import EFFECT_SIZES, TRUTH_RANGES, ImuTruth, draw_imu
from graph_calib.simulation.writing import manifest_text, write_simulation

__all__ = [
    "SCENARIOS", "Scenario", "Simulation", "SimulatedExperiment", "ExperimentPlan", "get_scenario",
    "scenario_names", "simulate", "write_simulation", "manifest_text", "SignalModel", "simulate_increments",
    "ThermalModel", "ImuTruth", "draw_imu", "EFFECT_SIZES", "TRUTH_RANGES",
]
