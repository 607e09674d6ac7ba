"""``pendulab calibrate --port``: the ramp test over the link against an emulator with a friction of our choosing."""

from __future__ import annotations

import json
import sys

import pytest
from hil_helpers import ENV, PYTHON, emulator

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals are POSIX")

#: Not the lab's default [1.5, 0.005, 3.0, 0.05, 20]: every number differs.
TRUE = {"F1": 2.0, "v1": 0.004, "F2": 3.5, "v2": 0.04, "B": 25.0}


def test_calibrate_on_the_rig_recovers_the_friction(tmp_path):
    import subprocess

    out, log = tmp_path / "rig.json", tmp_path / "ramp.csv"
    friction = ",".join(str(v) for v in TRUE.values())
    with emulator("--pendulum", "none", "--friction", friction) as emu:
        result = subprocess.run(
            [PYTHON, "-m", "pendulab", "calibrate", "--port", emu.port, "--iterations", "1", "--pendulum", "none",
             "--out", str(out), "--log", str(log)],
            capture_output=True, text=True, timeout=120, env=ENV,
        )
        emu_text = emu.text
    assert result.returncode == 0, result.stdout + result.stderr
    assert "iteration 1/1" in result.stdout and "motor enabled" in emu_text
    data = json.loads(out.read_text())
    fitted = data["friction"] if isinstance(data["friction"], dict) else dict(zip(TRUE, data["friction"]))
    for name in ("F1", "F2", "B"):
        assert fitted[name] == pytest.approx(TRUE[name], rel=0.10), (name, fitted)
    assert "rig at" in json.dumps(data)
    assert log.read_text().count("\n") > 5000  # the ramp log for 'pendulab fit'


@pytest.mark.parametrize("args, fragment", [
    ([], "give the rig"),
    (["--virtual", "--port", "loop://"], "give the rig"),
    (["--port", "loop://", "--friction", "1,0.005,2,0.05,20"], "--friction"),
])
def test_calibrate_needs_exactly_one_rig(args, fragment):
    import subprocess

    result = subprocess.run([PYTHON, "-m", "pendulab", "calibrate", *args], capture_output=True, text=True, timeout=60, env=ENV)
    assert result.returncode == 2
    assert len(result.stderr.strip().splitlines()) == 1 and fragment in result.stderr
