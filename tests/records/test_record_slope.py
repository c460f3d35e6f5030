"""The temperature-rate slope of graph_calib.model.record is scipy's Savitzky-Golay derivative (mode 'interp').

Written in numpy so that the solvers' import does not pull in scipy.signal (docs/performance.md); this
checks it against scipy's own filter on random walks, window lengths from the shortest to the whole series.
"""
import numpy as np
import pytest
from scipy.signal import savgol_filter

from graph_calib.model.record import _quadratic_slope


@pytest.mark.parametrize("n,win", [(5, 5), (7, 5), (50, 5), (513, 61), (100, 99), (1000, 301)])
def test_quadratic_slope_is_savgol_first_derivative(n, win):
    y = np.random.default_rng(n + win).normal(size=(n, 3)).cumsum(axis=0)
    ref = savgol_filter(y, win, 2, deriv=1, delta=0.7, axis=0, mode="interp")
    got = _quadratic_slope(y, win, 0.7)
    assert np.max(np.abs(got - ref)) <= 1e-10 * np.max(np.abs(ref))


def test_quadratic_slope_of_a_quadratic_is_exact():
    t = np.arange(40) * 0.5
    y = (3.0 - 0.2 * t + 0.01 * t ** 2)[:, None]
    assert np.allclose(_quadratic_slope(y, 9, 0.5)[:, 0], -0.2 + 0.02 * t, rtol=0, atol=1e-12)
