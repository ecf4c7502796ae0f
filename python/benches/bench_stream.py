"""Benchmark of the continuous stream (issue 35; not a test: nothing here asserts a time).

    python python/benches/bench_stream.py --rig target/debug/rig [--minutes 10] [--rate 10000]

A served virtual rig (`rig sim serve --speed 1`: the board's time, its output paced at the
link's byte rate, 92,160 B/s at 921,600 Bd) streams every sample at `--rate` for
`--minutes` of device time into `Rig.stream()` while a second Python thread is busy the
whole time (pure-Python arithmetic holding the GIL). Reports the samples expected and
received, the samples lost and the gaps (the device's numbering end to end), the link's
use in percent of its byte rate, and the CPU use of this process (Python and its port
thread) and of the served rig's process. Prints one JSON object.
"""

import argparse
import json
import os
import subprocess
import sys
import threading
import time

import numpy as np

from backdrive_rig import Rig, RigError

#: The link's byte rate at 921,600 Bd, 8N1 (protocol::link_bytes_per_s).
LINK_BYTES_PER_S = 921_600 // 10


def cpu_s(pid: int) -> float:
    """User + system CPU seconds of process `pid` (Linux /proc)."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def port_thread_cpu_s() -> float:
    """CPU seconds of this process's port threads (the Rust thread that reads the link,
    named `backdrive_rig port`; Linux truncates thread names to 15 bytes)."""
    total = 0.0
    for tid in os.listdir("/proc/self/task"):
        try:
            with open(f"/proc/self/task/{tid}/comm") as f:
                if f.read().strip() != "backdrive_rig p":
                    continue
            with open(f"/proc/self/task/{tid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            total += (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
        except OSError:
            pass
    return total


def run(rig_cli: str, minutes: float, rate: int) -> dict:
    serve = subprocess.Popen(
        [rig_cli, "sim", "serve", "--json", "--speed", "1"],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        port = json.loads(serve.stdout.readline())["port"]
        seconds = minutes * 60.0
        with Rig.open(port) as rig:
            stop = threading.Event()
            spins = [0]

            def busy() -> None:
                while not stop.is_set():
                    sum(i * i for i in range(2000))
                    spins[0] += 1

            worker = threading.Thread(target=busy, daemon=True)
            worker.start()
            bytes0 = rig.link_stats()["bytes_in"]
            serve_cpu0, cpu0, started = cpu_s(serve.pid), time.process_time(), time.monotonic()
            port0 = port_thread_cpu_s()
            received, gaps_seen, next_seq = 0, 0, 0
            stopped_by = None
            with rig.stream(rate_hz=rate, seconds=seconds, chunk_s=1.0) as s:
              try:
                for chunk in s:
                    seq = chunk["seq"]
                    # The numbering end to end: a jump is a gap (also in s.gaps).
                    gaps_seen += int(seq[0] != next_seq) + int(np.count_nonzero(np.diff(seq) != 1))
                    next_seq = int(seq[-1]) + 1
                    received += len(seq)
                    if received % (60 * rate) < len(seq):
                        print(
                            f"{received / rate:.0f} s of samples, {s.lost} lost, "
                            f"{time.monotonic() - started:.0f} s wall",
                            file=sys.stderr,
                            flush=True,
                        )
              except RigError as e:
                # The figures up to the stop are still reported, with why it stopped.
                stopped_by = str(e)
            wall = time.monotonic() - started
            cpu = time.process_time() - cpu0
            serve_cpu = cpu_s(serve.pid) - serve_cpu0
            port_cpu = port_thread_cpu_s() - port0
            link_bytes = rig.link_stats()["bytes_in"] - bytes0
            stop.set()
            worker.join()
            device_s = received / rate if received else seconds
            return {
                "rate_hz": rate,
                "stopped_by": stopped_by,
                "device_s": seconds,
                "wall_s": round(wall, 1),
                "expected_samples": int(round(seconds * rate)),
                "received_samples": received,
                "lost_samples": s.lost,
                "gaps": len(s.gaps),
                "gaps_in_numbering": gaps_seen,
                "link_bytes": link_bytes,
                "link_use_percent": round(100.0 * link_bytes / (LINK_BYTES_PER_S * device_s), 1),
                "host_cpu_percent": round(100.0 * cpu / wall, 1),
                "port_thread_cpu_percent": round(100.0 * port_cpu / wall, 1),
                "served_rig_cpu_percent": round(100.0 * serve_cpu / wall, 1),
                "busy_thread_spins": spins[0],
            }
    finally:
        serve.terminate()
        serve.wait()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rig", default=os.environ.get("BACKDRIVE_RIG_CLI", "rig"))
    p.add_argument("--minutes", type=float, default=10.0)
    p.add_argument("--rate", type=int, default=10000)
    a = p.parse_args()
    print(json.dumps(run(a.rig, a.minutes, a.rate)))


if __name__ == "__main__":
    main()
