"""Every capability flag of the three modelDescriptions, checked against what the FMU does (issue 12)."""

from __future__ import annotations

import ctypes
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Model, FMU2Slave

BIN = Path(sys.executable).parent


def slave(fmu: Path, tmp_path: Path, start: dict[str, float] | None = None) -> tuple[FMU2Slave, dict[str, int]]:
    md = read_model_description(str(fmu))
    unzipdir = extract(str(fmu), str(tmp_path / fmu.stem))
    s = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier=md.coSimulation.modelIdentifier, instanceName="i")
    s.instantiate()
    refs = {v.name: v.valueReference for v in md.modelVariables}
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    for name, value in (start or {}).items():
        if md.modelVariables[[v.name for v in md.modelVariables].index(name)].type == "Integer":
            s.setInteger([refs[name]], [int(value)])
        else:
            s.setReal([refs[name]], [value])
    s.exitInitializationMode()
    return s, refs


@pytest.fixture(params=["plant", "controller", "supervisor"])
def any_fmu(request, plant_fmu, controller_fmu, supervisor_fmu) -> Path:
    return {"plant": plant_fmu, "controller": controller_fmu, "supervisor": supervisor_fmu}[request.param]


def test_fmpy_validate_is_clean(any_fmu):
    result = subprocess.run([str(BIN / "fmpy"), "validate", str(any_fmu)], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0 and "No problems found" in result.stdout, result.stdout + result.stderr


def test_variable_step_flag_matches_do_step(any_fmu, tmp_path):
    """canHandleVariableCommunicationStepSize: true means doStep accepts steps other than the default."""
    md = read_model_description(str(any_fmu))
    step = float(md.defaultExperiment.stepSize)
    s, _ = slave(any_fmu, tmp_path)
    s.doStep(0.0, step)
    try:
        s.doStep(step, 2.5 * step)
        accepted = True
    except FMICallException:
        accepted = False
    s.freeInstance()
    assert accepted == md.coSimulation.canHandleVariableCommunicationStepSize


def test_default_experiment_step_is_accepted(any_fmu, tmp_path):
    """DefaultExperiment's stepSize is a step the FMU takes (the Controller's sample period h)."""
    md = read_model_description(str(any_fmu))
    s, refs = slave(any_fmu, tmp_path)
    if "h" in refs:
        assert s.getReal([refs["h"]])[0] == pytest.approx(float(md.defaultExperiment.stepSize))
    t = 0.0
    for _ in range(3):
        s.doStep(t, float(md.defaultExperiment.stepSize))
        t += float(md.defaultExperiment.stepSize)
    s.freeInstance()


def test_model_exchange_offered_only_where_it_works(any_fmu, tmp_path):
    """An FMU without ModelExchange in its description refuses to be instantiated as one; the plant's
    declared number of event indicators is what fmi2GetEventIndicators delivers, and they change sign."""
    md = read_model_description(str(any_fmu))
    unzipdir = extract(str(any_fmu), str(tmp_path / "me"))
    identifier = md.coSimulation.modelIdentifier
    model = FMU2Model(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier=identifier, instanceName="m")
    if md.modelExchange is None:
        with pytest.raises(Exception):
            model.instantiate()
        return
    model.instantiate()
    model.setupExperiment(startTime=0.0)
    model.enterInitializationMode()
    refs = {v.name: v.valueReference for v in md.modelVariables}
    model.setReal([refs["alpha"], refs["xdot"]], [np.pi, 0.3])  # cart coasting out of the stick band
    model.exitInitializationMode()
    model.newDiscreteStates()
    model.enterContinuousTimeMode()
    nz = md.numberOfEventIndicators
    assert nz > 0
    z = (ctypes.c_double * nz)()
    model.getEventIndicators(z, nz)
    z0 = np.array(z)
    with pytest.raises(FMICallException):
        model.getEventIndicators((ctypes.c_double * (nz + 1))(), nz + 1)
    # Integrate with explicit Euler until some indicator changes sign.
    x, dx = (ctypes.c_double * 4)(), (ctypes.c_double * 4)()
    model.getContinuousStates(x, 4)
    t = 0.0
    changed = False
    for _ in range(2000):
        t += 1e-4
        model.getDerivatives(dx, 4)
        for k in range(4):
            x[k] += 1e-4 * dx[k]
        model.setTime(t)
        model.setContinuousStates(x, 4)
        model.getEventIndicators(z, nz)
        if np.any(np.sign(np.array(z)) != np.sign(z0)):
            changed = True
            break
    model.terminate()
    model.freeInstance()
    assert changed
