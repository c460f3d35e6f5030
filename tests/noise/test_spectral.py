"""The white rate noise beside a quantization from the rests' spectra (graph_calib.noise.spectral)."""

import numpy as np
import pytest

from graph_calib.noise import spectral
from graph_calib.noise.spectral import rest_periodograms, split_cosine_taper, whittle_white_quantization

TAU0 = 0.01
#: A navigation-grade ring-laser gyro: white rate noise 0.002 deg/sqrt(h), quantization 0.5 arcsec.
N, Q = 5.8e-7, 2.4e-6
#: Rests of 20 to 70 s, as a 6-min table programme has them.
RESTS = np.array([[0, 7000], [9000, 11000], [12000, 14000], [15000, 17000], [18000, 28000]])


def _channel(seed, *, n=28000, white=N, quantization=Q, rate=7e-5):
    rng = np.random.default_rng(seed)
    e = quantization * rng.standard_normal(n + 1)
    return rate * TAU0 + white * np.sqrt(TAU0) * rng.standard_normal(n) + np.diff(e)


def test_the_expectation_of_each_ordinate_is_exact():
    """The mean of many tapered periodograms is ``N^2 tau0 v + Q^2 u`` ordinate by ordinate, the rest's ends and
    its mean taken out included (rests of 200 samples, where they matter most)."""
    rests = np.array([[0, 200]])
    I = np.mean([rest_periodograms(_channel(s, n=200), rests).I for s in range(4000)], axis=0)
    pg = rest_periodograms(_channel(0, n=200), rests)
    v, u = pg.v, pg.u
    expected = N**2 * TAU0 * v + Q**2 * u
    # 4000 exponentials a point: 1.6 % standard error; the low ordinates, where N shows, within 6 %
    assert np.all(np.abs(I / expected - 1) < 0.06)
    # without the ends' and the mean's share the lowest ordinate, where N shows most, would be half again off
    rho_only = N**2 * TAU0 + Q**2 * 2 * (1 - np.cos(2 * np.pi / 200))
    assert I[0] / rho_only > 1.4


def test_monte_carlo_the_estimates_scatter_as_their_sigmas_say():
    z_white, z_q, left_out = [], [], 0
    for seed in range(150):
        w = whittle_white_quantization(_channel(seed), RESTS, tau0=TAU0)
        assert w.converged
        left_out += bool(w.rests_left_out)
        z_white.append((w.white_var - N**2) / np.sqrt(w.cov[0, 0]))
        z_q.append((w.quantization_var - Q**2) / np.sqrt(w.cov[1, 1]))
    for z in (np.array(z_white), np.array(z_q)):
        assert abs(z.mean()) < 0.3 and 0.85 < z.std() < 1.15, (z.mean(), z.std())
    assert left_out <= 2          # a rest that is at rest is rarely left out


def test_a_white_channel_without_quantization_gives_its_density():
    w = whittle_white_quantization(_channel(3, white=3e-6, quantization=0.0), RESTS, tau0=TAU0)
    assert abs(np.sqrt(w.white_var) / 3e-6 - 1) < 0.02
    assert w.quantization_var < 3 * np.sqrt(w.cov[1, 1])


def test_the_taper_ramps_and_too_few_ordinates_give_none():
    h = split_cosine_taper(1000)
    assert h[0] < 0.01 and h[-1] < 0.01 and np.all(h[100:900] == 1.0) and np.allclose(h, h[::-1])
    assert whittle_white_quantization(_channel(0, n=10), np.array([[0, 10]]), tau0=TAU0) is None


@pytest.mark.parametrize("fraction", [0.1, 0.25])
def test_the_estimate_does_not_hang_on_the_taper(monkeypatch, fraction):
    monkeypatch.setattr(spectral, "TAPER_FRACTION", fraction)
    monkeypatch.setattr(spectral.split_cosine_taper, "__kwdefaults__", {"fraction": fraction})
    w = [whittle_white_quantization(_channel(s), RESTS, tau0=TAU0) for s in range(40)]
    ratio = np.mean([x.white_var for x in w]) / N**2
    assert abs(ratio - 1) < 0.06, ratio


def test_a_rest_that_is_not_at_rest_is_left_out():
    """A slow turn the rest detection let through (a 4-s stretch turning at 0.05 deg/s, rising and falling) puts
    low-frequency power in that rest alone: it is left out, and the white noise is the others'."""
    x = _channel(7, n=33000)
    t = np.arange(4000) * TAU0
    x[29000:33000] += np.deg2rad(0.05) * np.sin(np.pi * t / t[-1]) * TAU0
    rests = np.vstack([RESTS, [[29000, 33000]]])
    w = whittle_white_quantization(x, rests, tau0=TAU0)
    assert w.rests_left_out == (5,)
    clean = whittle_white_quantization(x, RESTS, tau0=TAU0)
    assert w.white_var == pytest.approx(clean.white_var, rel=1e-9)
    assert abs(w.white_var - N**2) < 3 * np.sqrt(w.cov[0, 0])
    # kept, it would have doubled the white noise's variance
    pooled = spectral._fit(*(lambda p: (p.I, p.v, p.u))(rest_periodograms(x, rests)), inflation=1.0, tau0=TAU0,
                           start=None)
    assert pooled.white_var > 2 * N**2


def test_the_report_s_allan_plot_marks_the_channels_from_the_spectra():
    """The diagnosis report's Allan plot (graph_calib.reports.diagnosis_report.allan_figure) labels each channel whose
    Q and N came from the spectra, and draws the model of the terms the result holds."""
    import matplotlib

    matplotlib.use("Agg")
    from graph_calib.noise import identify_noise
    from graph_calib.records.problem import noise_options
    from graph_calib.model import ModelOptions
    from graph_calib.reports.diagnosis_report import allan_figure
    from graph_calib.simulation import simulate

    exp = simulate("nav-subrange-short", rng=np.random.default_rng(2), hours=0.1,
                   gyro_quantization_arcsec=0.5).run()[0].experiment
    figures = noise_options(identify_noise(exp, keyframe_s=1.0), ModelOptions(grade="navigation")).noise_identified
    assert figures["gyro"]["estimator"] == ["whittle"] * 3 and figures["accel"]["estimator"] == ["allan"] * 3
    f = allan_figure({"identified": figures})
    gyro_ax, accel_ax = f.axes
    assert all("Q, N from the spectra" in t.get_text() for t in gyro_ax.get_legend().get_texts())
    assert not any("spectra" in t.get_text() for t in accel_ax.get_legend().get_texts())
