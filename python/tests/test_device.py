"""Identity, faults, parameters and versions, against the CLI's own output."""

import json
import os
import pty
import threading
import tty

import pytest

from backdrive_rig import (
    BadValueError,
    LinkError,
    NoReplyError,
    RefusedError,
    Rig,
    RigError,
    VersionMismatchError,
    versions,
)


def test_info_has_the_cli_keys_and_values(served):
    with Rig.open(served.port) as rig:
        info = rig.info()
    cli = json.loads(served.cli("info", "--json").stdout)
    assert set(info) == set(cli)
    for key in ("firmware_version", "protocol_version", "schema_hash", "board", "capabilities"):
        assert info[key] == cli[key], key
    assert info.board == "virtual"
    assert info.time_scale == pytest.approx(10.0)
    assert info.schema_hash == versions()["schema_hash"]


def test_in_process_rig_reports_itself_as_sim(rig):
    info = rig.info()
    assert info.sim is True
    assert "SIMULATION" in info.capabilities


def test_faults_and_clear_have_the_cli_keys(served):
    with Rig.open(served.port) as rig:
        faults = rig.faults()
        cleared = rig.clear()
    assert faults == {"active": [], "latched": []}
    cli = json.loads(served.cli("clear", "--json").stdout)
    assert set(cleared) == set(cli) == {"cleared", "active", "latched"}


def test_parameters_are_the_rig_file_sections(rig):
    p = rig.parameters()
    assert {"gear", "calibration", "limits"} <= set(p)
    assert p["gear"]["z"] == [49, 51, 50, 50]
    # Table 2 as stored on the device (N mm, A, s).
    assert p["calibration"]["c1"] == pytest.approx(62.1)
    assert p["calibration"]["c6"] == pytest.approx(2.25)


def test_set_parameters_merges_writes_and_reads_back(rig):
    before = rig.parameters()
    r = rig.set_parameters(limits={"max_freq_hz": 12.0})
    assert r.written is True
    assert any(c.startswith("max_freq_hz") for c in r.changed)
    after = rig.parameters()
    assert after["limits"]["max_freq_hz"] == pytest.approx(12.0)
    # Keys not given keep their values.
    assert after["calibration"] == before["calibration"]
    # The same again changes nothing.
    assert rig.set_parameters(limits={"max_freq_hz": 12.0}).written is False
    # The release range follows the new calibration, as `rig release` checks it.
    with pytest.raises(BadValueError, match=r"freq_hz 14.*1 to 12 Hz"):
        rig.release(freq_hz=14, seconds=1).start()


def test_set_parameters_refuses_an_implausible_calibration_naming_the_field(rig):
    before = rig.parameters()
    with pytest.raises(RigError, match="c1"):
        rig.set_parameters(calibration={"c1": -62.1})
    assert rig.parameters() == before


def test_set_parameters_from_a_rig_file(rig, tmp_path):
    path = tmp_path / "rig.toml"
    path.write_text("[limits]\nmax_freq_hz = 13.0\n")
    r = rig.set_parameters(path)
    assert r.written is True
    # Keys the file leaves out take the paper's values, as `rig calibration set` says.
    assert "max_current_a" in r.defaulted
    assert rig.parameters()["limits"]["max_freq_hz"] == pytest.approx(13.0)
    with pytest.raises(BadValueError, match="cannot read"):
        rig.set_parameters(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[limits]\nmax_freq_hz = 'fast'\n")
    with pytest.raises(BadValueError, match=r"line 2, in \[limits\].*nothing was written"):
        rig.set_parameters(bad)


def test_virtual_rig_options_are_checked():
    with pytest.raises(BadValueError, match="speed"):
        Rig.virtual(speed=0)
    with pytest.raises(BadValueError, match="preset"):
        Rig.virtual(preset="perfect")
    with pytest.raises(BadValueError, match="no-such-effect"):
        Rig.virtual(effects=["no-such-effect"])


def test_a_missing_port_is_a_link_error():
    with pytest.raises(LinkError, match="/dev/does-not-exist"):
        Rig.open("/dev/does-not-exist")
    # A LinkError is an OSError: `except OSError` catches a port that is not there.
    with pytest.raises(OSError):
        Rig.open("/dev/does-not-exist")


def test_errors_sit_under_the_standard_exceptions(tmp_path):
    import traceback

    import backdrive_rig as br

    standard = {
        br.BadValueError: ValueError,
        br.MissingFileError: FileNotFoundError,
        br.NoReplyError: TimeoutError,
        br.LinkError: OSError,
    }
    for ours, std in standard.items():
        assert issubclass(ours, std) and issubclass(ours, br.RigError), ours
    for name in ("RefusedError", "VersionMismatchError", "DeviceFaultError", "RigClosedError"):
        assert issubclass(getattr(br, name), br.RigError), name
    assert issubclass(br.MissingFileError, br.BadValueError)
    # Named as the package exports them, in tracebacks too.
    for cls in standard:
        assert cls.__module__ == "backdrive_rig" and cls.__qualname__ == cls.__name__
    # A missing file is a FileNotFoundError wherever a path is given.
    with pytest.raises(FileNotFoundError, match="missing.toml"):
        Rig.virtual(model=tmp_path / "missing.toml")
    with pytest.raises(FileNotFoundError, match="missing.csv"):
        br.explain(tmp_path / "missing.csv")
    # A gear of three tooth counts is a bad value like every other.
    with pytest.raises(br.BadValueError, match="four tooth counts") as e:
        br.design(z=[49, 51, 50])
    line = traceback.format_exception_only(e.type, e.value)[-1]
    assert line.startswith("backdrive_rig.BadValueError: design: z [49, 51, 50]"), line
    assert "_native" not in line and "RigError_" not in line


# Protocol v1's `Info` reply (protocol/src/compat.rs, from v1's golden bytes).
V1_INFO_FRAME = bytes([
    0x02, 0x07, 0x01, 0x1C, 0x01, 0x02, 0x01, 0xEF, 0xFD, 0xB6, 0xF5, 0x0D, 0x0D, 0x6E, 0x75,
    0x63, 0x6C, 0x65, 0x6F, 0x2D, 0x67, 0x34, 0x37, 0x34, 0x72, 0x65, 0x01, 0xFC, 0x5D, 0xDA,
    0x0A, 0x00,
])


def fake_device(answer: bytes):
    """A pseudo-terminal whose device answers every frame with `answer`."""
    master, slave = pty.openpty()
    tty.setraw(slave)
    stop = threading.Event()

    def serve():
        buf = b""
        while not stop.is_set():
            try:
                chunk = os.read(master, 4096)
            except OSError:
                return
            buf += chunk
            while b"\x00" in buf:
                frame, buf = buf.split(b"\x00", 1)
                if frame and answer:
                    os.write(master, b"\x00" + answer)

    t = threading.Thread(target=serve, daemon=True)
    t.start()
    return os.ttyname(slave), stop, (master, slave)


def test_an_older_device_is_refused_naming_what_to_update():
    port, stop, fds = fake_device(V1_INFO_FRAME)
    try:
        with pytest.raises(VersionMismatchError) as e:
            Rig.open(port)
        msg = str(e.value)
        assert "1" in msg and "update" in msg.lower()
    finally:
        stop.set()
        for fd in fds:
            os.close(fd)


def test_a_silent_device_is_no_reply_with_the_cli_hint():
    port, stop, fds = fake_device(b"")
    try:
        with pytest.raises(NoReplyError, match="nothing came back"):
            Rig.open(port)
    finally:
        stop.set()
        for fd in fds:
            os.close(fd)


def test_calls_from_several_threads_are_serialised(rig):
    errors = []

    def work():
        try:
            for _ in range(20):
                assert rig.faults()["latched"] == []
                assert rig.info().board == "virtual"
        except Exception as e:  # pragma: no cover - reported below
            errors.append(e)

    threads = [threading.Thread(target=work) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []


def test_a_closed_rig_says_so():
    r = Rig.virtual(speed=10)
    r.close()
    with pytest.raises(RigError, match="closed"):
        r.info()


def test_virtual_rig_from_a_rig_file(tmp_path):
    path = tmp_path / "rig.toml"
    path.write_text("[limits]\nmax_freq_hz = 12.0\n")
    # A plain rig file puts its rig (here its limits) on the virtual device.
    with Rig.virtual(model=path, speed=10) as rig:
        assert rig.parameters()["limits"]["max_freq_hz"] == pytest.approx(12.0)
    with pytest.raises(BadValueError, match="missing.toml"):
        Rig.virtual(model=tmp_path / "missing.toml")
