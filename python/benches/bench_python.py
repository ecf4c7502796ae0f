"""Benchmarks of the Python door (not tests: nothing here asserts a time).

    python python/benches/bench_python.py --rig target/debug/rig [--minutes 10] [--speed 10]

1. Recording: 1 kHz telemetry for `--minutes` of device time on the in-process virtual rig
   while a Python thread is busy the whole time (pure-Python arithmetic holding the GIL):
   samples received, samples lost (gaps in the device's counter), the rig's own link
   counters.
2. Round trip: `faults()` on a served rig (`rig sim serve`, real time) through Python, per
   call; `Rig.open(port)` + `faults()` + `close()` per call; and the CLI's `rig --port P
   faults --json` per process (what a script that shells out pays).
Prints one JSON object.
"""

import argparse
import json
import os
import subprocess
import sys
import threading
import time

from backdrive_rig import Rig


def record_under_load(minutes: float, speed: float) -> dict:
    seconds = minutes * 60.0
    with Rig.virtual(speed=speed) as rig:
        stop = threading.Event()
        spins = [0]

        def busy():
            while not stop.is_set():
                sum(i * i for i in range(2000))
                spins[0] += 1

        worker = threading.Thread(target=busy)
        worker.start()
        started = time.monotonic()
        cpu0 = time.process_time()
        rec = rig.recorder(rate_hz=1000, seconds=seconds)
        # Drain in chunks as a user would, keeping only counts (10 min is 600k rows).
        received = 0
        while not rec.done:
            time.sleep(1.0)
            received += len(rec.take(pandas=False)["seq"])
        rec.wait()
        received += len(rec.take(pandas=False)["seq"])
        wall = time.monotonic() - started
        stop.set()
        worker.join()
        stats = rig.link_stats()
        return {
            "device_s": seconds,
            "speed": speed,
            "wall_s": round(wall, 1),
            "process_cpu_s": round(time.process_time() - cpu0, 1),
            "expected_samples": int(seconds * 1000),
            "received_samples": received,
            "lost_samples": rec.lost,
            "gaps": len(rec.gaps),
            "busy_thread_iterations": spins[0],
            "link": dict(stats),
        }


def round_trips(rig_cli: str, n: int) -> dict:
    serve = subprocess.Popen(
        [rig_cli, "sim", "serve", "--json"], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True
    )
    try:
        port = json.loads(serve.stdout.readline())["port"]
        with Rig.open(port) as rig:
            rig.faults()
            t0 = time.perf_counter()
            for _ in range(n):
                rig.faults()
            per_call = (time.perf_counter() - t0) / n
        t0 = time.perf_counter()
        for _ in range(max(1, n // 10)):
            with Rig.open(port) as rig:
                rig.faults()
        open_call = (time.perf_counter() - t0) / max(1, n // 10)
        t0 = time.perf_counter()
        for _ in range(max(1, n // 10)):
            out = subprocess.run([rig_cli, "--port", port, "faults", "--json"], capture_output=True)
            assert out.returncode == 0, out.stderr
        cli = (time.perf_counter() - t0) / max(1, n // 10)
    finally:
        serve.send_signal(2)
        serve.wait()
    return {
        "python_faults_ms": round(per_call * 1e3, 2),
        "python_open_faults_close_ms": round(open_call * 1e3, 2),
        "cli_faults_process_ms": round(cli * 1e3, 2),
        "calls": n,
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rig", default=os.environ.get("BACKDRIVE_RIG_CLI", "rig"))
    p.add_argument("--minutes", type=float, default=10.0)
    p.add_argument("--speed", type=float, default=10.0)
    p.add_argument("--calls", type=int, default=200)
    a = p.parse_args()
    out = {"round_trip": round_trips(a.rig, a.calls), "record": record_under_load(a.minutes, a.speed)}
    json.dump(out, sys.stdout, indent=2)
    print()


if __name__ == "__main__":
    main()
