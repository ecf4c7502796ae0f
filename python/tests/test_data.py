"""Telemetry and captures as arrays and DataFrames, with the CLI's columns and units."""

import threading
import time

import numpy as np
import pytest

from backdrive_rig import TELEMETRY_COLUMNS, BadValueError, Rig

from conftest import SPEED


def test_telemetry_columns_are_the_monitor_csv_columns():
    assert TELEMETRY_COLUMNS[:4] == ["device_time_s", "state", "cam_speed_rad_s", "cam_hz"]
    assert len(TELEMETRY_COLUMNS) == 16


def test_record_two_seconds_at_1khz_without_gaps(served):
    with Rig.open(served.port) as rig:
        with rig.release(freq_hz=10, seconds=2):
            df = rig.record(seconds=2, rate_hz=1000)
    assert list(df.columns) == TELEMETRY_COLUMNS + ["seq"]
    # 2 s of device time at 1 kHz: 2000 samples (the first may start the count).
    assert 1995 <= len(df) <= 2001
    assert df.attrs["lost"] == 0 and df.attrs["gaps"] == []
    assert (np.diff(df["seq"].astype(np.int64)) == 1).all()
    dt = np.diff(df["device_time_s"])
    assert dt == pytest.approx(np.full_like(dt, 1e-3), abs=1e-6)
    # Units as in the CSV: cam_hz is |cam_speed_rad_s| / 2 pi.
    assert df["cam_hz"].to_numpy() == pytest.approx(
        np.abs(df["cam_speed_rad_s"].to_numpy()) / (2 * np.pi), rel=1e-5, abs=1e-6
    )
    # The release drove the cam to the asked 10 Hz.
    vib = df[df["state"] == "vibrating"]
    assert len(vib) > 200
    assert vib["cam_hz"].median() == pytest.approx(10.0, rel=0.05)


def test_record_as_numpy_arrays(rig):
    d = rig.record(seconds=0.5, rate_hz=100, pandas=False)
    assert set(d) == set(TELEMETRY_COLUMNS + ["seq"])
    assert d["device_time_s"].dtype == np.float64
    assert 49 <= len(d["device_time_s"]) <= 51
    assert set(d["state"]) == {"locked"}
    # Estimates are stale while locked: empty in the CSV, NaN here.
    assert np.isnan(d["tau_cam_nm"]).all()


def test_rates_the_device_would_change_are_refused(rig):
    with pytest.raises(BadValueError, match=r"rate_hz 300: the device sends telemetry at 1000 Hz divided by a whole number"):
        rig.record(seconds=1, rate_hz=300)
    with pytest.raises(BadValueError, match="seconds"):
        rig.record(seconds=0, rate_hz=100)


def test_background_recorder_keeps_every_sample_while_python_is_busy(rig):
    rec = rig.recorder(rate_hz=1000, seconds=3.0)
    busy_until = time.monotonic() + 3.0 / SPEED + 0.3
    # Two busy Python threads hold the GIL almost all the time.
    def spin():
        while time.monotonic() < busy_until:
            sum(range(5000))
    threads = [threading.Thread(target=spin) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    rec.wait()
    df = rec.take()
    assert rec.lost == 0 and rec.gaps == []
    assert 2995 <= len(df) <= 3001
    assert (np.diff(df["seq"].astype(np.int64)) == 1).all()


def take_some(rec):
    """The recorder's rows once it has some: polled, so a loaded machine that runs the rig
    slowly only makes the wait longer (the guard fails a rig that stopped)."""
    deadline = time.monotonic() + 60.0
    while True:
        df = rec.take()
        if len(df) > 0:
            return df
        assert time.monotonic() < deadline, "the recorder got no rows in 60 s"
        time.sleep(0.02)


def test_recorder_take_drains_and_stop_ends(rig):
    with rig.recorder(rate_hz=100) as rec:
        first = take_some(rec)
        second = take_some(rec)
    assert len(first) > 0 and len(second) > 0
    assert second["seq"].iloc[0] == first["seq"].iloc[-1] + 1
    assert rec.done


def test_capture_has_the_cli_csv_columns(rig):
    with rig.release(freq_hz=10, seconds=10):
        time.sleep(1.5 / SPEED + 0.2)
        df = rig.capture(seconds=0.2, rate_hz=10000)
    assert list(df.columns) == [
        "index", "t_s", "current_adc", "current_a", "encoder_count", "cam_angle_rad",
        "output_count", "output_angle_rad",
    ]
    assert len(df) == 2000
    # The virtual rig has the output encoder: a reading held from every control step.
    assert df["output_count"].notna().all()
    assert np.allclose(df["output_angle_rad"], df["output_count"] * 2 * np.pi / 8192)
    assert df.attrs["dropped"] == 0 and df.attrs["completed"] is True
    assert df["t_s"].iloc[1] == pytest.approx(1e-4)
    # A turning cam at about 10 Hz: the angle advances about 2 pi * 10 * 0.2 rad.
    turned = df["cam_angle_rad"].iloc[-1] - df["cam_angle_rad"].iloc[0]
    assert abs(turned) == pytest.approx(2 * np.pi * 10 * 0.2, rel=0.15)


def test_capture_limits_are_the_cli_limits(rig):
    with pytest.raises(BadValueError, match="rate_hz 3000"):
        rig.capture(seconds=0.1, rate_hz=3000)
    with pytest.raises(BadValueError, match="too long for one capture"):
        rig.capture(seconds=100, rate_hz=10000)
