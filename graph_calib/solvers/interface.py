r"""What every solver takes and gives back: one signature, one output, one progress event.

A solver is an object with a ``name`` and a method

    ``solve(problem, *, options, progress=None, initial=None) -> SolverOutput``

that calibrates a :class:`graph_calib.records.problem.Problem` (the shared model of one experiment, aligned).
It reads its own part of :class:`graph_calib.options.CalibrationOptions`, reports each iteration to
``progress`` as a :class:`ProgressEvent`, and may start from ``initial`` (keyframe attitudes and a
calibration vector, e.g. a smaller model's solution embedded in a larger layout).  Solvers are found
by name through :mod:`graph_calib.solvers.registry`; the result file is assembled from a
:class:`SolverOutput` by :mod:`graph_calib.solvers.results`, the same way for every solver.

Residual series
    Every solver returns its residuals per factor kind (``"rotation"``, ``"gravity"``,
    ``"encoder"``) in one layout, :class:`ResidualSeries`: the time of each factor and its three
    normalised components, N(0, 1) for a model that fits the noise.  A batch solver returns its
    whitened residuals at the solution; a filter its normalised innovations
    (``SolverOutput.residual_quantity`` says which).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Mapping, Protocol

import numpy as np

from graph_calib.sensors.params import Layout

#: The two quantities a residual series can hold.
WHITENED_RESIDUAL = "whitened residual"
NORMALISED_INNOVATION = "normalised innovation"


@dataclass(frozen=True)
class ResidualSeries:
    """One factor kind's normalised residuals over the record.

    Attributes
    ----------
    t : ndarray, shape (F,)
        Time of each factor, s (keyframe end for rotation, start for gravity, reading time for encoders).
    values : ndarray, shape (F, 3)
        Normalised components (whitened residuals or normalised innovations), dimensionless.
    """

    t: np.ndarray
    values: np.ndarray

    @property
    def count(self):
        return int(self.values.shape[0])


@dataclass(frozen=True)
class ProgressEvent:
    """One iteration of a solver, as every solver reports it.

    Attributes
    ----------
    solver : str
    iteration : int
        From 1: a Levenberg-Marquardt iteration, or a filter pass.
    cost : float
        The batch cost after it: half the sum of squared whitened residuals and priors.
    max_step_sigma : float or None
        Largest calibration step of the iteration in units of its sigma, where the solver knows it.
    chi2_per_dof : float or None
        Mean squared normalised measurement residual, where the solver knows it.
    """

    solver: str
    iteration: int
    cost: float
    max_step_sigma: float | None = None
    chi2_per_dof: float | None = None

    def text(self):
        """One line for a progress display."""
        parts = [f"{self.solver}: iteration {self.iteration}, cost {self.cost:.6g}"]
        if self.max_step_sigma is not None:
            parts.append(f"step {self.max_step_sigma:.3g} sigma")
        if self.chi2_per_dof is not None:
            parts.append(f"chi2/dof {self.chi2_per_dof:.3g}")
        return ", ".join(parts)


#: What a solver calls after each iteration.
ProgressCallback = Callable[[ProgressEvent], None]


@dataclass(frozen=True)
class SolverOutput:
    """What a solver concludes about one experiment, the same for every solver.

    Shapes: ``P`` calibration elements, ``K`` keyframes.

    Attributes
    ----------
    solver : str
        The solver's registered name.
    layout : graph_calib.sensors.params.Layout
    x : ndarray, shape (P,)
        Calibration estimate, SI, ``layout`` order.
    covariance : ndarray, shape (P, P)
        Its covariance (marginal over the attitudes); through :func:`graph_calib.solvers.registry.solve`
        without the data's information along the directions the record cannot resolve
        (``CalibrationModel.resolved_covariance``).
    t_key : ndarray, shape (K+1,)
        Keyframe boundary times, s.
    attitudes : ndarray, shape (K+1, 3, 3)
        ``C_nb`` at the boundaries given every measurement.
    residuals : mapping of str to ResidualSeries
        Per factor kind.
    residual_quantity : str
        :data:`WHITENED_RESIDUAL` or :data:`NORMALISED_INNOVATION`.
    iterations : int
        Iterations (filter passes) done.
    converged : bool
        Whether a stopping rule ended the iterations (else the iteration limit did).
    final_cost : float
        Half the sum of squared whitened residuals and priors at the solution.
    seconds : float
        Wall time of the solve.
    figures : mapping of str to float
        Further figures of this solver (e.g. the filter's mean seconds per pass), for the result file.
    """

    solver: str
    layout: Layout
    x: np.ndarray
    covariance: np.ndarray
    t_key: np.ndarray
    attitudes: np.ndarray
    residuals: Mapping[str, ResidualSeries]
    residual_quantity: str
    iterations: int
    converged: bool
    final_cost: float
    seconds: float
    figures: Mapping[str, float] = field(default_factory=dict)

    @property
    def sigma(self):
        """One sigma of every calibration element, shape (P,)."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    def residual_arrays(self):
        """``{kind: (t (F,), values (F, 3))}``: the residual series as :func:`graph_calib.io.write_residuals` takes them."""
        return {kind: (s.t, s.values) for kind, s in self.residuals.items()}


class Solver(Protocol):
    """The interface every solver implements (see the module docstring)."""

    name: str

    def solve(self, problem, *, options, progress=None, initial=None) -> SolverOutput:  # pragma: no cover
        ...


__all__ = ["ResidualSeries", "ProgressEvent", "ProgressCallback", "SolverOutput", "Solver", "WHITENED_RESIDUAL",
           "NORMALISED_INNOVATION"]
