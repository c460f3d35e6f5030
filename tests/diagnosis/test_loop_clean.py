"""On clean data (temperature curves exactly linear, no further effect) the campaign's loop adds nothing.

The campaign's loop is :func:`graph_calib.diagnosis.diagnose` with the options of
:func:`graph_calib.campaign.loop.loop_options`; its decisions use the factor graph only, so the filter is left
out here.  Three seeds of 18 min subranges at 50 Hz (about 30 s); the 20-seed count is
``benchmarks/loop_clean_seeds.py`` (docs/campaign.md records it).
"""

from dataclasses import replace

import numpy as np
import pytest

from graph_calib.campaign import CampaignOptions, calibration_options
from graph_calib.campaign.loop import loop_options
from graph_calib.diagnosis import diagnose
from graph_calib.io import Campaign
from graph_calib.simulation import simulate


def clean_subrange(seed, *, hours=0.3, rate_hz=50.0):
    """One short navigation-grade subrange with exactly linear temperature curves."""
    sim = simulate("nav-subrange-short", rng=np.random.default_rng(seed), hours=hours, rate_hz=rate_hz,
                   curvature=False)
    return sim.plans[0].run().experiment


def campaign_loop_options():
    """The loop's options as a campaign builds them (both solvers), the filter dropped (decisions use the graph)."""
    campaign = Campaign(path=None, imu_id="SIM-NAV 0001", grade="navigation", experiments=())
    opts = loop_options(campaign, CampaignOptions(), ("sqrt-kf", "factor-graph"))
    assert opts is not None and opts.solvers == ("factor-graph", "sqrt-kf")
    return campaign, replace(opts, solvers=("factor-graph",))


@pytest.mark.slow
def test_the_loop_adds_nothing_on_clean_subranges():
    campaign, dopts = campaign_loop_options()
    copts = calibration_options(campaign)
    added = {seed: diagnose(clean_subrange(seed), options=copts, diagnosis=dopts).added for seed in (101, 102, 103)}
    assert all(not a for a in added.values()), added
