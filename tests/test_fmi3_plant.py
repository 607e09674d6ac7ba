"""Plant3.fmu, the plant as an FMI 3.0 FMU (issue 11, part 3 and must-show 2).

The same C model (state_space.c) and CasADi code as Plant.fmu behind fmi3_wrapper.c: validation is clean, its trajectories
in fmpy equal the FMI 2.0 plant's (Co-Simulation and Model Exchange with CVode, smooth and with events),
1000 instantiate/free cycles do not grow the process, and its modelDescription.xml is the FMI 2.0 variable
table's. The SSP export can name it instead of the FMI 2.0 plant.
"""

from __future__ import annotations

import collections
import json
import math
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi3 import FMU3Model, FMU3Slave

from pendulab.model.plant import EVENT_INDICATORS, OUTPUTS, STATES

BIN = Path(sys.executable).parent
RECORDED = [*STATES, *OUTPUTS]
#: Friction off, no poke, no end stop within reach: a smooth right-hand side.
SMOOTH = {"F1": 0.0, "F2": 0.0, "poke_magnitude": 0.0, "track_half_length": 1e4, "alpha": math.pi + 0.3, "V": 2.0}
#: Friction on (stick, slip, sliding), the encoders' quantization and a poke whose edges fall inside a step.
EVENTS = {"alpha": math.pi - 0.3, "poke_start": 1.00037, "poke_magnitude": 220.0}


def run(fmu: Path, kind: str, start: dict, stop: float = 2.0) -> tuple[np.ndarray, collections.Counter]:
    """fmpy's run (CVode for Model Exchange), every recorded variable and the FMI calls made."""
    calls: collections.Counter = collections.Counter()
    result = simulate_fmu(
        str(fmu), fmi_type=kind, solver="CVode", relative_tolerance=1e-8, stop_time=stop, start_values=dict(start),
        output=RECORDED, output_interval=1e-3, fmi_call_logger=lambda message: calls.update([message.split("(")[0]]),
    )
    return result, calls


def max_difference(a: np.ndarray, b: np.ndarray) -> float:
    assert len(a) == len(b), f"{len(a)} rows against {len(b)}: not the same event sequence"
    return max(float(np.max(np.abs(a[name] - b[name]))) for name in ("time", *RECORDED))


# ---------------------------------------------------------------- the FMU
def test_model_exchange_and_co_simulation_with_both_platforms(plant3_fmu):
    md = read_model_description(str(plant3_fmu))
    assert md.fmiVersion == "3.0"
    assert md.modelExchange.modelIdentifier == md.coSimulation.modelIdentifier == "Plant3"
    assert md.numberOfContinuousStates == len(STATES)
    assert md.numberOfEventIndicators == len(EVENT_INDICATORS)
    names = set(zipfile.ZipFile(plant3_fmu).namelist())
    assert {"binaries/x86_64-linux/Plant3.so", "sources/buildDescription.xml", "sources/fmi3_wrapper.c", "sources/state_space.c"} <= names


def test_variables_are_the_fmi2_plants(plant_fmu, plant3_fmu):
    """One variable table: names, causality, variability, units, start values and the derivative of each
    state as in Plant.fmu; FMI 3.0 adds the independent variable time and one variable per event indicator."""
    two = {v.name: v for v in read_model_description(str(plant_fmu)).modelVariables}
    three = {v.name: v for v in read_model_description(str(plant3_fmu)).modelVariables}
    added = {"time", *(f"event_indicator.{n}" for n in EVENT_INDICATORS)}
    assert set(three) == set(two) | added
    for name, v2 in two.items():
        v3 = three[name]
        assert (v3.type, v3.causality, v3.variability, v3.unit) == ({"Real": "Float64"}[v2.type], v2.causality, v2.variability, v2.unit), name
        assert (v3.start is None) == (v2.start is None) and (v2.start is None or float(v3.start) == float(v2.start)), name
        assert (v3.derivative.name if v3.derivative else None) == (v2.derivative.name if v2.derivative else None), name
    assert three["time"].causality == "independent"
    assert len({v.valueReference for v in three.values()}) == len(three), "FMI 3.0 value references are unique"


def test_event_indicator_variables_are_the_event_indicators(plant3_fmu, tmp_path):
    """fmi3GetFloat64 on the declared event indicator variables gives what fmi3GetEventIndicators gives."""
    md = read_model_description(str(plant3_fmu))
    refs = {v.name: v.valueReference for v in md.modelVariables}
    model = FMU3Model(guid=md.guid, unzipDirectory=extract(str(plant3_fmu), str(tmp_path / "u")), modelIdentifier="Plant3", instanceName="m")
    model.instantiate()
    model.enterInitializationMode(startTime=0.0)
    model.setFloat64([refs["alpha"], refs["xdot"], refs["V"]], [math.pi, 0.3, 4.0])
    model.exitInitializationMode()
    model.updateDiscreteStates()
    model.enterContinuousTimeMode()
    import ctypes

    z = (ctypes.c_double * len(EVENT_INDICATORS))()
    model.getEventIndicators(z, len(EVENT_INDICATORS))
    declared = [u.variable.name for u in md.eventIndicators]
    assert declared == [f"event_indicator.{n}" for n in EVENT_INDICATORS]
    assert model.getFloat64([refs[n] for n in declared]) == list(z)
    assert len(set(np.sign(z))) > 1, "indicators of both signs: a state that is not trivial"
    assert model.getFloat64([refs["time"]]) == [0.0]
    model.terminate()
    model.freeInstance()


def test_wrong_instantiation_token_and_event_mode_are_refused(plant3_fmu, tmp_path):
    md = read_model_description(str(plant3_fmu))
    unzipdir = extract(str(plant3_fmu), str(tmp_path / "u"))
    with pytest.raises(Exception, match="instantiate"):
        FMU3Slave(guid="{00000000-0000-0000-0000-000000000000}", unzipDirectory=unzipdir, modelIdentifier="Plant3").instantiate()
    with pytest.raises(Exception, match="instantiate"):  # hasEventMode is false
        FMU3Slave(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier="Plant3").instantiate(eventModeUsed=True)


def test_calls_out_of_order_are_errors(plant3_fmu, tmp_path):
    from fmpy.fmi1 import FMICallException

    md = read_model_description(str(plant3_fmu))
    s = FMU3Slave(guid=md.guid, unzipDirectory=extract(str(plant3_fmu), str(tmp_path / "u")), modelIdentifier="Plant3")
    s.instantiate()
    with pytest.raises(FMICallException):
        s.doStep(0.0, 1e-3)  # before initialization
    s.enterInitializationMode(startTime=0.0)
    s.exitInitializationMode()
    with pytest.raises(FMICallException):
        s.setFloat64([[v.valueReference for v in md.modelVariables if v.name == "Mp"][0]], [0.5])  # fixed parameter
    s.doStep(0.0, 1e-3)
    s.terminate()
    s.freeInstance()


# ---------------------------------------------------------------- the same trajectories as FMI 2.0
@pytest.mark.parametrize("kind", ["CoSimulation", "ModelExchange"])
@pytest.mark.parametrize("case", ["smooth", "events"])
def test_trajectory_equals_the_fmi2_plant(plant_fmu, plant3_fmu, kind, case):
    """Every state and output at every recorded point (and every event row in Model Exchange) to 1e-12."""
    start = SMOOTH if case == "smooth" else EVENTS
    two, calls2 = run(plant_fmu, kind, start)
    three, calls3 = run(plant3_fmu, kind, start)
    difference = max_difference(two, three)
    print(f"\n{kind} {case}: {len(three)} rows, {calls3['fmi3EnterEventMode']} events, max |FMI 3.0 - FMI 2.0| = {difference:.3g}")
    assert difference <= 1e-12
    assert np.ptp(three["alpha"]) > 0.5, "the pendulum swings"
    if kind == "ModelExchange":
        assert calls3["fmi3EnterEventMode"] == calls2["fmi2EnterEventMode"]
        if case == "events":
            assert calls3["fmi3EnterEventMode"] > 2, "friction switches are events beside the poke's two edges"
            assert np.any(np.isclose(three["time"], 1.00037, rtol=0, atol=1e-12)), "the poke's start is a time event"
        else:
            assert calls3["fmi3EnterEventMode"] == 0


# ---------------------------------------------------------------- memory
CYCLES = r"""
import ctypes, json, math, sys

class MallInfo2(ctypes.Structure):
    _fields_ = [(n, ctypes.c_size_t) for n in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks",
                                                "uordblks", "fordblks", "keepcost")]

libc = ctypes.CDLL(None)
libc.mallinfo2.restype = MallInfo2
page = __import__("os").sysconf("SC_PAGE_SIZE")

def rss():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * page

lib = ctypes.CDLL(sys.argv[1])
token, alpha_vr, free_instances = sys.argv[2].encode(), int(sys.argv[3]), sys.argv[4] == "free"
P, D, B, S = ctypes.c_void_p, ctypes.c_double, ctypes.c_bool, ctypes.c_size_t
lib.fmi3InstantiateCoSimulation.restype = P
lib.fmi3InstantiateCoSimulation.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_char_p, B, B, B, B, P, S, P, P, P]
lib.fmi3InstantiateModelExchange.restype = P
lib.fmi3InstantiateModelExchange.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_char_p, B, B, P, P]
lib.fmi3EnterInitializationMode.argtypes = [P, B, D, D, B, D]
for name in ("fmi3ExitInitializationMode", "fmi3Terminate", "fmi3EnterContinuousTimeMode", "fmi3FreeInstance"):
    getattr(lib, name).argtypes = [P]
lib.fmi3SetFloat64.argtypes = lib.fmi3GetFloat64.argtypes = [P, ctypes.POINTER(ctypes.c_uint32), S, ctypes.POINTER(D), S]
lib.fmi3DoStep.argtypes = [P, D, D, B, P, P, P, P]
lib.fmi3UpdateDiscreteStates.argtypes = [P, P, P, P, P, P, P]
lib.fmi3GetContinuousStateDerivatives.argtypes = lib.fmi3GetEventIndicators.argtypes = [P, ctypes.POINTER(D), S]
vr, value, dx, z = ctypes.c_uint32(alpha_vr), D(), (D * 4)(), (D * 10)()
flags = [ctypes.byref(B()) for _ in range(4)] + [ctypes.byref(D())]

def cycle():
    cs = lib.fmi3InstantiateCoSimulation(b"cs", token, b"", False, False, False, False, None, 0, None, None, None)
    me = lib.fmi3InstantiateModelExchange(b"me", token, b"", False, False, None, None)
    assert cs and me
    for c in (cs, me):
        value.value = math.pi + 0.2
        assert lib.fmi3EnterInitializationMode(c, False, 0.0, 0.0, False, 0.0) == 0
        assert lib.fmi3SetFloat64(c, ctypes.byref(vr), 1, ctypes.byref(value), 1) == 0
        assert lib.fmi3ExitInitializationMode(c) == 0
    for k in range(100):
        assert lib.fmi3DoStep(cs, k * 1e-3, 1e-3, True, *flags[:3], flags[4]) == 0
    assert lib.fmi3UpdateDiscreteStates(me, *flags[:4], flags[0], flags[4]) == 0
    assert lib.fmi3EnterContinuousTimeMode(me) == 0
    assert lib.fmi3GetContinuousStateDerivatives(me, dx, 4) == 0 and lib.fmi3GetEventIndicators(me, z, 10) == 0
    lib.fmi3GetFloat64(cs, ctypes.byref(vr), 1, ctypes.byref(value), 1)
    result = (value.value, dx[3], z[0])
    for c in (cs, me):
        assert lib.fmi3Terminate(c) == 0
        if free_instances:
            lib.fmi3FreeInstance(c)
    return result

first = cycle()
for _ in range(50):
    cycle()
rss0, heap0 = rss(), libc.mallinfo2().uordblks
same = sum(cycle() == first for _ in range(1000))
print(json.dumps({"same": same, "rss_growth": rss() - rss0, "heap_growth": libc.mallinfo2().uordblks - heap0}))
"""


def cycles(plant3_fmu: Path, tmp_path: Path, mode: str) -> dict:
    md = read_model_description(str(plant3_fmu))
    unzipdir = Path(extract(str(plant3_fmu), str(tmp_path / mode)))
    alpha = [v.valueReference for v in md.modelVariables if v.name == "alpha"][0]
    result = subprocess.run([sys.executable, "-c", CYCLES, str(unzipdir / "binaries/x86_64-linux/Plant3.so"), md.guid, str(alpha), mode],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/self/statm and glibc's mallinfo2")
def test_thousand_instantiate_free_cycles_do_not_grow(plant3_fmu, tmp_path):
    """1000 x (a Co-Simulation instance: initialize, 100 steps; a Model Exchange instance: initialize, event
    update, derivatives, event indicators; terminate and free both), in a fresh process: same results every
    time, resident memory and malloc'd memory flat. The same cycles without fmi3FreeInstance show the
    measurement sees a leak."""
    freed = cycles(plant3_fmu, tmp_path, "free")
    print(f"\n1000 cycles: RSS {freed['rss_growth'] / 1024:+.0f} kB, heap {freed['heap_growth'] / 1024:+.1f} kB")
    assert freed["same"] == 1000
    assert freed["rss_growth"] < 256 * 1024, freed
    assert freed["heap_growth"] < 16 * 1024, freed
    leaked = cycles(plant3_fmu, tmp_path, "leak")
    print(f"without fmi3FreeInstance: RSS {leaked['rss_growth'] / 1024:+.0f} kB, heap {leaked['heap_growth'] / 1024:+.0f} kB")
    assert leaked["heap_growth"] > 1024 * 1024


# ---------------------------------------------------------------- sources
@pytest.mark.skipif(shutil.which("cmake") is None, reason="cmake is needed by fmpy's build")
def test_fmpy_compile_rebuilds_the_binary_from_sources(plant3_fmu, tmp_path):
    """``fmpy compile`` from sources/ (buildDescription.xml) alone gives a binary with the same trajectory."""
    stripped = tmp_path / "Plant3.fmu"
    with zipfile.ZipFile(plant3_fmu) as src, zipfile.ZipFile(stripped, "w", zipfile.ZIP_DEFLATED) as dst:
        for item in src.infolist():
            if not item.filename.startswith("binaries/"):
                dst.writestr(item, src.read(item))
    result = subprocess.run([str(BIN / "fmpy"), "compile", str(stripped)], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    assert "binaries/x86_64-linux/Plant3.so" in zipfile.ZipFile(stripped).namelist()
    rebuilt, _ = run(stripped, "CoSimulation", EVENTS, stop=1.2)
    shipped, _ = run(plant3_fmu, "CoSimulation", EVENTS, stop=1.2)
    # Another compiler configuration (CMake Release) may round differently in the last bits, no more.
    assert max_difference(rebuilt, shipped) < 1e-12


# ---------------------------------------------------------------- the SSP export names either plant
def test_ssp_export_names_the_fmi3_plant(plant_fmu, plant3_fmu, controller_fmu, supervisor_fmu, tmp_path):
    """``pendulum_system(..., plant="Plant3")``: the SSP carries Plant3.fmu with the same connectors (SSP types)
    and parameters as the loop with Plant.fmu, and fmpy reads it with the schema check."""
    from fmpy.ssp.ssd import read_ssd

    from pendulab.control.controller import demo_controller
    from pendulab.control.realization import discretize
    from pendulab.cosim.pendulum import pendulum_system
    from pendulab.cosim.ssp import export_ssp
    from pendulab.errors import UserError
    from pendulab.model.parameters import PlantParameters

    params, lti = PlantParameters.preset(), discretize(demo_controller(), h=1e-3).to_parameters()
    ssd = {}
    for plant in ("Plant", "Plant3"):
        path = export_ssp(pendulum_system(params, lti, plant=plant), tmp_path / f"{plant}.ssp")
        read_ssd(str(path), validate=True)
        with zipfile.ZipFile(path) as zf:
            assert f"resources/{plant}.fmu" in zf.namelist()
            ssd[plant] = zf.read("SystemStructure.ssd").decode()
    assert 'source="resources/Plant3.fmu"' in ssd["Plant3"]
    assert ssd["Plant3"].replace("Plant3.fmu", "Plant.fmu") == ssd["Plant"]
    ns = {"ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription"}
    plant = ET.fromstring(ssd["Plant3"]).find(".//ssd:Component[@name='plant']", ns)
    assert {c.get("name") for c in plant.iter(f"{{{ns['ssd']}}}Connector")} == {*STATES, *OUTPUTS, "V"}
    with pytest.raises(UserError, match="Plant3"):
        pendulum_system(params, lti, plant="Plant4")


def test_master_refuses_the_fmi3_plant_with_a_clear_message(plant3_fmu):
    from pendulab.cosim.master import Master
    from pendulab.cosim.system import System
    from pendulab.errors import UserError

    system = System()
    system.add("plant", plant3_fmu)
    with pytest.raises(UserError, match="FMI 3.0 FMU; the master runs FMI 2.0"):
        Master(system)


def test_simulate_writes_the_ssp_with_the_plant_it_is_asked_for(plant_fmu, plant3_fmu, loop_fmus, tmp_path):
    """``pendulab simulate --ssp`` exports the loop with Plant.fmu, ``--ssp Plant3`` with Plant3.fmu; the
    simulation itself runs the FMI 2.0 plant either way."""
    from pendulab.cli.main import main

    for option, plant in ((["--ssp"], "Plant"), (["--ssp", "Plant3"], "Plant3")):
        out = tmp_path / plant
        assert main(["simulate", "--demo", "--stop-time", "0.5", "--poke", "50,0.005,0.2", *option, "--out", str(out)]) == 0
        names = zipfile.ZipFile(out / "loop.ssp").namelist()
        assert f"resources/{plant}.fmu" in names and {"resources/Controller.fmu", "resources/Supervisor.fmu"} <= set(names)
        assert len([n for n in names if n.startswith("resources/Plant")]) == 1


def test_ecos_runs_the_fmi3_plant_as_the_fmi2_one(plant_fmu, plant3_fmu):
    """A second FMI 3.0 importer: Ecos (ecospy, which loads FMI 3.0 through fmi4c) steps Plant3.fmu to the
    same states and outputs as Plant.fmu, friction on, a saturating voltage and the poke, 1.5 s."""
    ecospy = pytest.importorskip("ecospy")
    runs = {}
    for fmu in (plant_fmu, plant3_fmu):
        with ecospy.EcosSimulationStructure() as structure:
            structure.add_model("plant", str(fmu))
            structure.add_parameter_set("initial", {"plant::alpha": math.pi + 0.2, "plant::poke_start": 0.7})
            with ecospy.EcosSimulation(structure=structure, step_size=1e-3) as sim:
                assert sim.init(parameter_set="initial")
                rows = []
                for k in range(1500):
                    sim.set_real("plant::V", 14.0 * math.sin(2 * math.pi * (0.5 + 1.5 * k * 1e-3) * k * 1e-3))
                    sim.step()
                    rows.append([sim.get_real(f"plant::{name}") for name in RECORDED])
                sim.terminate()
        runs[fmu.stem] = np.array(rows)
    assert np.ptp(runs["Plant3"][:, STATES.index("alpha")]) > 0.3, "a real swing"
    difference = float(np.max(np.abs(runs["Plant3"] - runs["Plant"])))
    print(f"\nEcos: max |Plant3 - Plant| = {difference:.3g}")
    assert difference <= 1e-12


def test_ecos_runs_the_ssp_loop_with_either_plant(loop_fmus, plant3_fmu, tmp_path):
    """The SSP exported with Plant3 runs in Ecos (closed loop of the three FMUs, a poke) exactly as the one
    with Plant."""
    ecospy = pytest.importorskip("ecospy")
    from pendulab.control.controller import demo_controller
    from pendulab.control.realization import discretize
    from pendulab.cosim.pendulum import pendulum_system
    from pendulab.cosim.ssp import PARAMETER_SET, export_ssp
    from pendulab.model.parameters import PlantParameters

    params = PlantParameters.preset().with_values(poke_start=0.2, poke_duration=0.005, poke_magnitude=220.0)
    lti = discretize(demo_controller(), h=1e-3).to_parameters()
    names = ("plant::alpha", "plant::x", "controller::V_command", "supervisor::V")
    runs = {}
    for plant in ("Plant", "Plant3"):
        ssp = export_ssp(pendulum_system(params, lti, plant=plant), tmp_path / f"{plant}.ssp", stop_time=1.0)
        with ecospy.EcosSimulation(ssp_path=str(ssp), step_size=1e-3) as sim:
            assert sim.init(parameter_set=PARAMETER_SET)
            rows = []
            for _ in range(800):
                sim.step()
                rows.append([sim.get_real(n) for n in names])
            sim.terminate()
        runs[plant] = np.array(rows)
    assert np.ptp(runs["Plant3"][:, 0]) > 0.05, "the poke moved the pendulum"
    assert float(np.max(np.abs(runs["Plant3"] - runs["Plant"]))) <= 1e-12
