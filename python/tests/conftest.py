"""Fixtures: the in-process virtual rig, and a served one (`rig sim serve`, the CLI named by
$BACKDRIVE_RIG_CLI, which `cargo xtask python` builds and sets)."""

import json
import os
import shutil
import signal
import subprocess

import pytest

from backdrive_rig import Rig

#: Virtual seconds per wall second of the test rigs (the machine runs 2 cores for many jobs).
SPEED = 10.0


def rig_cli() -> str:
    path = os.environ.get("BACKDRIVE_RIG_CLI") or shutil.which("rig")
    if not path or not os.path.exists(path):
        pytest.fail(
            "the served-rig tests need the `rig` CLI: set BACKDRIVE_RIG_CLI to it "
            "(`cargo xtask python` builds target/debug/rig and sets it)"
        )
    return path


class Served:
    """`rig sim serve --json` in a child process, stopped with SIGINT."""

    def __init__(self, *args: str, speed: float = SPEED):
        self.args = [rig_cli(), "sim", "serve", "--json", "--speed", str(speed), *args]
        self.proc = subprocess.Popen(
            self.args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )
        line = self.proc.stdout.readline()
        if not line:
            err = self.proc.stderr.read()
            raise RuntimeError(f"`{' '.join(self.args)}` did not start: {err}")
        self.ready = json.loads(line)
        self.port = self.ready["port"]

    def cli(self, *args: str) -> subprocess.CompletedProcess:
        """Runs `rig --port PORT ARGS...` against the served rig."""
        return subprocess.run(
            [rig_cli(), "--port", self.port, *args], capture_output=True, text=True, timeout=120
        )

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


@pytest.fixture
def served():
    s = Served("--preset", "ideal")
    yield s
    s.stop()


@pytest.fixture
def served_realtime():
    """A served rig at real time: the board's 500 ms comms timeout in wall time, so a test
    whose host must keep heartbeats going on a loaded machine has the board's slack."""
    s = Served("--preset", "ideal", speed=1.0)
    yield s
    s.stop()


#: Speed of the served rigs whose host runs a whole sweep: a served rig keeps the board's
#: time, so the host's wall-clock slack before the comms timeout is (500 - 150) ms / speed.
#: At 10x that is 35 ms, which a machine loaded with twice as many busy processes as cores
#: can take from the host's port thread (COMMS_TIMEOUT, seen 2 of 48 at load 8); at 3x it
#: is 117 ms.
SWEEP_SPEED = 3.0


@pytest.fixture
def served_with_effect():
    s = Served("--preset", "ideal", "--effect", "speed-dependent-axial-friction", speed=SWEEP_SPEED)
    yield s
    s.stop()


@pytest.fixture
def rig():
    with Rig.virtual(speed=SPEED) as r:
        yield r


def settled_state(rig: Rig) -> str:
    """The supervisor state after the drive had time to stop (last of 1 s of telemetry)."""
    df = rig.record(seconds=1.0, rate_hz=100)
    return df["state"].iloc[-1]
