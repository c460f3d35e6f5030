"""Where the solvers' noise comes from (records/problem.noise_options), and the simulator's noise options."""

import numpy as np
import pytest

from graph_calib.errors import InputError
from graph_calib.model import ModelOptions
from graph_calib.noise.identify import NoiseIdentification
from graph_calib.records.problem import noise_options
from graph_calib.sensors.params import GRADES
from graph_calib.simulation.scenarios import simulate


def test_without_rests_the_grades_noise_is_used_and_said():
    ni = NoiseIdentification(rests=np.zeros((0, 2), dtype=np.int64), gyro=None, accel=None)
    o = noise_options(ni, ModelOptions(grade="consumer"))
    assert o.gyro_noise == GRADES["consumer"].gyro_noise and o.accel_noise == GRADES["consumer"].accel_noise
    assert o.noise_source == {"gyro": "grade", "accel": "grade", "encoder": "grade"}


def test_declared_noise_is_kept_and_said():
    ni = NoiseIdentification(rests=np.zeros((0, 2), dtype=np.int64), gyro=None, accel=None)
    o = noise_options(ni, ModelOptions(gyro_noise=1e-6, encoder_noise=1e-5))
    assert o.gyro_noise == 1e-6
    assert o.noise_source == {"gyro": "declared", "accel": "grade", "encoder": "declared"}


@pytest.mark.parametrize("option, value, message", [
    ("noise_factor", -1.0, "noise_factor must be a non-negative number"),
    ("encoder_noise_arcsec", -0.5, "encoder_noise_arcsec must be a non-negative number of arcsec"),
    ("gyro_quantization_arcsec", float("nan"), "gyro_quantization_arcsec must be a non-negative number of arcsec"),
])
def test_bad_noise_options_are_refused_naming_them(option, value, message):
    with pytest.raises(InputError, match=message):
        simulate("nav-subrange-short", rng=np.random.default_rng(0), hours=0.01, **{option: value})


def test_the_default_noise_draws_are_those_of_before():
    # the quantization has a generator of its own: switching it on leaves the white noise's draws as they were
    a = simulate("nav-subrange-short", rng=np.random.default_rng(2), hours=0.01).run()[0].experiment
    b = simulate("nav-subrange-short", rng=np.random.default_rng(2), hours=0.01,
                 gyro_quantization_arcsec=0.5).run()[0].experiment
    np.testing.assert_array_equal(a.dv, b.dv)
    # and the difference is the quantization's: increments of a white angle error of 0.5 arcsec, summing to
    # that error alone (no drift)
    q = 0.5 * 4.8481368e-6
    assert abs(np.std(b.dtheta - a.dtheta) / (np.sqrt(2) * q) - 1) < 0.1
    assert np.max(np.abs(np.cumsum(b.dtheta - a.dtheta, axis=0))) < 10 * q      # a random walk: ~85 q
