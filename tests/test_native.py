"""The one compile-and-cache helper (pendulab.native) and where FMUs are found (issue 23).

A compiler is hidden by an empty PATH and an unset CC; a fake compiler is a script that records its calls.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from pendulab import native
from pendulab.fmu import build as fmu_build

SOURCE = "int pendulab_answer(void) { return 42; }\n"


@pytest.fixture
def no_compiler(monkeypatch, tmp_path):
    """No C compiler anywhere: CC unset, PATH without one."""
    monkeypatch.delenv("CC", raising=False)
    monkeypatch.setenv("PATH", str(tmp_path / "empty-bin"))
    assert native.find_compiler() is None


@pytest.fixture
def cache(monkeypatch, tmp_path):
    monkeypatch.setenv("PENDULAB_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache"


def fake_compiler(folder: Path, record: Path) -> Path:
    """A ``cc`` that records its arguments and fails, as a compiler that must not be called."""
    folder.mkdir(parents=True, exist_ok=True)
    script = folder / "cc"
    script.write_text(f"#!/bin/sh\necho \"$@\" >> {record}\nexit 1\n")
    script.chmod(0o755)
    return script


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler")
def test_compiles_once_then_loads_from_the_cache(cache):
    import ctypes

    first = native.shared_library(SOURCE, "answer")
    second = native.shared_library(SOURCE, "answer")
    assert first.built and not second.built and first.path == second.path
    assert first.path.parent == cache / "native"
    assert ctypes.CDLL(str(first.path)).pendulab_answer() == 42
    # Other flags or another source: another library, never the old one.
    assert native.shared_library(SOURCE, "answer", flags=("-O1",)).path != first.path
    assert native.shared_library(SOURCE.replace("42", "43"), "answer").path != first.path
    assert not list(cache.rglob("*.part")), "no half-written file is left"


def test_prebuilt_library_is_found_without_a_compiler(no_compiler, cache, monkeypatch, tmp_path):
    prebuilt = tmp_path / "prebuilt"
    prebuilt.mkdir()
    monkeypatch.setattr(native, "PREBUILT_DIR", prebuilt)
    assert native.shared_library(SOURCE, "answer") is None, "nothing prebuilt, no compiler: the caller's fallback"
    (prebuilt / native.library_name(SOURCE.encode(), "answer", ("-O2",))).write_bytes(b"stand-in")
    found = native.shared_library(SOURCE, "answer")
    assert found == (prebuilt / native.library_name(SOURCE.encode(), "answer", ("-O2",)), False)
    assert native.shared_library(SOURCE, "answer", prebuilt=False) is None


def test_a_feature_that_needs_a_compiler_says_which_and_how_in_one_line(no_compiler, cache):
    with pytest.raises(native.CompilerNeeded) as info:
        native.shared_library(SOURCE, "answer", feature="the answer")
    message = str(info.value)
    assert "\n" not in message and message.startswith("the answer needs a C compiler") and "apt-get install gcc" in message
    assert "winget" in native.install_hint("Windows") and "xcode-select" in native.install_hint("Darwin")


def test_cc_is_honoured_and_a_failing_compiler_falls_back(cache, monkeypatch, tmp_path):
    record = tmp_path / "calls.txt"
    monkeypatch.setenv("CC", str(fake_compiler(tmp_path / "bin", record)))
    assert native.shared_library(SOURCE, "answer") is None
    with pytest.raises(native.CompileFailed, match="compiling answer") as info:
        native.shared_library(SOURCE, "answer", feature="the answer")
    assert str(info.value).splitlines()[0].endswith("failed: exit status 1"), "the first line says what went wrong"
    assert len(record.read_text().splitlines()) == 2 and "-shared" in record.read_text()


def test_fit_functions_fall_back_to_casadis_virtual_machine(monkeypatch, cache):
    """Without a compiler the fit's replay and observer run in CasADi's virtual machine, with the compiled ones' bits."""
    import numpy as np

    from pendulab.calibration import _replay  # private: the fit's compile step must fall back, not fail
    from pendulab.model.parameters import PlantParameters

    sets = np.array([PlantParameters.preset("none", Beq=b).as_vector() for b in (4.0, 6.5, 9.0)], dtype=float)
    t, V = np.arange(300) * 1e-3, np.r_[np.full(150, 3.0), np.full(150, -2.0)]
    compiler = native.find_compiler()
    restart = {100: np.array([0.01, 0.0, 0.0, 0.0])}
    monkeypatch.setattr(native, "find_compiler", lambda: None)
    _replay._compiled.cache_clear()
    try:
        assert not _replay.prepare(PlantParameters.preset("none"), [1e-3], ("Beq",))
        in_vm = _replay.replay(sets, V, t, np.zeros(4), restart, free=("Beq",))
        assert not any(cache.rglob("pendulab_replay*"))
        if compiler:
            monkeypatch.setattr(native, "find_compiler", lambda: compiler)
            _replay._compiled.cache_clear()
            assert np.array_equal(in_vm, _replay.replay(sets, V, t, np.zeros(4), restart, free=("Beq",)))
    finally:
        _replay._compiled.cache_clear()  # later tests look for the compiler again
    assert np.ptp(in_vm[:, -1, 0]) > 1e-4  # the sets differ


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler")
def test_fit_functions_compile_through_the_helper(cache):
    """The fit's C goes through pendulab.native: built once into the cache's ``fit`` folder, then loaded from it."""
    import numpy as np

    from pendulab.calibration import _replay  # private: the fit's compile step must go through pendulab.native
    from pendulab.model.parameters import PlantParameters

    key = _replay._split(np.asarray(PlantParameters.preset("none").as_vector(), dtype=float), ("Beq",))
    source = _replay._source(10, *key, ways=1)
    assert _replay._load(source, "pendulab_test_replay", ("-O2", "-DLANES=1")) is not None
    built = list((cache / "fit").glob("pendulab_test_replay-*"))
    assert len(built) == 1
    stamp = built[0].stat().st_mtime_ns
    assert _replay._load(source, "pendulab_test_replay", ("-O2", "-DLANES=1")) is not None
    assert [p.stat().st_mtime_ns for p in (cache / "fit").glob("pendulab_test_replay-*")] == [stamp]  # not built again


@pytest.mark.skipif(shutil.which("cc") is None or sys.platform == "win32", reason="needs a POSIX C compiler")
def test_a_compiler_without_openmp_still_compiles_the_fit(monkeypatch, tmp_path, cache):
    """Apple's clang has no OpenMP: the fit's C is built without it (its groups of sets one after another), not
    left to the virtual machine."""
    import numpy as np

    from pendulab.calibration import _replay  # private: the fit's compile step must go without OpenMP
    from pendulab.model.parameters import PlantParameters

    record = tmp_path / "calls.txt"
    script = tmp_path / "bin" / "cc"
    script.parent.mkdir()
    script.write_text(f'#!/bin/sh\necho "$@" >> {record}\ncase " $* " in *" -fopenmp "*) exit 1;; esac\nexec {shutil.which("cc")} "$@"\n')
    script.chmod(0o755)
    monkeypatch.setenv("CC", str(script))
    key = _replay._split(np.asarray(PlantParameters.preset("none").as_vector(), dtype=float), ("Beq",))
    run = _replay._load(_replay._source(10, *key, ways=1), "pendulab_test_no_openmp", ("-O2", "-DLANES=1"))
    assert run is not None
    calls = record.read_text().splitlines()
    assert len(calls) == 2 and "-fopenmp" in calls[0] and "-fopenmp" not in calls[1]


def _stamped(path: Path, name: str, stale: bool = False) -> Path:
    """A stand-in FMU file marked as pendulab's (current or stale)."""
    path.mkdir(parents=True, exist_ok=True)
    fmu = path / f"{name}.fmu"
    with zipfile.ZipFile(fmu, "w") as zf:
        zf.writestr("modelDescription.xml", "<fmiModelDescription/>")
        zf.comment = (fmu_build._STAMP + ("0" * 16 if stale else fmu_build.source_hash())).encode()
    return fmu


def test_fmus_are_found_in_order_user_folder_then_package(monkeypatch, tmp_path, no_compiler):
    """Installed (no checkout): --fmus DIR, then ./fmus, then the package's prebuilt FMUs; nothing is built."""
    monkeypatch.setattr(fmu_build, "checkout_dir", lambda: None)
    monkeypatch.setattr(fmu_build, "PREBUILT_FMUS", tmp_path / "package")
    monkeypatch.setenv("PENDULAB_CACHE", str(tmp_path / "cache"))
    monkeypatch.delenv("PENDULAB_FMU_DIR", raising=False)
    monkeypatch.chdir(tmp_path)
    packaged = _stamped(tmp_path / "package", "Plant")
    assert fmu_build.ensure_fmu("Plant") == packaged
    own = tmp_path / "fmus" / "Plant.fmu"  # the user's own FMU (not built by pendulab) in ./fmus
    own.parent.mkdir()
    own.write_bytes(b"PK\x05\x06" + bytes(18))
    assert fmu_build.ensure_fmu("Plant") == own
    explicit = _stamped(tmp_path / "mine", "Plant", stale=True)  # stale, but no compiler: used as it is
    monkeypatch.setenv("PENDULAB_FMU_DIR", str(explicit.parent))
    assert fmu_build.ensure_fmu("Plant") == explicit
    # A missing FMU with nothing prebuilt and no compiler: one line saying what to install.
    with pytest.raises(native.CompilerNeeded, match=r"^building Supervisor.fmu from source needs a C compiler"):
        fmu_build.ensure_fmu("Supervisor")


def test_cli_fmus_option(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parents[1] / "src")}
    run = subprocess.run([sys.executable, "-m", "pendulab", "simulate", "--demo", "--fmus", str(tmp_path / "nowhere")],
                         capture_output=True, text=True, env=env, timeout=120)
    assert run.returncode == 2 and run.stderr.count("\n") == 1, run.stderr
    assert "--fmus" in run.stderr and "no such folder" in run.stderr and "Traceback" not in run.stderr
