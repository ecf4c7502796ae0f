"""Safe release: the gear is locked when the block ends, on an exception or Ctrl-C, at the
release's duration, when the release or the rig is dropped, and, when the interpreter dies
or hangs, by the duration or the device's comms timeout."""

import gc
import json
import math
import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from backdrive_rig import BadValueError, Rig

from conftest import SPEED, settled_state

#: The device's fault hold after a fault rises, device s (`protocol::FAULT_HOLD_MS`):
#: requests other than status and clear are refused meanwhile.
FAULT_HOLD_S = 0.5


def vibrating(rig) -> bool:
    df = rig.record(seconds=0.3, rate_hz=100)
    return bool((df["state"] == "vibrating").any() or (df["state"] == "spin_up").any())


def test_block_end_locks(rig):
    with rig.release(freq_hz=10, seconds=30) as r:
        assert r.live
        assert vibrating(rig)
    assert not r.live and r.ended_by == "stop"
    assert settled_state(rig) == "locked"


def test_exception_locks(rig):
    with pytest.raises(ZeroDivisionError):
        with rig.release(freq_hz=10, seconds=30) as r:
            assert vibrating(rig)
            1 / 0
    assert r.ended_by == "exception"
    assert settled_state(rig) == "locked"


def test_keyboard_interrupt_locks(rig):
    with pytest.raises(KeyboardInterrupt):
        with rig.release(freq_hz=10, seconds=30) as r:
            assert vibrating(rig)
            raise KeyboardInterrupt
    assert r.ended_by == "exception"
    assert settled_state(rig) == "locked"


def test_duration_ends_the_release_while_python_is_busy(rig):
    with rig.release(freq_hz=10, seconds=1.0) as r:
        # Busy Python (the GIL held) for 1.5 device-seconds' worth of wall time and more.
        end = time.monotonic() + 2.0 / SPEED + 0.5
        while time.monotonic() < end:
            sum(range(1000))
        assert not r.live
        assert r.ended_by == "duration"
    assert settled_state(rig) == "locked"


def test_dropping_the_release_locks(rig):
    r = rig.release(freq_hz=10, seconds=30).start()
    assert vibrating(rig)
    del r
    gc.collect()
    assert settled_state(rig) == "locked"


def test_a_release_without_duration_needs_confirmations(rig):
    with pytest.raises(BadValueError, match="seconds"):
        rig.release(freq_hz=10)
    with pytest.raises(BadValueError, match="confirm_s"):
        rig.release(freq_hz=10, seconds=None)
    # confirm_s is device time: 20 s is 2 s of wall time at SPEED, the slack Python has
    # between confirmations on a loaded machine (at 1 s, 0.1 s, a starved interpreter
    # missed it).
    with rig.release(freq_hz=10, seconds=None, confirm_s=20.0) as r:
        for _ in range(5):
            r.confirm()
            time.sleep(0.3 / SPEED)
        assert r.live
        # Unconfirmed, it ends on its own (waited on, not guessed).
        deadline = time.monotonic() + 60.0
        while r.live:
            assert time.monotonic() < deadline, "still live 60 s after the last confirm"
            time.sleep(0.05)
        assert r.ended_by == "keep-alive"
    assert settled_state(rig) == "locked"


def test_frequency_is_checked_as_the_cli_checks_it(rig):
    with pytest.raises(BadValueError, match=r"freq_hz 20: the device drives 1 to 15 Hz"):
        rig.release(freq_hz=20, seconds=1).start()
    with pytest.raises(BadValueError, match="seconds"):
        rig.release(freq_hz=10, seconds=-1).start()


def test_one_release_at_a_time(rig):
    with rig.release(freq_hz=10, seconds=30):
        with pytest.raises(BadValueError, match="already live"):
            rig.release(freq_hz=5, seconds=1).start()


#: Ctrl-C as a terminal delivers it: a shell that starts the tests in the background
#: without job control (`cmd &` in a script) starts them with SIGINT ignored, and Python
#: keeps an ignore it inherits, so the scripts put back the KeyboardInterrupt a user has.
CTRL_C_AS_FROM_A_TERMINAL = "import signal; signal.signal(signal.SIGINT, signal.default_int_handler)"

SCRIPT = textwrap.dedent(
    """
    import os, sys, time
    {ctrl_c}
    from backdrive_rig import Rig
    rig = Rig.open(sys.argv[1])
    mode = sys.argv[2]
    r = rig.release(freq_hz=10, seconds=float(sys.argv[3]))
    if mode != "ctrl-c":
        r.start()
        print("released", flush=True)
    if mode == "die":
        os._exit(0)
    if mode == "hang":
        while True:
            pass
    if mode == "ctrl-c":
        try:
            with r:
                print("released", flush=True)
                time.sleep(600)
        except KeyboardInterrupt:
            print("ended_by", r.ended_by, flush=True)
            rig.close()
    """
).replace("{ctrl_c}", CTRL_C_AS_FROM_A_TERMINAL)


def run_script(port, mode, seconds):
    p = subprocess.Popen(
        [sys.executable, "-c", SCRIPT, port, mode, str(seconds)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    line = p.stdout.readline()
    assert line.strip() == "released", p.stderr.read()
    return p


def finish(p, timeout_s):
    """The script's output once it has ended; a script still running after `timeout_s` is
    killed (so it cannot hold its rig into the next test) and the test fails with what it
    printed."""
    try:
        return p.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        p.kill()
        out, err = p.communicate()
        pytest.fail(f"still running {timeout_s} s after the signal; printed {out!r}, {err!r}")


def served_state(served, clear=False):
    """Faults, the settled state and the cam's last speed (Hz) of the served rig, seen by a
    new client; `clear`: then clears the faults and returns the state after."""
    with Rig.open(served.port) as rig:
        faults = rig.faults()
        df = rig.record(seconds=1.0, rate_hz=100)
        state, cam_hz = df["state"].iloc[-1], df["cam_hz"].iloc[-1]
        if clear:
            rig.clear()
            state = settled_state(rig)
        return faults, state, cam_hz


def test_ctrl_c_in_a_release_block_leaves_the_rig_locked(served_realtime):
    served = served_realtime
    # "released" is printed inside the `with` block: the signal lands in it, whatever the
    # machine's load (no sleep to guess when).
    p = run_script(served.port, "ctrl-c", 600)
    p.send_signal(signal.SIGINT)
    out, err = finish(p, 30)
    assert "ended_by exception" in out, (p.returncode, out, err)
    faults, state, cam_hz = served_state(served)
    # Locked by the library, not by the device's comms timeout.
    assert faults["latched"] == []
    assert state == "locked"


def test_a_dead_interpreter_stops_within_the_comms_timeout(served):
    p = run_script(served.port, "die", 600)
    p.wait(timeout=30)
    # Until the device saw the port closed, a new client is the old one to it, and this
    # library's client would end that release cleanly on closing: ask `rig faults` (which
    # leaves a release alone) until the device latched its fault, then wait out its fault
    # hold (which refuses telemetry) on the device's own clock, never a guessed sleep.
    deadline = time.monotonic() + 60.0

    def device(*args):
        out = served.cli(*args, "--json")
        assert time.monotonic() < deadline, f"no COMMS_TIMEOUT 60 s after the interpreter died: {out}"
        return json.loads(out.stdout)

    while "COMMS_TIMEOUT" not in device("faults")["latched"]:
        time.sleep(0.05)
    # `uptime_s` counts whole seconds: two more are past the fault's rise by over one.
    seen_at = device("info")["uptime_s"]
    while device("info")["uptime_s"] < seen_at + math.ceil(FAULT_HOLD_S) + 1:
        time.sleep(0.05)
    faults, state, cam_hz = served_state(served, clear=True)
    # The device stopped itself: the comms timeout latched, the cam stands still; once
    # cleared, the gear is locked.
    assert "COMMS_TIMEOUT" in faults["latched"]
    assert cam_hz < 0.1
    assert state == "locked"


def test_a_hung_interpreter_stops_at_the_duration(served_realtime):
    served = served_realtime
    p = run_script(served.port, "hang", 1.0)
    try:
        # The GIL is held by the busy loop; the Rust thread ends the release at 1 s.
        time.sleep(2.0)
    finally:
        p.kill()
        p.wait()
    faults, state, cam_hz = served_state(served)
    # Ended by the library at its duration (no comms timeout latched by the kill).
    assert faults["latched"] == []
    assert state == "locked"


SWEEP_SCRIPT = textwrap.dedent(
    """
    import sys, time
    {ctrl_c}
    from backdrive_rig import Rig
    rig = Rig.open(sys.argv[1])
    print("sweeping", flush=True)
    t0 = time.monotonic()
    try:
        rig.torque_sweep(quick=True, progress=lambda done, total, line: print("point", done, flush=True))
        print("finished", flush=True)
    except KeyboardInterrupt:
        print(f"interrupted after {time.monotonic() - t0:.1f} s", flush=True)
        rig.close()
    """
).replace("{ctrl_c}", CTRL_C_AS_FROM_A_TERMINAL)


def test_ctrl_c_stops_a_running_sweep_with_the_gear_locked(served):
    p = subprocess.Popen(
        [sys.executable, "-c", SWEEP_SCRIPT, served.port],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert p.stdout.readline().strip() == "sweeping"
    # The first point's progress line says the sweep runs (29 points to go): the signal
    # lands mid-sweep on the rig's own progress, not after a guessed sleep.
    first = p.stdout.readline().strip()
    assert first == "point 1", (first, p.poll())
    p.send_signal(signal.SIGINT)
    out, err = finish(p, 60)
    assert out.startswith("interrupted after"), (p.returncode, out, err)
    faults, state, cam_hz = served_state(served)
    assert faults["latched"] == []
    assert state == "locked" and cam_hz < 0.1
