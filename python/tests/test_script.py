"""The issue's "done when" as a user runs it: a plain script in the fresh environment against
`rig sim serve` with a hidden effect (docs/examples/backdrive_rig_script.py)."""

import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[2] / "docs" / "examples" / "backdrive_rig_script.py"


def test_the_example_script_runs_on_a_served_rig(served_with_effect):
    out = subprocess.run(
        [sys.executable, str(SCRIPT), served_with_effect.port],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    recorded = lines[1].split()
    assert recorded[0] == "recorded" and 1995 <= int(recorded[1]) <= 2001, out.stdout
    assert lines[1].endswith("samples, 0 lost"), out.stdout
    assert lines[2] == "quick sweep: 30 rows"
    assert "speed-dependent-axial-friction" in lines[3]
