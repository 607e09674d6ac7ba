"""The README's commands for FMI engineers run as written (issue 25: the old one had a flag fmpy does not know).

Every line of the bash block under "For FMI engineers" but the build (which the FMU fixtures and
test_fmu_build run) is run from a folder holding ``fmus/``; the Python block after it runs on the demo's
``loop.ssp`` the bash block wrote.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

README = Path(__file__).resolve().parents[1] / "README.md"
BIN = Path(sys.executable).parent


def fmi_blocks() -> tuple[list[str], str]:
    section = README.read_text().split("## For FMI engineers", 1)[1]
    bash = re.search(r"```bash\n(.*?)```", section, re.S).group(1)
    python = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    return [line.split("  #")[0].strip() for line in bash.splitlines() if line.strip()], python


@pytest.fixture(scope="module")
def ran(plant_fmu, plant3_fmu, controller_fmu, supervisor_fmu, tmp_path_factory) -> Path:
    """Every command of the bash block, run in a fresh folder with the built FMUs in ``fmus/``."""
    work = tmp_path_factory.mktemp("readme")
    (work / "fmus").mkdir()
    for fmu in (plant_fmu, plant3_fmu, controller_fmu, supervisor_fmu):
        (work / "fmus" / fmu.name).symlink_to(fmu)
    commands, _ = fmi_blocks()
    assert commands[0].startswith("python build_fmus.py")
    for command in commands[1:]:
        argv = shlex.split(command)
        assert argv[0] in ("fmpy", "pendulab"), command
        result = subprocess.run([str(BIN / argv[0]), *argv[1:]], cwd=work, capture_output=True, text=True, timeout=300,
                                env={**os.environ, "PENDULAB_FMU_DIR": str(work / "fmus")})
        assert result.returncode == 0, f"{command}\n{result.stdout}\n{result.stderr}"
        if argv[1] == "validate":
            assert "No problems found" in result.stdout, result.stdout
    return work


def test_the_readme_commands_run_and_write_what_they_say(ran):
    me = np.genfromtxt(ran / "plant_me.csv", delimiter=",", names=True)
    cs = np.genfromtxt(ran / "plant_cs.csv", delimiter=",", names=True)
    assert me["time"][-1] == pytest.approx(3.0) and cs["time"][-1] == pytest.approx(3.0)
    # CVode's Model Exchange run and the RK4 Co-Simulation run: the same falling pendulum.
    assert abs(me["alpha"][-1]) > 1.0
    assert np.interp(2.0, me["time"], me["alpha"]) == pytest.approx(np.interp(2.0, cs["time"], cs["alpha"]), abs=1e-3)
    assert (ran / "plant3_me.csv").stat().st_size > 0 and (ran / "demo" / "loop.ssp").is_file()


def test_the_interface_flag_is_honoured(ran):
    """``--interface-type ModelExchange`` really asks for Model Exchange: a Co-Simulation-only FMU refuses it."""
    result = subprocess.run([str(BIN / "fmpy"), "simulate", "fmus/Controller.fmu", "--interface-type", "ModelExchange"],
                            cwd=ran, capture_output=True, text=True, timeout=120)
    assert result.returncode != 0 and "ModelExchange" in result.stderr + result.stdout


def test_the_readme_ssp_snippet_runs_in_fmpy_and_ecos(ran, capsys):
    pytest.importorskip("ecospy")
    _, snippet = fmi_blocks()
    cwd = Path.cwd()
    os.chdir(ran)
    try:
        exec(compile(snippet, "README.md", "exec"), {})  # noqa: S102 - the README's own example
    finally:
        os.chdir(cwd)
    fmpy_alpha, ecos_alpha = map(float, capsys.readouterr().out.split())
    assert fmpy_alpha == ecos_alpha and abs(fmpy_alpha) < 0.02  # balanced, and the two tools agree exactly
