"""Hostile arguments and threads (issue 33): every bad value a BadValueError naming it,
nothing that panics the port's thread, recordings from several threads queued."""

import threading

import pytest

from backdrive_rig import BadValueError, Rig, design


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda r: r.release(freq_hz=10, seconds=1e300), "seconds"),
        (lambda r: r.release(freq_hz=10, seconds=2**64 + 1), "seconds"),
        (lambda r: r.release(freq_hz=10, seconds=None, confirm_s=1e300), "confirm_s"),
        (lambda r: r.release(freq_hz=10, seconds=float("nan")), "seconds"),
        (lambda r: r.recorder(rate_hz=100, seconds=1e18), "seconds"),
        (lambda r: r.record(seconds=1, rate_hz=float("nan")), "rate_hz"),
        (lambda r: r.record(seconds=1, rate_hz=-1), "rate_hz"),
        (lambda r: r.record(seconds=1, rate_hz=2**70), "rate_hz"),
        (lambda r: r.capture(seconds=1e300, rate_hz=10000), "seconds"),
        (lambda r: r.torque_sweep(plan_toml="rest_s = 1e300\n[[points]]\nload_nm = 0.1\nvolts = 3.6\n"), "rest_s"),
        (lambda r: r.torque_sweep(plan_toml="repeats = 100000000\n[[points]]\nload_nm = 0.1\nvolts = 3.6\n"), "repeats"),
    ],
)
def test_extreme_arguments_are_bad_values_and_the_rig_lives_on(rig, call, name):
    with pytest.raises(BadValueError, match=name):
        with call(rig):
            pass
    # The port's thread is alive: the next call works.
    assert rig.faults()["latched"] == []


def test_constructor_arguments_are_bad_values():
    with pytest.raises(BadValueError, match="seed"):
        Rig.virtual(seed=-1)
    with pytest.raises(BadValueError, match="speed"):
        Rig.virtual(speed=float("nan"))
    with pytest.raises(BadValueError, match="baud"):
        Rig.open("/dev/null", baud=-1)
    with pytest.raises(BadValueError, match=r"z\[0\]"):
        design(z=[float("nan"), 51, 50, 50])
    with pytest.raises(BadValueError, match="give four"):
        design(z=[49, 51, 50])


def test_two_threads_recording_queue_and_leave_the_rig_usable(rig):
    errors = []
    lengths = []

    def records():
        try:
            for _ in range(20):
                lengths.append(len(rig.record(seconds=0.05, rate_hz=100, pandas=False)["seq"]))
        except Exception as e:  # noqa: BLE001 - reported below
            errors.append(e)

    threads = [threading.Thread(target=records) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120)
    assert not any(t.is_alive() for t in threads), "a recording thread hung"
    assert errors == []
    assert len(lengths) == 40 and min(lengths) >= 4, lengths
    # Not poisoned: one more recording runs.
    assert len(rig.record(seconds=0.05, rate_hz=100, pandas=False)["seq"]) >= 4
