"""The importer registry: a new format is one module and one entry, and the command line takes it as it is."""

from __future__ import annotations

import sys
import types

import numpy as np

from graph_calib import cli, io
from graph_calib.importers import registry
from graph_calib.importers.common import build_experiment, constant_temperature


def _read(inputs, options):
    n = 200
    t = np.arange(n) / 100.0
    dv = np.tile([0.0, 0.0, 9.81 * 0.01], (n, 1))
    temp, names = constant_temperature(n, options.get("temperature_degC", 20.0))
    return build_experiment(t=t, dtheta=np.zeros((n, 3)), dv=dv * options.get("scale", 1.0), temperature=temp,
                            names=names, temperature_map=np.zeros(6), rate_hz=100.0, latitude_rad=0.5,
                            gravity_mps2=9.81, imu_id="", description="a test format", source=inputs[0],
                            skip_lines=None)


def test_a_registered_format_runs_through_the_command_line_with_its_own_option(tmp_path, monkeypatch, capsys):
    module = types.ModuleType("graph_calib.importers.fake_format")
    module.FORMAT = registry.ImportFormat(
        name="fake", inputs=("THING",), summary="a format registered by a test", example="graph-calib import fake x",
        read=_read, options=(registry.Option("--scale", "a factor on the force", {"type": float}),))
    monkeypatch.setitem(sys.modules, "graph_calib.importers.fake_format", module)
    monkeypatch.setattr(registry, "FORMAT_MODULES", registry.FORMAT_MODULES + ("fake_format",))
    monkeypatch.setattr(registry, "_FORMATS", None)
    (tmp_path / "x").write_text("")
    out = tmp_path / "x.h5"
    assert cli.main(["import", "fake", str(tmp_path / "x"), "--scale", "1.001", "--out", str(out)]) == 0
    assert io.read_experiment(out).dv[0, 2] == 9.81 * 0.01 * 1.001
    assert cli.main(["import", "csv", str(tmp_path / "x"), "--scale", "2", "--out", str(out)]) == 2
    assert "--scale: does not apply to format csv (only fake)" in capsys.readouterr().err
    assert cli.main([]) == 2
    assert "import formats: xsens, mpu6050, csv, rosbag, ulog, fake" in capsys.readouterr().out
