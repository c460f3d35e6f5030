"""Options that decide a calibration besides the data: the model's and each solver's.

Frozen dataclasses of plain values (their ``repr`` is a campaign's cache key).  They sit below the
solvers so that the problem builder, every solver and the commands share one definition.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from graph_calib.model import REPREINTEGRATE_TOL, ModelOptions


@dataclass(frozen=True)
class GraphOptions:
    """Options of the factor-graph batch solver.

    Attributes
    ----------
    max_iterations : int
    lambda_initial : float
        Initial Levenberg-Marquardt damping.
    rel_tol : float
        Stop when the relative decrease of the cost is below this.
    step_tol_sigma : float
        ... or when every calibration step is below this fraction of its *prior* sigma.
        Off (0) by default: a prior sigma is no measure of a well-determined element
        (where the heading is weakly held, a small fraction of the prior stops the
        iterations early in their crawl along it, short of the optimum); the cost rule
        is scale-free.
    robust : str or None
        ``"huber"`` or ``"cauchy"`` on gravity and encoder factors; None for least squares.
    robust_k : float
        Threshold of the robust loss, in whitened units, for a 3-row factor (one gravity
        measurement or one encoder reading); an encoder factor stacking ``m`` readings
        uses ``robust_k * sqrt(m)``, GTSAM applying the loss to a factor's whole residual.
    repreintegrate_tol : float
        Largest first-order keyframe rotation change (rad) before re-preintegration.
    covariance : bool
        False: a solve whose solution only starts another (:func:`graph_calib.solvers.registry.loose`): no
        covariance (NaN), and the residuals those of the last linearisation.
    """

    max_iterations: int = 500
    lambda_initial: float = 1e-6
    rel_tol: float = 1e-10
    step_tol_sigma: float = 0.0
    robust: str | None = None
    robust_k: float = 3.0
    repreintegrate_tol: float = REPREINTEGRATE_TOL
    covariance: bool = True


@dataclass(frozen=True)
class FilterOptions:
    """Options of the iterated square-root Kalman filter (``kf_reference``).

    Attributes
    ----------
    max_passes : int
        Largest number of passes over the record.
    x_tol : float
        Converged when a pass moves every calibration element by less than ``x_tol`` of its sigma ...
    attitude_tol : float
        ... and every smoothed attitude correction is below ``attitude_tol`` of its sigma.
    """

    max_passes: int = 500
    x_tol: float = 1e-3
    attitude_tol: float = 1e-2


@dataclass(frozen=True)
class CalibrationOptions:
    """Everything that decides a calibration besides the data.

    Attributes
    ----------
    model : ModelOptions
        Keyframes, grade, effects, priors, noise.
    graph : GraphOptions
        The factor graph's Levenberg-Marquardt options.
    filter : FilterOptions
        The square-root filter's passes and tolerances.
    t_ref_degC : float or None
        Reference temperature; None for the mean sensor temperature.
    variance_components : bool
        :func:`graph_calib.calibrate.solve_problem` estimates one variance factor per measurement kind
        before the solvers' final run (:mod:`graph_calib.solvers.variance`); False: the identified noise as
        it is (and any ``ModelOptions.variance_factors`` set).
    structure_tests : bool
        :func:`graph_calib.calibrate.solve_problem` runs the closed loop's score tests of the effects the
        model lacks at the solution (:mod:`graph_calib.diagnosis.structure`; no adoption): a significant
        one fails the verdict, named.

    Examples
    --------
    >>> opts = CalibrationOptions(model=ModelOptions(grade="consumer"), graph=GraphOptions(max_iterations=200))
    >>> opts.model.grade, opts.filter.max_passes
    ('consumer', 500)
    """

    model: ModelOptions = field(default_factory=ModelOptions)
    graph: GraphOptions = field(default_factory=GraphOptions)
    filter: FilterOptions = field(default_factory=FilterOptions)
    t_ref_degC: float | None = None
    variance_components: bool = True
    structure_tests: bool = True

    def with_added_effects(self, added):
        """The same options with the further effects ``added`` after the model's own (``ModelOptions.extra_effects``)."""
        return replace(self, model=replace(self.model, extra_effects=tuple(self.model.extra_effects) + tuple(added)))


__all__ = ["GraphOptions", "FilterOptions", "CalibrationOptions", "ModelOptions"]
