"""The FMUs' win64 binaries, proven under Wine against the linux64 ones (issue 11, parts 1-2).

One plain C host (tests/hosts/fmu_host.c) is built natively and with mingw-w64; each runs the same
reference cases (the plant's open-loop case, plant and controller in a loop) on its platform's binaries.
The FMI 3.0 plant (Plant3) has its own host (tests/hosts/fmi3_host.c): Co-Simulation and Model Exchange.
The seesaw (issue 20) runs in both hosts in the plant's place: Seesaw.fmu in fmu_host.c, Seesaw3.fmu in fmi3_host.c.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmi_harness import hanging_plant_run
from fmpy import read_model_description

from pendulab.fmu.build import FMI_HEADERS, WIN64_COMPILER

HOST = Path(__file__).parent / "hosts" / "fmu_host.c"
WINE = shutil.which("wine64") or ("/usr/lib/wine/wine64" if Path("/usr/lib/wine/wine64").exists() else None)
SUFFIX = {"linux64": ".so", "win64": ".dll"}
#: FMI 3.0 names the same two platforms by architecture and system.
SUFFIX3 = {"x86_64-linux": ".so", "x86_64-windows": ".dll"}


def binaries(fmu: Path) -> dict[str, str]:
    """Platform folder -> the binary's path in the FMU, for the FMU's FMI version."""
    suffixes = SUFFIX3 if read_model_description(str(fmu)).fmiVersion.startswith("3.") else SUFFIX
    return {platform_dir: f"binaries/{platform_dir}/{fmu.stem}{suffix}" for platform_dir, suffix in suffixes.items()}


def test_every_fmu_carries_both_platforms(plant_fmu, controller_fmu, supervisor_fmu, plant3_fmu, seesaw_fmu, seesaw3_fmu):
    """A missing binary for either platform fails here (an FMU built without mingw-w64 has no win64)."""
    for fmu in (plant_fmu, controller_fmu, supervisor_fmu, plant3_fmu, seesaw_fmu, seesaw3_fmu):
        names = set(zipfile.ZipFile(fmu).namelist())
        for platform_dir, path in binaries(fmu).items():
            assert path in names, (fmu.name, platform_dir)


def test_win64_dlls_import_only_what_windows_has(plant_fmu, controller_fmu, supervisor_fmu, plant3_fmu, seesaw_fmu, seesaw3_fmu,
                                                 tmp_path):
    for fmu in (plant_fmu, controller_fmu, supervisor_fmu, plant3_fmu, seesaw_fmu, seesaw3_fmu):
        dll = tmp_path / f"{fmu.stem}.dll"
        dll.write_bytes(zipfile.ZipFile(fmu).read([p for p in binaries(fmu).values() if p.endswith(".dll")][0]))
        dump = subprocess.run(["x86_64-w64-mingw32-objdump", "-p", str(dll)], capture_output=True, text=True, check=True).stdout
        imports = {line.split(":")[1].strip().lower() for line in dump.splitlines() if "DLL Name:" in line}
        assert imports == {"kernel32.dll", "msvcrt.dll"}, (fmu.name, imports)


@pytest.fixture(scope="module")
def wineprefix(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One Wine prefix for the module's hosts: Wine sets it up on its first run (seconds of CPU); the others reuse it."""
    return tmp_path_factory.mktemp("wine") / "prefix"


def _run_host(source: Path, windows: bool, folder: Path, arguments: list[str], wineprefix: Path) -> list[np.ndarray]:
    """Compile the C host ``source`` for linux64 (cc) or win64 (mingw-w64) and run it, the win64 one under Wine,
    with ``arguments`` (its binaries must already be in ``folder``): the numbers of its last two lines."""
    exe = folder / (source.stem + (".exe" if windows else ""))
    compiler, libs = (WIN64_COMPILER, ["-lm"]) if windows else ("cc", ["-ldl", "-lm"])
    subprocess.run([compiler, "-std=c99", "-O1", f"-I{FMI_HEADERS}", str(source), "-o", str(exe), *libs],
                   check=True, capture_output=True)
    command = [WINE, str(exe)] if windows else [str(exe)]
    env = {**os.environ, "WINEDEBUG": "-all", "WINEPREFIX": str(wineprefix)}
    run = subprocess.run(command + arguments, capture_output=True, text=True, timeout=300, env=env)
    assert run.returncode == 0, (exe.name, run.stdout, run.stderr)
    lines = [line for line in run.stdout.splitlines() if line.strip()]
    return [np.array([float(v) for v in line.split()]) for line in lines[-2:]]


def _arguments(fmus: tuple[Path, Path, Path], folder: Path, platform_dir: str, angle: str = "alpha") -> list[str]:
    args = []
    for fmu in fmus:
        binary = folder / f"{fmu.stem}{SUFFIX[platform_dir]}"
        binary.write_bytes(zipfile.ZipFile(fmu).read(f"binaries/{platform_dir}/{fmu.stem}{SUFFIX[platform_dir]}"))
        args += [str(binary), read_model_description(str(fmu)).guid]
    plant, ctl, sup = ({v.name: v.valueReference for v in read_model_description(str(f)).modelVariables} for f in fmus)
    refs = [plant[n] for n in ("V", "x", "xdot", angle, f"{angle}dot", f"{angle}_measured", "x_measured")]
    refs += [ctl[n] for n in ("alpha_measured", "V_command", "n", "A[1,1]", "B[1]", "C[1]", "D")]
    refs += [sup[n] for n in ("V_command", "alpha_measured", "x_measured", "V")]
    return args + ["1500"] + [str(r) for r in refs]


@pytest.mark.skipif(WINE is None or shutil.which(WIN64_COMPILER) is None, reason="needs mingw-w64 and wine64 (.ci/run installs both)")
def test_win64_binaries_under_wine_equal_linux64(plant_fmu, controller_fmu, supervisor_fmu, tmp_path, wineprefix):
    """The plant's open-loop case and the loop of the three FMUs: Wine's results equal linux64's to 1e-12."""
    results = {}
    for platform_dir in ("linux64", "win64"):
        folder = tmp_path / platform_dir
        folder.mkdir()
        arguments = _arguments((plant_fmu, controller_fmu, supervisor_fmu), folder, platform_dir)
        results[platform_dir] = _run_host(HOST, platform_dir == "win64", folder, arguments, wineprefix)
    for linux, windows in zip(results["linux64"], results["win64"]):
        assert np.all(np.isfinite(linux)) and np.any(linux != 0)
        print("\nlinux64", linux, "\nwin64  ", windows, "\nmax |difference|", np.max(np.abs(windows - linux)))
        np.testing.assert_allclose(windows, linux, rtol=0, atol=1e-12)


HOST3 = Path(__file__).parent / "hosts" / "fmi3_host.c"


@pytest.mark.skipif(WINE is None or shutil.which(WIN64_COMPILER) is None, reason="needs mingw-w64 and wine64 (.ci/run installs both)")
def test_fmi3_plant_win64_under_wine_equals_linux64_and_fmi2(plant_fmu, plant3_fmu, tmp_path, wineprefix):
    """Plant3's x86_64-windows DLL under Wine (tests/hosts/fmi3_host.c: Co-Simulation open loop, Model Exchange
    with state and time events) equals its x86_64-linux binary to 1e-12, and the Co-Simulation case equals
    the FMI 2.0 plant's."""
    md = read_model_description(str(plant3_fmu))
    refs = {v.name: v.valueReference for v in md.modelVariables}
    steps = 1500
    results = {}
    for platform_dir in ("x86_64-linux", "x86_64-windows"):
        folder = tmp_path / platform_dir
        folder.mkdir()
        binary = folder / f"Plant3{SUFFIX3[platform_dir]}"
        binary.write_bytes(zipfile.ZipFile(plant3_fmu).read(f"binaries/{platform_dir}/{binary.name}"))
        arguments = [str(binary), md.guid, str(steps), *(str(refs[n]) for n in ("V", "x", "xdot", "alpha", "alphadot"))]
        results[platform_dir] = _run_host(HOST3, platform_dir == "x86_64-windows", folder, arguments, wineprefix)
    linux, windows = results["x86_64-linux"], results["x86_64-windows"]
    state_events, time_events = linux[1][4:]
    assert state_events > 0 and time_events == 2, "Model Exchange met friction switches and the poke's two edges"
    for a, b in zip(linux, windows):
        print("\nx86_64-linux  ", a, "\nx86_64-windows", b, "\nmax |difference|", np.max(np.abs(a - b)))
        assert np.all(np.isfinite(a)) and np.any(a[:4] != 0)
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-12)
    fmi2 = hanging_plant_run(plant_fmu, steps)[-1]  # fmi3_host.c's open-loop case on the FMI 2.0 plant, through fmpy
    print("FMI 2.0 plant, same case:", fmi2, "max |difference|", np.max(np.abs(fmi2 - linux[0])))
    np.testing.assert_allclose(linux[0], fmi2, rtol=0, atol=1e-12)


@pytest.mark.skipif(WINE is None or shutil.which(WIN64_COMPILER) is None, reason="needs mingw-w64 and wine64 (.ci/run installs both)")
def test_seesaw_win64_under_wine_equals_linux64(seesaw_fmu, seesaw3_fmu, controller_fmu, supervisor_fmu, tmp_path, wineprefix):
    """The seesaw's win64 binaries under Wine equal its linux64 ones to 1e-12: Seesaw.fmu in fmu_host.c's two cases
    (12 V sine open loop from a 0.05 rad tilt: onto the track's stop; the loop of three FMUs from 0.01 rad: onto a
    tilt stop), Seesaw3.fmu in fmi3_host.c's (Co-Simulation, and Model Exchange from 0.05 rad with state events and
    the tap's two edges as time events); FMI 3.0's Co-Simulation case equals FMI 2.0's."""
    steps, angles = 1500, ["0.05", "0.01"]
    results = {}
    for platform_dir in ("linux64", "win64"):
        folder = tmp_path / platform_dir
        folder.mkdir()
        arguments = _arguments((seesaw_fmu, controller_fmu, supervisor_fmu), folder, platform_dir, angle="theta")
        results[platform_dir] = _run_host(HOST, platform_dir == "win64", folder, arguments + angles, wineprefix)
    md3 = read_model_description(str(seesaw3_fmu))
    refs3 = {v.name: v.valueReference for v in md3.modelVariables}
    for platform_dir in ("x86_64-linux", "x86_64-windows"):
        folder = tmp_path / platform_dir
        folder.mkdir()
        binary = folder / f"Seesaw3{SUFFIX3[platform_dir]}"
        binary.write_bytes(zipfile.ZipFile(seesaw3_fmu).read(f"binaries/{platform_dir}/{binary.name}"))
        arguments = [str(binary), md3.guid, str(steps), *(str(refs3[n]) for n in ("V", "x", "xdot", "theta", "thetadot")), "0.05", "0.05"]
        results[platform_dir] = _run_host(HOST3, platform_dir == "x86_64-windows", folder, arguments, wineprefix)
    for linux, windows in (("linux64", "win64"), ("x86_64-linux", "x86_64-windows")):
        for a, b in zip(results[linux], results[windows]):
            print(f"\n{linux}", a, f"\n{windows}", b, "\nmax |difference|", np.max(np.abs(b - a)))
            assert np.all(np.isfinite(a)) and np.any(a[:4] != 0)
            np.testing.assert_allclose(b, a, rtol=0, atol=1e-12)
    starts = {v.name: v.start for v in read_model_description(str(seesaw_fmu)).modelVariables}
    assert abs(results["linux64"][0][0]) == float(starts["track_half_length"]), "the open loop ends on a track stop"
    assert abs(results["linux64"][1][2]) == float(starts["theta_stop"]), "the loop (a pendulum's gains) ends on a tilt stop"
    state_events, time_events = results["x86_64-linux"][1][4:]
    assert state_events > 0 and time_events == 2, "Model Exchange met the switches and the tap's two edges"
    np.testing.assert_allclose(results["x86_64-linux"][0], results["linux64"][0], rtol=0, atol=1e-12)


PLAN_HOST = Path(__file__).parent / "hosts" / "plan_host.c"


def _plan_reference() -> list[np.ndarray]:
    """What tests/hosts/plan_host.c must print, computed here: the plan's semantics in Python."""
    state, steps, rows = 1.0, 0, []
    for k in range(10):
        rows += [state + 0, state + 1]
        state += 0.25 * rows[-1]
        if k == 9:
            break  # the barrier: no step after the last point
        steps += 1
        state = 0.5 * state + 0.1 * k + 0.1
    first = np.array([-1, steps, *rows])
    state = 1.0
    for k in range(10):
        state += 0.25 * (state + 1)
        if 0.1 * k >= 0.5:
            return [first, np.array([4, k, state])]  # op 4 (the step) failed at point k
        state = 0.5 * state + 0.1 * k + 0.1
    raise AssertionError("unreachable")


def plan_runner_binary(folder: Path, windows: bool) -> Path:
    """The plan runner as a wheel ships it: from the built wheel in $PENDULAB_WHEEL_DIR, else compiled the same way."""
    from pendulab.cosim.master import PLAN_RUNNER_FLAGS, PLAN_RUNNER_SOURCE
    from pendulab.native import compile_shared, library_name

    name = library_name(PLAN_RUNNER_SOURCE.read_bytes(), PLAN_RUNNER_SOURCE.stem, PLAN_RUNNER_FLAGS,
                        system="Windows" if windows else "Linux")
    wheels = sorted(Path(os.environ.get("PENDULAB_WHEEL_DIR", "/nonexistent")).glob(f"*{'win_amd64' if windows else 'manylinux'}*.whl"))
    target = folder / name
    if wheels:
        target.write_bytes(zipfile.ZipFile(wheels[-1]).read(f"pendulab/prebuilt/{name}"))
    else:
        compile_shared(WIN64_COMPILER if windows else "cc", [PLAN_RUNNER_SOURCE], target, flags=PLAN_RUNNER_FLAGS, windows=windows)
    return target


@pytest.mark.skipif(WINE is None or shutil.which(WIN64_COMPILER) is None, reason="needs mingw-w64 and wine64 (.ci/run installs both)")
def test_plan_runner_dll_runs_under_wine_like_linux64(tmp_path, wineprefix):
    """The win64 step-plan runner a wheel carries: loads in a C host under Wine, runs a plan (reads, a connection,
    writes, the barrier, steps) and stops at a failing step exactly as the linux64 one does; imports only
    KERNEL32 and msvcrt."""
    results = {}
    for platform_dir in ("linux64", "win64"):
        folder = tmp_path / platform_dir
        folder.mkdir()
        library = plan_runner_binary(folder, platform_dir == "win64")
        results[platform_dir] = _run_host(PLAN_HOST, platform_dir == "win64", folder, [str(library)], wineprefix)
    dump = subprocess.run(["x86_64-w64-mingw32-objdump", "-p", str(library)], capture_output=True, text=True, check=True).stdout
    assert {line.split(":")[1].strip().lower() for line in dump.splitlines() if "DLL Name:" in line} == {"kernel32.dll", "msvcrt.dll"}
    for linux, windows, reference in zip(results["linux64"], results["win64"], _plan_reference()):
        np.testing.assert_array_equal(linux, reference)
        np.testing.assert_array_equal(windows, reference)
