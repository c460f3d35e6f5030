"""``--guided-turns DEG|off`` on calibrate, diagnose and crossval: one parser, its refusals named."""

import argparse
import math

import pytest

from graph_calib.commands.model_options import guided_turns_of
from graph_calib.errors import InputError


@pytest.mark.parametrize("text, value", [(None, True), ("off", False), ("OFF", False), ("0.3", math.radians(0.3))])
def test_the_option_reads_off_or_a_spread_in_degrees(text, value):
    assert guided_turns_of(argparse.Namespace(guided_turns=text)) == value


@pytest.mark.parametrize("text", ["abc", "0", "-1", "nan", "inf"])
def test_anything_else_is_refused_naming_the_option(text):
    with pytest.raises(InputError, match=r"--guided-turns: must be 'off' or a positive number of degrees"):
        guided_turns_of(argparse.Namespace(guided_turns=text))


@pytest.mark.parametrize("command", ["calibrate", "diagnose", "crossval"])
def test_every_command_that_calibrates_takes_it(command):
    from graph_calib.cli import build_parser
    args = build_parser().parse_args([command, "x.h5", "--out", "o", "--guided-turns", "off"])
    assert guided_turns_of(args) is False
