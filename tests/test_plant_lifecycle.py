"""Plant.fmu's life cycle: 1000 instantiate / simulate / free cycles without a crash or memory growth,
reset, independent instances and the FMI state machine (issue 2, must-show 6)."""

from __future__ import annotations

import ctypes
import ctypes.util
import math
import os
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave, defaultCallbacks, fmi2CoSimulation

STATES = ("x", "xdot", "alpha", "alphadot")
PAGE = os.sysconf("SC_PAGE_SIZE")


def resident_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * PAGE


class _MallInfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in
                ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks", "fordblks", "keepcost")]


def heap_in_use() -> int | None:
    """Bytes malloc has handed out and not got back (glibc >= 2.33), or None elsewhere."""
    libc = ctypes.CDLL(ctypes.util.find_library("c"))
    if not hasattr(libc, "mallinfo2"):
        return None
    libc.mallinfo2.restype = _MallInfo2
    info = libc.mallinfo2()
    return int(info.uordblks + info.hblkhd)


class Plant:
    """One loaded Plant binary with raw ctypes entry points (what a fast master does)."""

    def __init__(self, unzipdir: Path):
        md = read_model_description(str(unzipdir))
        self.guid = md.guid
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.fmu = FMU2Slave(guid=md.guid, modelIdentifier="Plant", unzipDirectory=str(unzipdir), instanceName="plant")
        f = self.fmu._functions
        self.instantiate, self.free = f["fmi2Instantiate"], f["fmi2FreeInstance"]
        self.setup, self.enter, self.leave = f["fmi2SetupExperiment"], f["fmi2EnterInitializationMode"], f["fmi2ExitInitializationMode"]
        self.do_step, self.set_real, self.get_real = f["fmi2DoStep"], f["fmi2SetReal"], f["fmi2GetReal"]
        self.terminate, self.reset = f["fmi2Terminate"], f["fmi2Reset"]
        self.v_ref = (ctypes.c_uint * 1)(self.vr["V"])
        self.alpha_ref = (ctypes.c_uint * 1)(self.vr["alpha"])
        self.state_refs = (ctypes.c_uint * 4)(*(self.vr[s] for s in STATES))
        self.value = (ctypes.c_double * 1)()
        self.states = (ctypes.c_double * 4)()

    def new(self, guid: str | None = None) -> int | None:
        return self.instantiate(b"plant", fmi2CoSimulation, (guid or self.guid).encode(), b"", ctypes.byref(defaultCallbacks), 0, 0)

    def run(self, c: int, n_steps: int, alpha0: float = math.pi + 0.2) -> np.ndarray:
        """Initialize, step ``n_steps`` x 1 ms with a square-wave V, return the final states."""
        assert self.setup(c, 0, 0.0, 0.0, 0, 0.0) == 0
        assert self.enter(c) == 0
        self.value[0] = alpha0
        assert self.set_real(c, self.alpha_ref, 1, self.value) == 0
        assert self.leave(c) == 0
        for k in range(n_steps):
            self.value[0] = 6.0 if (k // 50) % 2 else -6.0
            self.set_real(c, self.v_ref, 1, self.value)
            if self.do_step(c, k * 1e-3, 1e-3, 1) != 0:
                raise RuntimeError(f"fmi2DoStep failed at step {k}")
        assert self.get_real(c, self.state_refs, 4, self.states) == 0
        return np.array(self.states)

    def close(self) -> None:
        self.fmu.freeLibrary()


@pytest.fixture
def plant(plant_unzipdir: Path):
    p = Plant(plant_unzipdir)
    yield p
    p.close()


def test_thousand_instantiate_simulate_free_cycles(plant: Plant) -> None:
    """1000 x (instantiate, 300 steps, terminate, free): same result every time, no memory growth."""
    def cycle() -> np.ndarray:
        c = plant.new()
        assert c, "fmi2Instantiate returned NULL"
        final = plant.run(c, 300)
        assert plant.terminate(c) == 0
        plant.free(c)
        return final

    reference = cycle()
    for _ in range(50):  # warm-up: let malloc and Python settle
        cycle()
    rss_before, heap_before = resident_bytes(), heap_in_use()
    different = sum(not np.array_equal(cycle(), reference) for _ in range(1000))
    assert different == 0, f"{different} of 1000 cycles gave another result"
    rss_growth = resident_bytes() - rss_before
    # One leaked instance is ~2 kB (variables + CasADi work space): 1000 leaks would be ~2 MB.
    assert rss_growth < 512 * 1024, f"resident memory grew by {rss_growth / 1024:.0f} kB over 1000 cycles"
    if heap_before is not None:
        heap_growth = heap_in_use() - heap_before
        assert heap_growth < 64 * 1024, f"malloc'd memory grew by {heap_growth / 1024:.0f} kB over 1000 cycles"


def test_library_load_unload_cycles(plant_unzipdir: Path) -> None:
    """fmpy's own path: FMU2Slave loads the binary, instantiate / step / freeInstance unloads it; 200 times."""
    md = read_model_description(str(plant_unzipdir))
    vr = [md.modelVariables[i].valueReference for i, v in enumerate(md.modelVariables) if v.name == "alpha"]

    def cycle() -> float:
        fmu = FMU2Slave(guid=md.guid, modelIdentifier="Plant", unzipDirectory=str(plant_unzipdir), instanceName="p")
        fmu.instantiate()
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.setReal(vr, [math.pi + 0.1])
        fmu.exitInitializationMode()
        for k in range(100):
            fmu.doStep(k * 1e-3, 1e-3)
        alpha = fmu.getReal(vr)[0]
        fmu.terminate()
        fmu.freeInstance()  # also unloads the shared library
        return alpha

    first = cycle()
    for _ in range(20):
        cycle()
    rss_before = resident_bytes()
    for _ in range(200):
        assert cycle() == first
    assert resident_bytes() - rss_before < 1024 * 1024


def test_instances_are_independent(plant: Plant) -> None:
    """Three instances stepped in lockstep with different inputs equal three solo runs (no shared state)."""
    alphas = (math.pi + 0.1, math.pi - 0.3, 0.05)
    solo = []
    for a in alphas:
        c = plant.new()
        solo.append(plant.run(c, 400, alpha0=a))
        plant.free(c)
    comps = [plant.new() for _ in alphas]
    try:
        for c, a in zip(comps, alphas):
            assert plant.setup(c, 0, 0.0, 0.0, 0, 0.0) == 0 and plant.enter(c) == 0
            plant.value[0] = a
            plant.set_real(c, plant.alpha_ref, 1, plant.value)
            assert plant.leave(c) == 0
        for k in range(400):
            for c in comps:
                plant.value[0] = 6.0 if (k // 50) % 2 else -6.0
                plant.set_real(c, plant.v_ref, 1, plant.value)
                assert plant.do_step(c, k * 1e-3, 1e-3, 1) == 0
        for c, expected in zip(comps, solo):
            plant.get_real(c, plant.state_refs, 4, plant.states)
            np.testing.assert_array_equal(np.array(plant.states), expected)
    finally:
        for c in comps:
            plant.free(c)


def test_reset_gives_the_same_trajectory_again(plant: Plant) -> None:
    c = plant.new()
    try:
        first = plant.run(c, 500)
        assert plant.reset(c) == 0
        # After reset every variable is back at its start value (the alpha set before is gone) ...
        plant.get_real(c, plant.state_refs, 4, plant.states)
        assert list(plant.states) == [0.0, 0.0, 0.0, 0.0]
        # ... and the same experiment gives the same trajectory.
        np.testing.assert_array_equal(plant.run(c, 500), first)
        # Reset from the terminated state too.
        assert plant.terminate(c) == 0 and plant.reset(c) == 0
        np.testing.assert_array_equal(plant.run(c, 500), first)
    finally:
        plant.free(c)


def test_wrong_guid_is_refused(plant: Plant, plant_unzipdir: Path) -> None:
    assert not plant.new(guid="{00000000-0000-0000-0000-000000000000}")
    fmu = FMU2Slave(guid="{not-the-plant}", modelIdentifier="Plant", unzipDirectory=str(plant_unzipdir))
    with pytest.raises(Exception, match="instantiate"):
        fmu.instantiate()
    fmu.freeLibrary()


def test_calls_out_of_order_are_errors(plant: Plant) -> None:
    c = plant.new()
    try:
        assert plant.do_step(c, 0.0, 1e-3, 1) > 1, "fmi2DoStep before initialization"
        assert plant.setup(c, 0, 0.0, 0.0, 0, 0.0) == 0 and plant.enter(c) == 0
        assert plant.do_step(c, 0.0, 1e-3, 1) > 1, "fmi2DoStep in initialization mode"
        assert plant.leave(c) == 0
        assert plant.do_step(c, 0.0, -1e-3, 1) > 1, "negative step size"
        assert plant.do_step(c, 0.0, 0.0, 1) > 1, "zero step size"
        bad = (ctypes.c_uint * 1)(10_000)
        assert plant.get_real(c, bad, 1, plant.value) > 1, "unknown value reference"
        assert plant.set_real(c, bad, 1, plant.value) > 1
        assert plant.do_step(c, 0.0, 1e-3, 1) == 0, "the instance still works after refused calls"
        assert plant.terminate(c) == 0
        assert plant.do_step(c, 1e-3, 1e-3, 1) > 1, "fmi2DoStep after fmi2Terminate"
    finally:
        plant.free(c)


def test_fmpy_wrappers_raise_on_errors(plant_unzipdir: Path) -> None:
    md = read_model_description(str(plant_unzipdir))
    fmu = FMU2Slave(guid=md.guid, modelIdentifier="Plant", unzipDirectory=str(plant_unzipdir))
    fmu.instantiate()
    try:
        with pytest.raises(FMICallException):
            fmu.doStep(0.0, 1e-3)
    finally:
        fmu.freeInstance()
