"""The Python door from a plain script, against a served virtual rig:

    rig sim serve --json --preset ideal --effect speed-dependent-axial-friction --speed 10 &
    python docs/examples/backdrive_rig_script.py /dev/pts/N

Opens the port, releases for 2 s while recording 1 kHz telemetry, runs the quick torque
sweep and asks `explain` which effect the model misses. Ctrl-C at any point leaves the rig
locked.
"""

import sys

from backdrive_rig import Rig, explain

port = sys.argv[1]
with Rig.open(port) as rig:
    info = rig.info()
    print(f"{info.board} on {port}: firmware {info.firmware_version}, protocol {info.protocol_version}")
    with rig.release(freq_hz=10, seconds=2):
        telemetry = rig.record(seconds=2, rate_hz=1000)
    print(f"recorded {len(telemetry)} samples, {telemetry.attrs['lost']} lost")
    sweep = rig.torque_sweep(quick=True)
    print(f"quick sweep: {len(sweep)} rows")
result = explain(sweep)
print(f"explain: {result.verdict}; effects: {', '.join(e['name'] for e in result.effects)}")
