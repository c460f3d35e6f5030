"""The problem builder's refusals (graph_calib/problem.py)."""

from dataclasses import replace

import numpy as np
import pytest

from graph_calib.errors import InputError
from graph_calib.problem import build_problem


def test_a_record_cut_into_segments_is_refused_naming_the_dataset(experiment_factory):
    exp = experiment_factory(n=600)
    seg = np.repeat(np.array([0, 1], dtype=np.int32), 300)
    with pytest.raises(InputError, match=r"cut into 2 segments.*not supported yet") as info:
        build_problem(replace(exp, segment=seg))
    assert "/imu/segment" in str(info.value)
    build_problem(replace(exp, segment=np.zeros(600, dtype=np.int32)))       # one segment: as before
