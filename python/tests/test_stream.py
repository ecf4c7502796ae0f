"""The continuous stream from Python: ``rig.stream()`` as numpy chunks and ``Recorder`` at
10 kHz, every sample numbered, none lost or hidden."""

import threading

import numpy as np
import pytest

from backdrive_rig import STREAM_COLUMNS, BadValueError, RefusedError


def test_stream_columns_are_the_record_csv_columns_without_lost():
    assert STREAM_COLUMNS[:4] == ["seq", "t_s", "current_adc", "current_a"]
    assert "lost" not in STREAM_COLUMNS


def test_stream_yields_every_sample_at_10khz_in_numpy_chunks(rig):
    with rig.stream(rate_hz=10000, seconds=0.5, chunk_s=0.1) as s:
        chunks = list(s)
    assert s.done
    assert all(list(c.keys()) == STREAM_COLUMNS for c in chunks)
    seq = np.concatenate([c["seq"] for c in chunks])
    # Half a second of device time at 10 kHz: 5,000 samples numbered 0..4999.
    assert len(seq) == 5000 and s.samples == 5000
    assert (seq == np.arange(5000)).all()
    assert (s.lost, s.gaps) == (0, [])
    t = np.concatenate([c["t_s"] for c in chunks])
    assert t[-1] == pytest.approx(0.4999)
    first = chunks[0]
    assert first["current_a"].dtype == np.float64
    assert first["current_adc"].dtype == np.uint16
    assert set(first["state"]) == {"locked"}


def test_recorder_at_10khz_records_the_stream_while_python_is_busy(rig):
    busy = threading.Event()

    def spin() -> None:
        x = 0
        while not busy.is_set():
            x += 1

    worker = threading.Thread(target=spin)
    worker.start()
    try:
        df = rig.record(seconds=0.3, rate_hz=10000)
    finally:
        busy.set()
        worker.join()
    assert list(df.columns) == STREAM_COLUMNS
    assert len(df) == 3000
    assert (df["seq"].to_numpy() == np.arange(3000)).all()
    assert df.attrs["lost"] == 0 and df.attrs["rate_hz"] == 10000


def test_a_rate_the_stream_cannot_run_names_the_rate_that_fits(rig):
    with pytest.raises(RefusedError, match="2500 Hz"):
        rig.stream(rate_hz=3000)
    with pytest.raises(BadValueError):
        rig.stream(rate_hz=20000)
    # Nothing was left running: a stream at a good rate starts.
    with rig.stream(rate_hz=2500, seconds=0.1) as s:
        n = sum(len(c["seq"]) for c in s)
    assert n == 250


def test_the_fast_link_is_agreed_on_a_served_rig(served):
    from backdrive_rig import Rig

    with Rig.open(served.port, baud=4000000) as rig:
        assert rig.info()["max_baud"] == 4000000
        df = rig.record(seconds=0.2, rate_hz=10000)
        assert len(df) == 2000 and df.attrs["lost"] == 0
    with pytest.raises(BadValueError, match="--baud 4000000"):
        Rig.open(served.port, baud=2000000)
