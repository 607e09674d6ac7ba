"""Plant.fmu as a file: FMI validation, native binaries without Python, sources that rebuild it,
documented parameters, and the build commands (issue 2, must-show 2; SPEC §6)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pytest
from fmi_harness import hanging_plant_run
from fmpy import extract, read_model_description, supported_platforms
from fmpy.validation import validate_fmu

from pendulab.fmu.build import FMI_HEADERS, WIN64_COMPILER, is_current
from pendulab.model.parameters import PlantParameters
from pendulab.model.plant import STATES

BIN = Path(sys.executable).parent
OUTPUTS = ("x", "xdot", "alpha", "alphadot", "alpha_measured", "x_measured", "V_applied", "F_friction")


def test_model_exchange_and_co_simulation_in_one_fmu(plant_fmu: Path) -> None:
    md = read_model_description(str(plant_fmu))
    assert md.fmiVersion == "2.0"
    assert md.modelExchange.modelIdentifier == md.coSimulation.modelIdentifier == "Plant"
    assert md.coSimulation.canHandleVariableCommunicationStepSize
    assert "linux64" in supported_platforms(str(plant_fmu))


def test_is_current_stamp(plant_fmu: Path) -> None:
    """The fixture's FMU was built from the sources in this checkout."""
    assert is_current(plant_fmu)


# ---------------------------------------------------------------- variables
def test_variables_of_the_issue(plant_fmu: Path) -> None:
    md = read_model_description(str(plant_fmu))
    variables = {v.name: v for v in md.modelVariables}
    assert variables["V"].causality == "input" and variables["V"].unit == "V"
    for name in OUTPUTS:
        assert variables[name].causality == "output", name
        assert variables[name].unit, f"{name} has no unit"
        assert variables[name].description, f"{name} has no description"
    for name in STATES:
        assert variables[name].initial == "exact" and float(variables[name].start) == 0.0, f"state {name} takes a start value"
    derivatives = {v.derivative.name for v in md.modelVariables if v.derivative is not None}
    assert derivatives == set(STATES)
    assert [u.variable.name for u in md.outputs] == list(OUTPUTS)


def test_every_parameter_has_unit_description_and_default(plant_fmu: Path) -> None:
    md = read_model_description(str(plant_fmu))
    parameters = [v for v in md.modelVariables if v.causality == "parameter"]
    assert [v.name for v in parameters] == list(PlantParameters.names())
    defaults = PlantParameters()
    units = {u.name for u in md.unitDefinitions}
    for v in parameters:
        assert v.type == "Real" and v.variability in ("fixed", "tunable")
        assert v.unit and v.unit in units, f"parameter {v.name} has no declared unit"
        assert v.description and len(v.description) > 5, f"parameter {v.name} has no description"
        assert float(v.start) == getattr(defaults, v.name), f"start value of {v.name}"
    # The issue's list of names.
    issue_names = (
        "Mp Lp lp Ip Bp M_cart Beq Rm Kt Km Kg eta_g eta_m Jm r_mp g V_max I_max F1 v1 F2 v2 B "
        "q_alpha q_x poke_magnitude poke_duration poke_start"
    ).split()
    assert set(issue_names) <= {v.name for v in parameters}


# ---------------------------------------------------------------- native binaries, no Python
def _needed(shared_object: Path) -> list[str]:
    out = subprocess.run(["readelf", "-d", str(shared_object)], capture_output=True, text=True, check=True).stdout
    return [line.split("[")[1].rstrip("]") for line in out.splitlines() if "(NEEDED)" in line]


@pytest.mark.skipif(shutil.which("readelf") is None, reason="readelf (binutils) is not installed")
def test_linux64_binary_needs_no_python(plant_unzipdir: Path) -> None:
    so = plant_unzipdir / "binaries" / "linux64" / "Plant.so"
    needed = _needed(so)
    assert not [lib for lib in needed if "python" in lib.lower()], needed
    assert set(needed) <= {"libc.so.6", "libm.so.6"}, f"unexpected run-time dependencies {needed}"
    undefined = subprocess.run(["nm", "-D", "--undefined-only", str(so)], capture_output=True, text=True, check=True).stdout
    assert not [s for s in undefined.split() if s.startswith(("Py", "_Py"))]
    exported = subprocess.run(["nm", "-D", "--defined-only", str(so)], capture_output=True, text=True, check=True).stdout
    symbols = {line.split()[-1] for line in exported.splitlines()}
    assert {"fmi2Instantiate", "fmi2DoStep", "fmi2GetDerivatives", "fmi2SetTime"} <= symbols
    assert {s for s in symbols if not s.startswith("fmi2")} <= {"_init", "_fini"}, "only the FMI API is exported"


@pytest.mark.skipif(shutil.which(WIN64_COMPILER) is None, reason="mingw-w64 cross compiler not installed")
def test_win64_binary_imports_only_the_c_runtime(plant_unzipdir: Path) -> None:
    dll = plant_unzipdir / "binaries" / "win64" / "Plant.dll"
    assert dll.is_file(), "with mingw-w64 present the FMU carries a win64 binary"
    dump = subprocess.run(["x86_64-w64-mingw32-objdump", "-p", str(dll)], capture_output=True, text=True, check=True).stdout
    imports = {line.split(":")[1].strip().lower() for line in dump.splitlines() if "DLL Name:" in line}
    assert imports <= {"kernel32.dll", "msvcrt.dll"}, imports
    assert "fmi2DoStep" in dump and "fmi2Instantiate" in dump


HOST_C = textwrap.dedent(
    r"""
    /* A minimal FMI 2.0 co-simulation host in plain C: proves the binary runs without Python. */
    #include <dlfcn.h>
    #include <stdio.h>
    #include <stdlib.h>
    #include "fmi2Functions.h"

    static void logger(fmi2ComponentEnvironment e, fmi2String name, fmi2Status s, fmi2String c, fmi2String m, ...) {
        (void)e; (void)s; (void)c; fprintf(stderr, "%s: %s\n", name, m);
    }

    int main(int argc, char **argv) {
        void *lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
        fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
        fmi2ValueReference vr[5];
        fmi2Real v[5], start, value;
        int k, n = atoi(argv[3]);
        if (!lib) { fprintf(stderr, "dlopen: %s\n", dlerror()); return 3; }
        for (k = 0; k < 5; k++) vr[k] = (fmi2ValueReference)atoi(argv[4 + k]);  /* V x xdot alpha alphadot */
        fmi2InstantiateTYPE *instantiate = (fmi2InstantiateTYPE *)dlsym(lib, "fmi2Instantiate");
        fmi2SetupExperimentTYPE *setup = (fmi2SetupExperimentTYPE *)dlsym(lib, "fmi2SetupExperiment");
        fmi2EnterInitializationModeTYPE *enter = (fmi2EnterInitializationModeTYPE *)dlsym(lib, "fmi2EnterInitializationMode");
        fmi2ExitInitializationModeTYPE *leave = (fmi2ExitInitializationModeTYPE *)dlsym(lib, "fmi2ExitInitializationMode");
        fmi2SetRealTYPE *set_real = (fmi2SetRealTYPE *)dlsym(lib, "fmi2SetReal");
        fmi2GetRealTYPE *get_real = (fmi2GetRealTYPE *)dlsym(lib, "fmi2GetReal");
        fmi2DoStepTYPE *do_step = (fmi2DoStepTYPE *)dlsym(lib, "fmi2DoStep");
        fmi2FreeInstanceTYPE *free_instance = (fmi2FreeInstanceTYPE *)dlsym(lib, "fmi2FreeInstance");
        fmi2Component c = instantiate("plant", fmi2CoSimulation, argv[2], "", &cb, fmi2False, fmi2False);
        if (!c) return 4;
        setup(c, fmi2False, 0, 0, fmi2False, 0);
        enter(c);
        start = 3.14159265358979323846 + 0.3;
        set_real(c, &vr[3], 1, &start);
        if (leave(c) != fmi2OK) return 5;
        for (k = 0; k < n; k++) {
            value = 12.0 * sin(2 * 3.14159265358979323846 * k * 1e-3);
            set_real(c, &vr[0], 1, &value);
            if (do_step(c, k * 1e-3, 1e-3, fmi2True) != fmi2OK) return 6;
        }
        get_real(c, &vr[1], 4, v);
        printf("%.17g %.17g %.17g %.17g\n", v[0], v[1], v[2], v[3]);
        free_instance(c);
        dlclose(lib);
        return 0;
    }
    """
).replace("#include <stdlib.h>", "#include <stdlib.h>\n#include <math.h>")


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler")
def test_binary_runs_in_a_plain_c_host(plant_unzipdir: Path, tmp_path: Path) -> None:
    """A host program without Python loads Plant.so (all symbols bound at load) and gets fmpy's trajectory."""
    host = tmp_path / "host"
    (tmp_path / "host.c").write_text(HOST_C)
    subprocess.run(
        ["cc", "-std=c99", "-O1", f"-I{FMI_HEADERS}", str(tmp_path / "host.c"), "-o", str(host), "-ldl", "-lm"],
        check=True, capture_output=True,
    )
    md = read_model_description(str(plant_unzipdir))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    so = plant_unzipdir / "binaries" / "linux64" / "Plant.so"
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "LD_PRELOAD"))}
    n = 1500
    result = subprocess.run(
        [str(host), str(so), md.guid, str(n), *(str(vr[k]) for k in ("V", *STATES))],
        capture_output=True, text=True, timeout=60, env=env,
    )
    assert result.returncode == 0, result.stderr
    c_states = np.array([float(v) for v in result.stdout.split()])
    np.testing.assert_array_equal(c_states, hanging_plant_run(plant_unzipdir, n)[-1])


# ---------------------------------------------------------------- sources/ rebuild the binary
def test_sources_listed_in_the_model_description_are_shipped(plant_fmu: Path) -> None:
    md = read_model_description(str(plant_fmu))
    with zipfile.ZipFile(plant_fmu) as zf:
        names = set(zf.namelist())
        root = ElementTree.fromstring(zf.read("modelDescription.xml"))
    for interface in ("ModelExchange", "CoSimulation"):
        listed = [f.get("name") for f in root.findall(f"{interface}/SourceFiles/File")]
        assert "fmi2_wrapper.c" in listed, f"{interface} lists its SourceFiles"
        assert all(f"sources/{f}" in names for f in listed)
    build = md.buildConfigurations[0]
    assert build.modelIdentifier == "Plant"
    assert all(f"sources/{f}" in names for f in build.sourceFileSets[0].sourceFiles)
    # Every header the sources include is in sources/ or is a standard FMI header.
    assert {"sources/fmu_model.h", "sources/variables.h", "sources/plant_casadi.h"} <= names


@pytest.mark.skipif(shutil.which("cmake") is None, reason="cmake is needed by fmpy's build")
def test_fmpy_compile_rebuilds_the_binary_from_sources(plant_fmu: Path, plant_unzipdir: Path, tmp_path: Path) -> None:
    """``fmpy compile`` on a copy without binaries/ gives a working binary with the same trajectory."""
    stripped = tmp_path / "Plant.fmu"
    with zipfile.ZipFile(plant_fmu) as src, zipfile.ZipFile(stripped, "w", zipfile.ZIP_DEFLATED) as dst:
        for item in src.infolist():
            if not item.filename.startswith("binaries/"):
                dst.writestr(item, src.read(item))
    assert "linux64" not in supported_platforms(str(stripped))
    result = subprocess.run(
        [str(BIN / "fmpy"), "compile", str(stripped)], capture_output=True, text=True, timeout=300, cwd=tmp_path
    )
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    assert "linux64" in supported_platforms(str(stripped))
    assert validate_fmu(str(stripped)) == []
    rebuilt = Path(extract(str(stripped), unzipdir=str(tmp_path / "rebuilt")))
    # Another compiler configuration (CMake Release) may round differently in the last bits, no more.
    np.testing.assert_allclose(hanging_plant_run(rebuilt), hanging_plant_run(plant_unzipdir), rtol=1e-12, atol=1e-12)


# ---------------------------------------------------------------- the build commands
def test_pendulab_build_fmus_into_a_folder(plant_fmu: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    result = subprocess.run(
        [str(BIN / "pendulab"), "build-fmus", "Plant", "--out", str(out)], capture_output=True, text=True, timeout=300
    )
    assert result.returncode == 0, result.stderr
    built = out / "Plant.fmu"
    assert f"built {built}" in result.stdout
    assert sorted(p.name for p in out.iterdir()) == ["Plant.fmu"], "no temporary files left behind"
    assert validate_fmu(str(built)) == []
    # Same sources, same model: same GUID as the fixture's FMU.
    assert read_model_description(str(built)).guid == read_model_description(str(plant_fmu)).guid
    assert is_current(built)


def test_build_fmus_script_rejects_an_unknown_name(tmp_path: Path) -> None:
    script = Path(__file__).resolve().parents[1] / "build_fmus.py"
    result = subprocess.run(
        [sys.executable, str(script), "Pendulum", "--out", str(tmp_path)], capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 2
    assert result.stderr.count("\n") == 1 and "Pendulum" in result.stderr and "Traceback" not in result.stderr
    assert list(tmp_path.iterdir()) == []
