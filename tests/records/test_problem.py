"""The problem builder's refusals (graph_calib/records/problem.py)."""

from dataclasses import replace

import numpy as np
import pytest

from graph_calib.errors import InputError
from graph_calib.records.problem import build_problem


def test_a_segment_without_a_static_interval_is_refused_naming_it(experiment_factory):
    """Each segment is aligned on its own rest (docs/model.md, "Segments"): a piece that only turns cannot be."""
    exp = experiment_factory(n=1200, with_table=False)        # static for the first half ...
    dt = 1.0 / exp.rate_hz
    angle = 0.5 * np.arange(1, 601) * dt                      # ... then rolling about x at 0.5 rad/s
    dtheta, dv = exp.dtheta.copy(), exp.dv.copy()
    dtheta[600:] = [0.5 * dt, 0.0, 0.0]
    dv[600:] = exp.gravity_mps2 * dt * np.column_stack([np.zeros(600), np.sin(angle), np.cos(angle)])
    exp = replace(exp, dtheta=dtheta, dv=dv)
    seg = np.repeat(np.array([0, 1], dtype=np.int32), 600)
    with pytest.raises(InputError, match=r"/imu/segment \[sample 600\]: segment 1 \(samples 600\.\.1199\) has no "
                                         r"static interval") as info:
        build_problem(replace(exp, segment=seg, source="cut.h5"))
    assert str(info.value).startswith("cut.h5")
    problem = build_problem(replace(exp, segment=np.zeros(1200, dtype=np.int32)))     # one segment: as before
    assert problem.q_nb0.shape == (4,) and len(problem.segment_alignments) == 1
