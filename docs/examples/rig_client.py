#!/usr/bin/env python3
"""Talk to the rig (a board, or `rig sim serve`) from Python: Hello, GetInfo, one telemetry
sample. The whole wire format fits in a few lines (protocol/LAYOUT.md gives every byte):

    body  = postcard(seq: u16 varint, message)
    frame = 0x00 ++ COBS(body ++ CRC-32(body) little-endian) ++ 0x00

Usage:
    rig sim serve --json            # prints {"port": "/dev/pts/N", ...}
    python3 docs/examples/rig_client.py /dev/pts/N

Uses pyserial (pip install pyserial) when it is installed; otherwise, on Linux and macOS,
it opens the port as a raw file (enough for the served virtual rig's pseudo-terminal).
Prints one JSON object: the device's info and a telemetry sample.
"""

import json
import os
import select
import struct
import sys
import time
import zlib

PROTOCOL_VERSION = 8


# --- framing -------------------------------------------------------------------------

def cobs_encode(data: bytes) -> bytes:
    out, block = bytearray(), bytearray()
    for b in data:
        if b == 0:
            out += bytes([len(block) + 1]) + block
            block = bytearray()
        else:
            block.append(b)
            if len(block) == 254:
                out += bytes([255]) + block
                block = bytearray()
    return bytes(out + bytes([len(block) + 1]) + block)


def cobs_decode(data: bytes) -> bytes:
    out, i = bytearray(), 0
    while i < len(data):
        code = data[i]
        if code == 0 or i + code > len(data):
            raise ValueError("bad COBS")
        out += data[i + 1:i + code]
        i += code
        if code < 255 and i < len(data):
            out.append(0)
    return bytes(out)


def frame(body: bytes) -> bytes:
    crc = struct.pack("<I", zlib.crc32(body) & 0xFFFFFFFF)
    return b"\x00" + cobs_encode(body + crc) + b"\x00"


def unframe(run: bytes):
    """The body of one run between delimiters, or None (noise, bad CRC)."""
    try:
        raw = cobs_decode(run)
    except ValueError:
        return None
    if len(raw) < 5 or struct.pack("<I", zlib.crc32(raw[:-4]) & 0xFFFFFFFF) != raw[-4:]:
        return None
    return raw[:-4]


# --- postcard ------------------------------------------------------------------------

def varint(n: int) -> bytes:
    out = bytearray()
    while True:
        b = n & 0x7F
        n >>= 7
        out.append(b | (0x80 if n else 0))
        if not n:
            return bytes(out)


class Reader:
    def __init__(self, data: bytes):
        self.data, self.pos = data, 0

    def varint(self) -> int:
        n = shift = 0
        while True:
            b = self.data[self.pos]
            self.pos += 1
            n |= (b & 0x7F) << shift
            shift += 7
            if not b & 0x80:
                return n

    def u8(self) -> int:
        self.pos += 1
        return self.data[self.pos - 1]

    def f32(self) -> float:
        self.pos += 4
        return struct.unpack("<f", self.data[self.pos - 4:self.pos])[0]

    def string(self) -> str:
        n = self.varint()
        self.pos += n
        return self.data[self.pos - n:self.pos].decode()


# Request tags (LAYOUT.md, `Request`).
HELLO, GET_INFO, START_TELEMETRY, STOP_TELEMETRY = 0, 1, 6, 7
# DeviceMessage tags and Reply tags.
MSG_REPLY, MSG_TELEMETRY = 0, 1
REPLY_INFO, REPLY_NACK, REPLY_ACK = 0, 1, 2
STATES = ["locked", "spin_up", "vibrating", "stopping", "fault"]


# --- the port ------------------------------------------------------------------------

class Port:
    def __init__(self, name: str):
        try:
            import serial  # pyserial
            self.s = serial.Serial(name, 921600, timeout=0.05)
            self.read = lambda: self.s.read(4096)
            self.write = self.s.write
        except ImportError:
            import termios
            import tty
            fd = os.open(name, os.O_RDWR | os.O_NOCTTY)
            tty.setraw(fd, termios.TCSANOW)
            self.read = lambda: os.read(fd, 4096) if select.select([fd], [], [], 0.05)[0] else b""
            self.write = lambda b: os.write(fd, b)
        self.buf, self.seq = bytearray(), 0
        self.write(b"\x00")  # the device drops any half-received frame

    def send(self, message: bytes) -> int:
        self.seq = (self.seq + 1) & 0xFFFF
        self.write(frame(varint(self.seq) + message))
        return self.seq

    def messages(self, timeout: float):
        """Yields (tag, Reader) of each device message until `timeout` s pass."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            self.buf += self.read()
            while b"\x00" in self.buf:
                run, _, rest = bytes(self.buf).partition(b"\x00")
                self.buf = bytearray(rest)
                body = unframe(run) if run else None
                if body is None:
                    continue
                r = Reader(body)
                r.varint()  # the device's seq
                yield r.varint(), r

    def request(self, message: bytes, timeout: float = 1.0) -> Reader:
        """Sends `message`; returns the Reader at the reply's tag (Info, Nack, ...)."""
        seq = self.send(message)
        for tag, r in self.messages(timeout):
            if tag == MSG_REPLY and r.varint() == seq:
                return r
        raise TimeoutError("no reply")


def info(r: Reader) -> dict:
    return {
        "protocol_version": r.varint(),
        "schema_hash": r.varint(),
        "firmware_version": "%d.%d.%d" % (r.u8(), r.u8(), r.u8()),
        "firmware_build": r.string(),
        "board": r.string(),
    }


def main() -> int:
    if len(sys.argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    port = Port(sys.argv[1])
    # Hello with the schema hash this script does not know: the device answers
    # Nack(VersionMismatch) with its own, and a second Hello with it opens the session.
    schema_hash = 0
    for _ in range(3):
        r = port.request(bytes([HELLO]) + varint(PROTOCOL_VERSION) + varint(schema_hash))
        tag = r.varint()
        if tag == REPLY_INFO:
            break
        if tag == REPLY_NACK and r.varint() == 0:  # VersionMismatch
            device_protocol, schema_hash = r.varint(), r.varint()
            if device_protocol != PROTOCOL_VERSION:
                print("the device speaks protocol %d, this script %d" % (device_protocol, PROTOCOL_VERSION), file=sys.stderr)
                return 1
    r = port.request(bytes([GET_INFO]))
    if r.varint() != REPLY_INFO:
        print("GetInfo refused", file=sys.stderr)
        return 1
    result = {"info": info(r)}
    port.request(bytes([START_TELEMETRY]) + varint(50))
    for tag, r in port.messages(2.0):
        if tag == MSG_TELEMETRY:
            result["telemetry"] = {
                "seq": r.varint(),
                "device_time_us": r.varint(),
                "cam_speed_rad_s": r.f32(),
                "current_a": r.f32(),
                "pwm_duty": r.f32(),
                "tau_cam_nm": r.f32(),
                "tau_rot_nm": r.f32(),
                "state": STATES[r.varint()],
            }
            break
    port.request(bytes([STOP_TELEMETRY]))
    print(json.dumps(result))
    return 0 if "telemetry" in result else 1


if __name__ == "__main__":
    sys.exit(main())
