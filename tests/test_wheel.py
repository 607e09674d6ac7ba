"""The linux wheel installed in a fresh virtual environment, with every C compiler hidden (issue 23).

One module-scoped environment (the wheel is built once, or taken from ``$PENDULAB_WHEEL_DIR`` where CI's
``build_wheels.py`` step already built it):

* a fresh venv with the wheel installed (``pip install --no-deps``); its third-party dependencies are the
  test environment's, seen through a path in a ``.pth`` file (reinstalling 300 MB of numpy, scipy, casadi
  and matplotlib from the registry would cost more than everything else here; the win_amd64 resolution test
  resolves them from the registry);
* PATH holds only the venv's ``bin/`` and fake compilers (``cc``, ``gcc``, ``clang``, ``c99``,
  ``x86_64-w64-mingw32-gcc``) that record each call and fail; ``CC`` is unset; HOME, the caches and the
  working folder are new and empty.

The README's install section is run as written; then a lab session against the rig emulator, and the
calibration's ramp test and ``fit`` (which, without a compiler, evaluates its functions in CasADi's
virtual machine and says so).
"""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
import sysconfig
import time
import zipfile
from pathlib import Path

import pytest
from hil_helpers import PortProcess, ended_by, last_line, until_the_link_holds

REPO = Path(__file__).resolve().parents[1]
FAKE_COMPILERS = ("cc", "gcc", "clang", "c99", "tcc", "x86_64-w64-mingw32-gcc")

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="builds and runs the linux x86_64 wheel")


def _readme_install_commands() -> list[str]:
    """The commands of the README's 'Install on a lab PC' section, as a user types them."""
    text = (REPO / "README.md").read_text()
    section = text.split("## Install on a lab PC", 1)[1].split("\n## ", 1)[0]
    block = re.search(r"```bash\n(.*?)```", section, re.S).group(1)  # type: ignore[union-attr]
    return [line.split("#", 1)[0].strip() for line in block.splitlines() if line.split("#", 1)[0].strip()]


def _linux_wheel(folder: Path) -> tuple[Path, float]:
    """The linux wheel (CI's, or built now) and the seconds its build took here (0 if CI's)."""
    shared = sorted(Path(os.environ.get("PENDULAB_WHEEL_DIR", "/nonexistent")).glob("pendulab-*-manylinux*_x86_64.whl"))
    if shared:
        return shared[-1], 0.0
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "build", "--no-isolation", "--skip-dependency-check", "--wheel", "--outdir", str(folder), str(REPO)],
                   check=True, capture_output=True, timeout=900)
    return next(folder.glob("pendulab-*.whl")), time.perf_counter() - start


class Env:
    """The fresh venv and how to run commands in it with no compiler on the PATH."""

    def __init__(self, root: Path):
        self.root = root
        self.venv = root / "venv"
        self.work = root / "work"
        self.calls = root / "compiler-calls.txt"
        self.env = {
            "PATH": f"{self.venv / 'bin'}{os.pathsep}{root / 'fake-compilers'}",
            "HOME": str(root / "home"), "XDG_CACHE_HOME": str(root / "cache"), "MPLBACKEND": "Agg",
            "PYTHONUNBUFFERED": "1", "LANG": "C.UTF-8",
        }

    def run(self, command: str | list[str], timeout: float = 300, fakes: bool = True) -> subprocess.CompletedProcess:
        """Run ``command`` in the work folder; ``fakes=False``: no compiler at all on the PATH, not even a fake."""
        argv = shlex.split(command) if isinstance(command, str) else command
        env = self.env if fakes else {**self.env, "PATH": str(self.venv / "bin")}
        return subprocess.run(argv, cwd=self.work, env=env, capture_output=True, text=True, timeout=timeout)

    def compiler_calls(self) -> list[str]:
        return self.calls.read_text().splitlines() if self.calls.exists() else []


@pytest.fixture(scope="module")
def wheel_env(tmp_path_factory):
    root = tmp_path_factory.mktemp("wheel")
    wheel, build_seconds = _linux_wheel(root / "dist")
    env = Env(root)
    for folder in ("home", "cache", "work", "fake-compilers"):
        (root / folder).mkdir()
    for name in FAKE_COMPILERS:
        fake = root / "fake-compilers" / name
        fake.write_text(f'#!/bin/sh\necho "{name} $*" >> {env.calls}\nexit 1\n')
        fake.chmod(0o755)
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(env.venv)], check=True, timeout=120)
    site = Path(subprocess.check_output([env.venv / "bin" / "python", "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                                        text=True).strip())
    (site / "test_dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")

    # The README, as written; 'pip install <wheel>' is timed to the first run.mat.
    timeline, outputs = {}, []
    start = time.perf_counter()
    for command in _readme_install_commands():
        argv = shlex.split(command)
        if argv[:2] == ["pip", "install"]:
            argv = [sys.executable, "-m", "pip", "--python", str(env.venv / "bin" / "python"), "install", "--no-deps", "-q", str(wheel)]
        run = env.run(argv)
        outputs.append((command, run))
        timeline[command] = time.perf_counter() - start
    return {"env": env, "wheel": wheel, "build_seconds": build_seconds, "outputs": outputs, "timeline": timeline}


def test_wheel_has_the_prebuilt_parts_and_a_platform_tag(wheel_env):
    wheel = wheel_env["wheel"]
    names = zipfile.ZipFile(wheel).namelist()
    assert re.fullmatch(r"pendulab-[\d.]+-py3-none-manylinux_2_\d+_x86_64\.whl", wheel.name), wheel.name
    fmus = {n.rsplit("/", 1)[1] for n in names if n.startswith("pendulab/prebuilt/fmus/")}
    assert {"Plant.fmu", "Controller.fmu", "Supervisor.fmu", "Plant3.fmu"} <= fmus
    for fmu in fmus:
        inside = zipfile.ZipFile(zipfile.ZipFile(wheel).open(f"pendulab/prebuilt/fmus/{fmu}")).namelist()
        assert any(n.endswith(".so") for n in inside) and any(n.endswith(".dll") for n in inside), fmu
        assert any(n.startswith("sources/") for n in inside), fmu
    assert [n for n in names if re.fullmatch(r"pendulab/prebuilt/plan_runner-[0-9a-f]{12}\.so", n)]
    print(f"\n{wheel.name}: {wheel.stat().st_size / 1e6:.2f} MB; built in {wheel_env['build_seconds']:.1f} s")


def test_readme_install_runs_without_a_compiler(wheel_env):
    env: Env = wheel_env["env"]
    for command, run in wheel_env["outputs"]:
        assert run.returncode == 0, (command, run.stdout[-2000:], run.stderr[-2000:])
    out = env.work / "runs" / "demo"
    for name in ("run.mat", "run.csv", "metrics.json"):
        assert (out / name).stat().st_size > 0, name
    assert list(out.glob("*.png")), "the plots"
    assert env.compiler_calls() == [], "nothing was compiled"
    # The FMUs and the plan runner came from inside the installed package.
    probe = env.run([str(env.venv / "bin" / "python"), "-c",
                     "from pendulab.fmu.build import ensure_fmu; from pendulab.cosim import master; from pendulab.native import shared_library;"
                     "print(ensure_fmu('Plant')); print(shared_library(master.PLAN_RUNNER_SOURCE, flags=master.PLAN_RUNNER_FLAGS).path);"
                     "print(master.native_runner() is not None)"])
    plant, runner, native = probe.stdout.split()
    assert "site-packages/pendulab/prebuilt/fmus/Plant.fmu" in plant and "site-packages/pendulab/prebuilt/plan_runner-" in runner
    assert native == "True"
    assert not (env.root / "cache" / "pendulab").exists(), "nothing was built into the cache"
    first = next(t for c, t in wheel_env["timeline"].items() if "simulate" in c)
    print(f"\npip install (no deps) to the first run.mat: {first:.1f} s")


def _lab_session(env: Env, out: str) -> tuple[int, str, str]:
    """``lab --demo`` against ``rig-emulator``: started, 5 s of balancing after the hand lets go, ended by the key."""
    pendulab = str(env.venv / "bin" / "pendulab")
    emulator = PortProcess([pendulab, "rig-emulator", "--raise-after", "0.3", "--poke", "150,0.005,1"], env=env.env, cwd=env.work)
    try:
        lab = subprocess.Popen([pendulab, "lab", "--port", emulator.port, "--demo", "--max-delay", "8", "--out", out],
                               stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env.env, cwd=env.work)
        lab.stdin.write("s\n")  # type: ignore[union-attr]
        lab.stdin.flush()  # type: ignore[union-attr]
        emulator.wait_for("hand released", timeout=30)
        time.sleep(5.0)
        try:
            lab.stdin.write("e\n")  # type: ignore[union-attr]
            lab.stdin.flush()  # type: ignore[union-attr]
        except BrokenPipeError:
            pass  # it ended on its own; its output says why
        stdout, stderr = lab.communicate(timeout=60)
    finally:
        emulator.stop()
    return lab.returncode, stdout, stderr


#: How a session ends when this machine, not pendulab, is too slow for a 1 kHz link (as in test_hil_lab_modes).
HOST_TOO_SLOW = ("the link is too slow", "the host's answers stopped reaching it in time", "while setting up the session",
                 "stopped streaming samples")


def test_lab_demo_against_the_rig_emulator_for_5_s(wheel_env):
    """As in test_hil_lab: a session on a loaded machine may lose its real-time link (the rig's watchdog trips, the
    lab ends with the motor off and the log kept, as on a rig); that is printed and the session run again (at most
    three in all). Any other ending fails at once."""
    env: Env = wheel_env["env"]

    def session(attempt: int):
        out = f"runs/lab-{attempt}"
        return (out, *_lab_session(env, out))

    def lost(run) -> str | None:
        _, status, stdout, stderr = run
        return f"status {status}: {last_line(stdout)}" if status != 0 and ended_by(stdout + stderr, HOST_TOO_SLOW) else None

    out, status, stdout, stderr = until_the_link_holds(session, lost)
    assert status == 0, (stdout[-2000:], stderr[-2000:])
    assert "ended by the operator (e)" in stdout, stdout[-2000:]
    for name in ("rig_log.csv", "run.mat", "metrics.json", "timing.json"):
        assert (env.work / out / name).is_file(), name
    assert env.compiler_calls() == []


def test_fit_on_the_calibrate_log_without_a_compiler(wheel_env):
    """The ramp test on the virtual rig, then ``fit`` on its log with no compiler on the PATH at all (the fake ones
    would be called, fail, and give the same fallback): CasADi's virtual machine instead of C, said to the user.
    Here the fit is of the force gain alone, on the log's first slow ramp (up to the second centring, 3.8 s), which
    the virtual machine does in about 15 s (the whole 14 s log takes 85 s); the whole fit, with and without a
    compiler, is timed in bench/wheel.py."""
    env: Env = wheel_env["env"]
    calibrate = env.run("pendulab calibrate --virtual --iterations 1 --out cal.json --log ramp.csv")
    assert calibrate.returncode == 0, calibrate.stderr[-2000:]
    lines = (env.work / "ramp.csv").read_text().splitlines()
    second_centring = [float(re.search(r"t=([0-9.]+)", line).group(1)) for line in lines if line.startswith("# event") and line.endswith(": centring")][1]
    first_ramp = [line for line in lines if not line[:1].isdigit() or float(line.split(",")[0]) < second_centring]  # comments, header
    (env.work / "first-ramp.csv").write_text("\n".join(first_ramp) + "\n")
    start = time.perf_counter()
    fit = env.run("pendulab fit first-ramp.csv --pendulum none --fit force_gain --out fitted.json", timeout=600, fakes=False)
    seconds = time.perf_counter() - start
    assert fit.returncode == 0, (fit.stdout[-3000:], fit.stderr[-2000:])
    assert "no C compiler: CasADi's virtual machine" in fit.stdout + fit.stderr
    fitted = json.loads((env.work / "fitted.json").read_text())["force_gain"]
    assert abs(fitted - 1.0) < 0.02, fitted  # the virtual rig's force gain is the model's, 1 (measured: 1.0067)
    print(f"\nfit (force gain = {fitted:.4f}) of the first ramp of a 1-iteration ramp log without a compiler: {seconds:.1f} s")


#: The Python versions a lab PC may have.
WINDOWS_PYTHONS = ("3.10", "3.11", "3.12", "3.13")
#: pendulab's direct dependencies, as the registry names them.
DIRECT = {"numpy", "scipy", "casadi", "control", "fmpy", "matplotlib", "pyserial", "pythonfmu", "h5py", "plotly"}


def _windows_requirements() -> list[str]:
    """The win_amd64 wheel where CI built it (its tag and its metadata are then what is resolved), else the
    dependencies as pyproject.toml lists them."""
    shared = sorted(Path(os.environ.get("PENDULAB_WHEEL_DIR", "/nonexistent")).glob("pendulab-*-win_amd64.whl"))
    if shared:
        return [str(shared[-1])]
    try:
        import tomllib
    except ImportError:  # Python 3.10
        import tomli as tomllib

    return tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["dependencies"]


def test_every_dependency_has_a_windows_wheel_for_python_3_10_to_3_13(tmp_path):
    """pip resolves pendulab for win_amd64, wheels only (``--only-binary=:all: --platform win_amd64``), for each
    Python a lab PC may have: ``pip install --dry-run --report`` is ``pip download``'s resolution without
    fetching some 150 MB of wheels per version (the registry serves their metadata alone)."""
    requirements = _windows_requirements()
    runs = {}
    for python in WINDOWS_PYTHONS:  # the four resolutions side by side
        command = [sys.executable, "-m", "pip", "install", "--dry-run", "--ignore-installed", "--only-binary=:all:",
                   "--platform", "win_amd64", "--python-version", python, "--target", str(tmp_path / python),
                   "--report", str(tmp_path / f"{python}.json"), "-q", *requirements]
        runs[python] = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    for python, proc in runs.items():
        _, stderr = proc.communicate(timeout=600)
        assert proc.returncode == 0, (python, stderr[-3000:])
        report = json.loads((tmp_path / f"{python}.json").read_text())
        files = {i["metadata"]["name"].lower(): i["download_info"]["url"].rsplit("/", 1)[-1] for i in report["install"]}
        assert DIRECT <= set(files), (python, sorted(files))
        for name, file in files.items():
            assert file.endswith(".whl"), (python, name, file)
            platform_tag = file[:-4].split("-")[-1]
            assert platform_tag in ("any", "win_amd64"), (python, name, file)
        print(f"\nPython {python} on win_amd64: {len(files)} wheels, e.g. {files['casadi']}, {files['numpy']}")
