"""Fixtures of the compensation tests: one short campaign, shared by the table, apply and export tests."""

import json

import pytest

from graph_calib import cli

EFFECTS = ("gyro.g_sensitivity", "time_lag.accel")


@pytest.fixture(scope="package")
def campaign(tmp_path_factory):
    """``(simulation folder, campaign folder)`` of a short campaign, factor graph only, run through the CLI."""
    root = tmp_path_factory.mktemp("compensation")
    sim, camp = root / "sim", root / "camp"
    argv = ["simulate", "nav-campaign", "--hours", "0.02", "--seed", "5", "--out", sim]
    for e in EFFECTS:
        argv += ["--effect", e]
    assert cli.main([str(a) for a in argv]) == 0
    manifest = sim / "campaign.toml"
    manifest.write_text(manifest.read_text() + f"\n[model]\neffects = {json.dumps(list(EFFECTS))}\n")
    # the declared model and the two effects, without the closed loop: the loop is not this file's subject
    # (tests/campaign/test_campaign_loop.py, tests/campaign/test_campaign_pooled.py), and on these 72 s subranges the campaign's
    # pooled test adopts accel.nonlinearity (common value 15.6 > 13.4, 2 dof), whose second-order terms the
    # bounds and the apply-twice check below do not cover
    assert cli.main(["campaign", str(manifest), "--out", str(camp), "--workers", "0", "--solver", "factor-graph",
                     "--no-report", "--quiet", "--no-diagnose"]) == 0
    return sim, camp
