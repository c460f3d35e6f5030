"""The frictions a lab user met importing hand-held records, each with its message (or its remedy applied)."""

from __future__ import annotations

import re

import numpy as np
import pytest

from graph_calib import cli, io
from graph_calib.errors import InputError
from graph_calib.importers import import_csv

RATE = 100.0
LAT = 0.8


def _signals(n, seed=0):
    rng = np.random.default_rng(seed)
    omega = rng.normal(0.0, 0.01, (n, 3))
    f = np.array([0.0, 0.0, 9.81]) + rng.normal(0.0, 0.01, (n, 3))
    return omega, f


def _write(path, header, rows):
    path.write_text((header + "\n" if header else "") + "\n".join(",".join(map(str, r)) for r in rows) + "\n")
    return path


def _rows(t, omega, f, *extra):
    return [[repr(float(t[k])), *omega[k], *f[k], *(e[k] for e in extra)] for k in range(t.shape[0])]


@pytest.mark.parametrize("header, t_scale", [
    ("t,gx,gy,gz,ax,ay,az,temp", 1.0),
    ("time,gyro_x,gyro_y,gyro_z,acc_x,acc_y,acc_z,temperature", 1.0),
    ("timestamp,omega_x,omega_y,omega_z,alpha_x,alpha_y,alpha_z,temp", 1e9),          # Kalibr's imu0.csv, ns
    ("#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],a_RS_S_x [m s^-2],"
     "a_RS_S_y [m s^-2],a_RS_S_z [m s^-2],temp", 1e9),                                  # EuRoC's
])
def test_a_header_naming_its_columns_is_read_without_columns(tmp_path, capsys, header, t_scale):
    n = 200
    omega, f = _signals(n)
    if t_scale != 1.0:    # nanoseconds since 1970, exact integers beyond 2^53
        stamps = 1_400_000_000 * 10**9 + np.arange(n, dtype=np.int64) * (10**9 // int(RATE))
    else:
        stamps = np.arange(n) / RATE
    rows = [[int(stamps[k]) if t_scale != 1.0 else repr(float(stamps[k])), *omega[k], *f[k], 21.5]
            for k in range(n)]
    path = _write(tmp_path / "imu.csv", header, rows)
    out = tmp_path / "x.h5"
    assert cli.main(["import", "csv", str(path), "--latitude-deg", "45", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "note: columns from the header line" in printed
    exp = io.read_experiment(out)
    assert exp.n_samples == n and exp.rate_hz == RATE
    np.testing.assert_allclose(exp.dv[1:], f[1:] / RATE, rtol=1e-6)


def test_a_header_without_known_names_asks_for_columns(tmp_path):
    path = _write(tmp_path / "a.csv", "when,p,q,r,u,v,w", [[0.0] * 7])
    from graph_calib.importers.csv import FORMAT
    with pytest.raises(InputError, match=re.escape("line 1: the header line names its columns (when, p, q, r, u, v, w) "
                                                   "but none is a known name for gx, gy, gz, ax, ay, az: give "
                                                   "--columns")):
        FORMAT.read([path], {"latitude_rad": LAT})


COLS = {"t": 0, "gx": 1, "gy": 2, "gz": 3, "ax": 4, "ay": 5, "az": 6, "temp": 7}


def _grouped(tmp_path):
    """Three faces, each group of rows restarting its clock at 0, labelled in column 8."""
    rows = []
    for face, label in enumerate(("face_a", "face_b", "face_c")):
        omega, f = _signals(100, seed=face)
        t = np.arange(100) / RATE
        rows += [[*r, label] for r in _rows(t, omega, f, np.full(100, 20.0))]
    return _write(tmp_path / "grouped.csv", None, rows)


def test_rows_grouped_by_a_label_name_the_remedy(tmp_path):
    path = _grouped(tmp_path)
    with pytest.raises(InputError, match=re.escape("line 101: time 0.0 s is not after the previous row's 0.99 s: rows "
                                                   "must be in time order. If the rows are grouped (each group "
                                                   "restarting its clock, e.g. one group per face), map the group's "
                                                   "label column as the segment (segment=COLUMN in --columns)")):
        import_csv(path, columns=COLS, latitude_rad=LAT)


def test_a_label_column_becomes_the_segments_placed_one_after_the_other(tmp_path):
    exp = import_csv(_grouped(tmp_path), columns={**COLS, "segment": 8}, latitude_rad=LAT)
    assert exp.n_segments == 3 and np.array_equal(exp.segment, np.repeat([0, 1, 2], 100))
    assert np.all(np.diff(exp.t) > 0)
    np.testing.assert_allclose(np.diff(exp.t), 1.0 / RATE, rtol=1e-9)   # each group one period after the last


def test_sort_puts_shuffled_rows_in_time_order(tmp_path):
    omega, f = _signals(100)
    rows = _rows(np.arange(100) / RATE, omega, f, np.full(100, 20.0))
    order = np.random.default_rng(3).permutation(100)
    path = _write(tmp_path / "s.csv", None, [rows[k] for k in order])
    with pytest.raises(InputError, match="if the rows are only shuffled, --sort sorts them by time"):
        import_csv(path, columns=COLS, latitude_rad=LAT)
    exp = import_csv(path, columns=COLS, latitude_rad=LAT, sort=True)
    np.testing.assert_allclose(exp.dv[1:], f[1:] / RATE, rtol=1e-9)


def _jittered(tmp_path, *, missing=()):
    """Wireless stamps: samples arrive in bursts every 35 ms (gaps of 3.5 periods), stamped on arrival."""
    n = 400
    omega, f = _signals(n)
    k = np.arange(n)
    burst = np.ceil(np.round(k / RATE / 0.035, 9)) * 0.035
    rank = k - np.searchsorted(burst, burst)          # position inside its burst
    arrival = burst + rank * 1e-4
    keep = np.setdiff1d(k, missing)
    return _write(tmp_path / "j.csv", None, _rows(arrival[keep], omega[keep], f[keep], np.full(keep.size, 20.0)))


def test_jittered_stamps_with_no_sample_missing_become_the_sample_index(tmp_path):
    exp = import_csv(_jittered(tmp_path), columns=COLS, latitude_rad=LAT, rate_hz=RATE)
    np.testing.assert_allclose(np.diff(exp.t), 1.0 / RATE, rtol=1e-9)
    assert "follow the sample index" in exp.description and "no sample is missing" in exp.description


def test_jittered_stamps_with_samples_missing_propose_segments_not_the_index(tmp_path):
    """40 samples lost: the sample index at a rate fitted to the end points would close the gap and misplace every
    later sample (a lab user who followed that remedy got gyro scales 150 sigma off and a pass)."""
    path = _jittered(tmp_path, missing=range(100, 140))
    with pytest.raises(InputError, match=r"about 40 samples are missing \(.*half of them before sample 100, "
                                         r".*Mark where each piece starts with a segment column") as info:
        import_csv(path, columns=COLS, latitude_rad=LAT, rate_hz=RATE)
    assert "--rate-hz" not in str(info.value)


def test_late_stamps_with_every_sample_there_propose_the_sample_index(tmp_path):
    """A link that stalls and then delivers the held samples at once: a gap, but the span holds every sample."""
    n = 400
    omega, f = _signals(n)
    t = np.arange(n) / RATE
    t[150:160] = t[160] - 1e-4 * np.arange(10, 0, -1)       # ten samples held back, then sent in one burst
    path = _write(tmp_path / "late.csv", None, _rows(t, omega, f, np.full(n, 20.0)))
    with pytest.raises(InputError, match=r"while the span holds every sample: the clock is not the sample clock\. If "
                                         r"the stamps are late \(a wireless link\), use the sample index at the "
                                         r"nominal rate \(csv: leave t= out of --columns and give --rate-hz"):
        import_csv(path, columns=COLS, latitude_rad=LAT, rate_hz=RATE)


def test_a_missing_temperature_names_the_option(tmp_path, capsys):
    omega, f = _signals(50)
    path = _write(tmp_path / "t.csv", "t,gx,gy,gz,ax,ay,az", _rows(np.arange(50) / RATE, omega, f))
    assert cli.main(["import", "csv", str(path), "--latitude-deg", "45", "--out", str(tmp_path / "x.h5")]) == 2
    assert (f"{path}: --temperature: no temperature column: map one (temp=COLUMN in --columns, or a header column "
            "named temp or temperature) or give an assumed constant temperature (--temperature DEGC)"
            ) in capsys.readouterr().err
    assert cli.main(["import", "csv", str(path), "--latitude-deg", "45", "--temperature", "21",
                     "--out", str(tmp_path / "x.h5")]) == 0


def test_a_header_column_temp_imu_is_the_temperature(tmp_path):
    omega, f = _signals(50)
    path = _write(tmp_path / "t.csv", "t,gx,gy,gz,ax,ay,az,temp_imu",
                  _rows(np.arange(50) / RATE, omega, f, np.full(50, 21.0)))
    from graph_calib.importers.csv import FORMAT
    exp = FORMAT.read([path], {"latitude_rad": LAT})
    assert np.all(exp.temperature == 21.0)


def test_a_byte_order_mark_before_the_header_is_read_past(tmp_path):
    omega, f = _signals(50)
    path = _write(tmp_path / "bom.csv", "timestamp,gx,gy,gz,ax,ay,az,temp",
                  _rows(np.arange(50) / RATE, omega, f, np.full(50, 21.0)))
    path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())
    from graph_calib.importers.csv import FORMAT
    exp = FORMAT.read([path], {"latitude_rad": LAT})
    assert exp.n_samples == 50 and exp.rate_hz == RATE


@pytest.mark.parametrize("sep, name", [(";", "semicolon"), ("\t", "tab")])
def test_a_header_split_by_another_separator_names_the_delimiter_option(tmp_path, sep, name):
    omega, f = _signals(20)
    rows = _rows(np.arange(20) / RATE, omega, f, np.full(20, 21.0))
    path = tmp_path / "s.csv"
    path.write_text(sep.join("t gx gy gz ax ay az temp".split()) + "\n"
                    + "\n".join(sep.join(map(str, r)) for r in rows) + "\n")
    from graph_calib.importers.csv import FORMAT
    with pytest.raises(InputError, match=re.escape(f"line 1: the header line is one column (t{sep}gx") + ".*"
                       + re.escape(f"but splits at each {name}: give --delimiter {name}")):
        FORMAT.read([path], {"latitude_rad": LAT})
    exp = FORMAT.read([path], {"latitude_rad": LAT, "delimiter": sep})
    assert exp.n_samples == 20


def test_a_row_logged_twice_is_named_when_sorting(tmp_path):
    omega, f = _signals(100)
    rows = _rows(np.arange(100) / RATE, omega, f, np.full(100, 20.0))
    rows.insert(40, list(rows[39]))                      # line 41 repeats line 40
    order = np.random.default_rng(3).permutation(len(rows))
    path = _write(tmp_path / "d.csv", None, [rows[k] for k in order])
    lines = sorted(int(np.flatnonzero(order == k)[0]) + 1 for k in (39, 40))
    with pytest.raises(InputError, match=re.escape(f"line {lines[1]}: lines {lines[0]} and {lines[1]} have the same "
                                                   "time 0.39 s: a row logged twice? sorting cannot order them; "
                                                   "remove one")):
        import_csv(path, columns=COLS, latitude_rad=LAT, sort=True)


@pytest.mark.parametrize("scale, units", [(1e3, "ms"), (1e9, "ns")])
def test_a_time_column_in_other_units_read_as_seconds_is_refused(tmp_path, scale, units):
    omega, f = _signals(100)
    path = _write(tmp_path / "ms.csv", None, _rows(np.arange(100) / RATE * scale, omega, f, np.full(100, 20.0)))
    with pytest.raises(InputError, match=re.escape("time_units: the time column advances by ") + ".*"
                       + re.escape("an IMU samples faster; if the column counts milliseconds or nanoseconds give "
                                   "--time-units ms or ns")):
        import_csv(path, columns=COLS, latitude_rad=LAT, time_units="s")
    exp = import_csv(path, columns=COLS, latitude_rad=LAT, time_units=units)
    assert exp.rate_hz == pytest.approx(RATE)


@pytest.mark.parametrize("option, value, said", [("gyro_units", "deg/s", "rad/s"), ("time_units", "s", "ns")])
def test_a_units_option_against_the_headers_units_is_refused(tmp_path, option, value, said):
    """EuRoC's header names its units; a --gyro-units deg/s beside it made the rates 57 times too small."""
    n = 50
    omega, f = _signals(n)
    stamps = 1_400_000_000 * 10**9 + np.arange(n, dtype=np.int64) * (10**9 // int(RATE))
    header = ("#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],a_RS_S_x [m s^-2],"
              "a_RS_S_y [m s^-2],a_RS_S_z [m s^-2],temp")
    path = _write(tmp_path / "e.csv", header, [[int(stamps[k]), *omega[k], *f[k], 21.5] for k in range(n)])
    from graph_calib.importers.csv import FORMAT
    flag = "--" + option.replace("_", "-")
    with pytest.raises(InputError, match=re.escape(f"{flag}: the header line says the {option.split('_')[0]} column "
                                                   f"is in {said}, but {value} is given")):
        FORMAT.read([path], {"latitude_rad": LAT, option: value})
    assert FORMAT.read([path], {"latitude_rad": LAT, option: said}).n_samples == n


def test_stamps_jittered_within_a_period_follow_the_sample_index(tmp_path):
    """Stamps taken on arrival, +-4 ms about a 100 Hz clock, in order and no gap: taken as they were, each sample's
    increment carried the stamps' scatter and the calibration read it as accelerometer noise (variance factor 0.01)."""
    n = 400
    omega, f = _signals(n)
    t = np.arange(n) / RATE + np.random.default_rng(5).uniform(-0.004, 0.004, n)
    exp = import_csv(_write(tmp_path / "j.csv", None, _rows(t, omega, f, np.full(n, 20.0))), columns=COLS,
                     latitude_rad=LAT)
    np.testing.assert_allclose(np.diff(exp.t), np.diff(exp.t)[0], rtol=1e-9)
    assert exp.rate_hz == pytest.approx(RATE, rel=2e-3)
    assert "follow the sample index" in exp.description and "spacing scatter" in exp.description
    np.testing.assert_allclose(exp.dv[1:] * exp.rate_hz, f[1:], rtol=1e-6)


def test_a_sample_clock_s_stamps_are_kept(tmp_path):
    """A clock whose spacing varies by a fraction of a per cent (a drifting crystal): its stamps stay."""
    n = 400
    omega, f = _signals(n)
    t = np.cumsum(np.full(n, 1.0 / RATE) * (1.0 + 0.002 * np.sin(np.arange(n) / 30.0)))
    exp = import_csv(_write(tmp_path / "c.csv", None, _rows(t, omega, f, np.full(n, 20.0))), columns=COLS,
                     latitude_rad=LAT)
    np.testing.assert_allclose(exp.t, t - t[0] + exp.t[0], atol=1e-12)
    assert "follow the sample index" not in exp.description


def test_nanosecond_stamps_guessed_without_units_are_named_exactly_and_give_way_to_an_option(tmp_path):
    n = 50
    omega, f = _signals(n)
    stamps = 1_600_000_000_010_000_000 + np.arange(n, dtype=np.int64) * 10_000_000
    path = _write(tmp_path / "ns.csv", "t,gx,gy,gz,ax,ay,az,temp", [[int(stamps[k]), *omega[k], *f[k], 21.0]
                                                                    for k in range(n)])
    from graph_calib.importers.csv import FORMAT
    from graph_calib.importers.csv_header import detect_layout
    _, units, notes, header_lines = detect_layout(path, delimiter=",")
    assert header_lines == 1
    assert units == {"time_guess": "ns"}
    assert ("time column read as nanoseconds (whole numbers from 1600000000010000000); give --time-units to read it "
            "in other units") in notes
    assert FORMAT.read([path], {"latitude_rad": LAT}).rate_hz == pytest.approx(RATE)
    # a guess gives way: read as microseconds the record is 0.1 Hz, which the time check refuses by name
    with pytest.raises(InputError, match="time_units: the time column advances by 10.0 s per row read as us"):
        FORMAT.read([path], {"latitude_rad": LAT, "time_units": "us"})


def test_comment_lines_above_the_header_are_read_past(tmp_path):
    """An exporter's own lines (# exported by ..., # date ...) above the header line that names the columns."""
    n = 50
    omega, f = _signals(n)
    path = _write(tmp_path / "c.csv", "# exported by some logger v2\n# 2026-12-05\ntimestamp,gx,gy,gz,ax,ay,az,temp",
                  _rows(np.arange(n) / RATE, omega, f, np.full(n, 21.0)))
    from graph_calib.importers.csv import FORMAT
    options = {"latitude_rad": LAT}
    exp = FORMAT.read([path], options)
    assert exp.n_samples == n and exp.rate_hz == pytest.approx(RATE)
    assert "2 line(s) above the header line read as comments" in options["_notes"]
    np.testing.assert_allclose(exp.dv[1:] * RATE, f[1:], rtol=1e-6)


def test_a_header_below_comment_lines_is_named_by_its_own_line(tmp_path):
    path = _write(tmp_path / "a.csv", "# exported by some logger\nwhen,p,q,r,u,v,w", [[0.0] * 7])
    from graph_calib.importers.csv import FORMAT
    with pytest.raises(InputError, match=re.escape("line 2: the header line names its columns (when, p, q, r, u, v, "
                                                   "w)")):
        FORMAT.read([path], {"latitude_rad": LAT})


@pytest.mark.parametrize("fmt", ["rosbag", "ulog", "csv"])
def test_a_missing_input_is_named_before_any_option_it_lacks(tmp_path, capsys, fmt):
    """Without ``--latitude-deg`` too, a missing input is what the one message names (it is the first to fix)."""
    missing = tmp_path / "nowhere.bag"
    out = tmp_path / "out.h5"
    assert cli.main(["import", fmt, str(missing), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{missing}: file not found" in err and "latitude" not in err
    assert not out.exists()


def test_columns_named_by_the_first_line_need_no_header_lines_option(tmp_path):
    """``--columns t=millis,...`` on a file whose first line names them: that line is the header (it said 'but
    header_lines is 0', the Python parameter, for a header it had just read)."""
    omega, f = _signals(50)
    path = _write(tmp_path / "a.csv", "millis,wx,wy,wz,fx,fy,fz,deg",
                  _rows(np.arange(50) * 10.0, omega, f, np.full(50, 20.0)))
    cols = {"t": "millis", "gx": "wx", "gy": "wy", "gz": "wz", "ax": "fx", "ay": "fy", "az": "fz", "temp": "deg"}
    exp = import_csv(path, columns=cols, latitude_rad=LAT, time_units="ms")
    assert exp.n_samples == 50
    np.testing.assert_allclose(exp.dv[1:], f[1:] / RATE, rtol=1e-9)
    with pytest.raises(InputError, match=r"column 'time' not in the header line 1 \(millis, wx"):
        import_csv(path, columns={**cols, "t": "time"}, latitude_rad=LAT, time_units="ms")
    other = {k: v.upper() for k, v in cols.items()}
    with pytest.raises(InputError, match=r"names a header column, but no header line was given: give --header-lines N"):
        import_csv(path, columns=other, latitude_rad=LAT, time_units="ms")


def test_a_row_logged_twice_is_named_without_sorting_too(tmp_path):
    omega, f = _signals(50)
    rows = _rows(np.arange(50) / RATE, omega, f, np.full(50, 20.0))
    path = _write(tmp_path / "d.csv", None, rows[:20] + [rows[19]] + rows[20:])
    with pytest.raises(InputError, match=r"line 21: lines 20 and 21 have the same time 0\.19 s: a row logged twice\? "
                                         r"remove one"):
        import_csv(path, columns=COLS, latitude_rad=LAT)


def test_a_time_column_read_in_too_fine_units_is_refused(tmp_path):
    """A millisecond log imported with --time-units us was a 0.13 s record at 100 kHz, refused only later."""
    omega, f = _signals(50)
    path = _write(tmp_path / "ms.csv", None, _rows(np.arange(50) * 10.0, omega, f, np.full(50, 20.0)))
    with pytest.raises(InputError, match=r"time_units: the time column advances by 1e-05 s per row read as us \(a "
                                         r"1e\+05 Hz record, 0\.00049 s long\): faster than an IMU samples"):
        import_csv(path, columns=COLS, latitude_rad=LAT, time_units="us")
    assert import_csv(path, columns=COLS, latitude_rad=LAT, time_units="ms").n_samples == 50


@pytest.mark.parametrize("extra", [[], ["--delimiter", "semicolon"]])
def test_numbers_with_a_decimal_comma_are_named(tmp_path, capsys, extra):
    """A European phone export (';' between columns, ',' in the numbers) was taken for a header of unknown names."""
    omega, f = _signals(30)
    rows = [";".join(f"{v:.6f}".replace(".", ",") for v in [k / RATE, *omega[k], *f[k], 20.0]) for k in range(30)]
    path = tmp_path / "eu.csv"
    path.write_text("\n".join(rows) + "\n")
    argv = ["import", "csv", str(path), "--latitude-deg", "45", "--out", str(tmp_path / "x.h5"), *extra]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert "line 1: the numbers have a decimal comma (0,000000;" in err and "--delimiter semicolon" in err, err


def _counter_log(tmp_path, *, skip=None, deg=True):
    """imucal's example layout: a sample counter, the gyros in deg/s, the accelerometers in m/s^2, no time column."""
    n = 300
    omega, f = _signals(n)
    index = np.arange(n)
    if skip is not None:
        index[skip:] += 1                                # one sample lost at ``skip``
    rows = [[int(index[k]), *(np.degrees(omega[k]) if deg else omega[k]), *f[k]] for k in range(n)]
    return _write(tmp_path / "session.csv", "n_samples,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z", rows), omega


def test_a_sample_counter_is_the_time_column_and_asks_for_the_rate_by_its_option(tmp_path, capsys):
    path, omega = _counter_log(tmp_path)
    base = ["import", "csv", str(path), "--latitude-deg", "45", "--temperature", "20", "--gyro-units", "deg/s",
            "--out", str(tmp_path / "x.h5")]
    assert cli.main(base) == 2
    assert (f"{path}: --rate-hz: the time column counts samples: give the sample rate (--rate-hz HZ), t = index / "
            "rate_hz") in capsys.readouterr().err
    assert cli.main(base + ["--rate-hz", "102.4"]) == 0
    printed = capsys.readouterr().out
    assert "t=n_samples" in printed and "n_samples read as a sample counter: t = index / --rate-hz" in printed
    exp = io.read_experiment(tmp_path / "x.h5")
    assert exp.rate_hz == 102.4 and exp.n_samples == 300
    np.testing.assert_allclose(exp.t, np.arange(300) / 102.4, rtol=0, atol=1e-12)
    np.testing.assert_allclose(exp.dtheta[1:], omega[1:] / 102.4, rtol=1e-9)


def test_a_sample_counter_that_skips_names_the_lost_sample(tmp_path, capsys):
    path, _ = _counter_log(tmp_path, skip=120)
    assert cli.main(["import", "csv", str(path), "--latitude-deg", "45", "--temperature", "20", "--gyro-units",
                     "deg/s", "--rate-hz", "100", "--out", str(tmp_path / "x.h5")]) == 2
    err = capsys.readouterr().err
    assert (f"{path}: t: the sample counter steps from 119 to 121 (input line 122): 1 sample(s) lost. Mark where each "
            "piece starts with a segment column") in err


def test_a_log_in_deg_per_s_read_as_radians_names_the_units_option(tmp_path, capsys):
    n = 300
    omega, f = _signals(n)
    omega[100:110] = [20.0, 0.0, 0.0]                    # a fast turn: 20 rad/s, 1146 deg/s, written in deg/s
    path = _write(tmp_path / "d.csv", "t,gx,gy,gz,ax,ay,az",
                  [[repr(k / RATE), *np.degrees(omega[k]), *f[k]] for k in range(n)])
    assert cli.main(["import", "csv", str(path), "--latitude-deg", "45", "--temperature", "20",
                     "--out", str(tmp_path / "x.h5")]) == 2
    assert "(graph-calib import csv: --gyro-units deg/s for a log in deg/s)" in capsys.readouterr().err


def test_a_header_above_rows_with_a_text_label_column_is_the_first_line(tmp_path, capsys):
    """imucal's annotated session: a label column first (``part``), then a sample counter and the triads; its rows hold
    text, so the header is the line that names both triads, not the last line before a row of numbers (there is
    none: the importer once took the 50th data row for the header). Grouped by label, each group restarting its
    counter: the message names the label column as the remedy, which then imports."""
    rows = []
    for label in ("x_a", "x_p"):
        omega, f = _signals(100, seed=len(rows))
        rows += [[label, 1000 + k, *np.degrees(omega[k]), *f[k]] for k in range(100)]
    path = _write(tmp_path / "annotated.csv", "part,samples,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z", rows)
    base = ["import", "csv", str(path), "--latitude-deg", "45", "--temperature", "20", "--rate-hz", "100",
            "--gyro-units", "deg/s", "--out", str(tmp_path / "x.h5")]
    assert cli.main(base) == 2
    assert ("line 102: time 1000.0 samples is not after the previous row's 1099.0 samples: rows must be in time order. "
            "If the rows are grouped") in capsys.readouterr().err
    assert cli.main(base + ["--columns", "segment=part,t=samples,gx=gyr_x,gy=gyr_y,gz=gyr_z,ax=acc_x,ay=acc_y,az=acc_z",
                            "--time-units", "samples"]) == 0
    exp = io.read_experiment(tmp_path / "x.h5")
    assert exp.n_segments == 2 and exp.n_samples == 200
