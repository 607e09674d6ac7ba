"""Every capability flag of the FMUs' modelDescriptions, checked against what the FMU does (issue 12);
the FMI 3.0 plant (Plant3, issue 11) through fmpy's FMI 3.0 classes; the seesaw's two (issue 20) too."""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Model, FMU2Slave
from fmpy.fmi3 import FMU3Model, FMU3Slave
from fmpy.validation import validate_fmu


def is_fmi3(md) -> bool:  # noqa: ANN001 - fmpy's ModelDescription
    return md.fmiVersion.startswith("3.")


def initialize(fmu, md, start: dict[str, float] | None = None) -> dict[str, int]:  # noqa: ANN001 - fmpy FMU objects
    """Initialization mode with ``start`` set, in either FMI version's calls."""
    refs = {v.name: v.valueReference for v in md.modelVariables}
    types = {v.name: v.type for v in md.modelVariables}
    if is_fmi3(md):
        fmu.enterInitializationMode(startTime=0.0)
    else:
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
    for name, value in (start or {}).items():
        if types[name] in ("Integer", "Int32"):
            (fmu.setInt32 if is_fmi3(md) else fmu.setInteger)([refs[name]], [int(value)])
        else:
            (fmu.setFloat64 if is_fmi3(md) else fmu.setReal)([refs[name]], [value])
    fmu.exitInitializationMode()
    return refs


def slave(fmu: Path, tmp_path: Path, start: dict[str, float] | None = None) -> tuple[FMU2Slave | FMU3Slave, dict[str, int]]:
    md = read_model_description(str(fmu))
    unzipdir = extract(str(fmu), str(tmp_path / fmu.stem))
    cls = FMU3Slave if is_fmi3(md) else FMU2Slave
    s = cls(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier=md.coSimulation.modelIdentifier, instanceName="i")
    s.instantiate()
    return s, initialize(s, md, start)


@pytest.fixture(params=["plant", "controller", "supervisor", "plant3", "seesaw", "seesaw3"])
def any_fmu(request, plant_fmu, controller_fmu, supervisor_fmu, plant3_fmu, seesaw_fmu, seesaw3_fmu) -> Path:
    return {"plant": plant_fmu, "controller": controller_fmu, "supervisor": supervisor_fmu, "plant3": plant3_fmu,
            "seesaw": seesaw_fmu, "seesaw3": seesaw3_fmu}[request.param]


@pytest.mark.parametrize("name", ["plant", "plant3", "controller", "supervisor", "seesaw"])
def test_fmpy_validate_is_clean(name, request):
    """``fmpy validate`` of every FMU finds no problem: its check (fmpy.validation.validate_fmu), run here once
    for all of them; the command line itself runs in test_readme_fmi (the README's commands)."""
    assert validate_fmu(str(request.getfixturevalue(f"{name}_fmu"))) == []


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
    declared number of event indicators is what fmi2GetEventIndicators (fmi3GetEventIndicators) delivers,
    and they change sign."""
    md = read_model_description(str(any_fmu))
    unzipdir = extract(str(any_fmu), str(tmp_path / "me"))
    identifier = md.coSimulation.modelIdentifier
    cls = FMU3Model if is_fmi3(md) else FMU2Model
    model = cls(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier=identifier, instanceName="m")
    if md.modelExchange is None:
        with pytest.raises(Exception):
            model.instantiate()
        return
    model.instantiate()
    # The cart coasting out of the stick band (the pendulum hanging; the seesaw level).
    initialize(model, md, {"alpha": np.pi, "xdot": 0.3} if "alpha" in {v.name for v in md.modelVariables} else {"xdot": 0.3})
    (model.updateDiscreteStates if is_fmi3(md) else model.newDiscreteStates)()
    model.enterContinuousTimeMode()
    get_derivatives = model.getContinuousStateDerivatives if is_fmi3(md) else model.getDerivatives
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
        get_derivatives(dx, 4)
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


@pytest.mark.parametrize("name", ["plant", "plant3"])
def test_model_exchange_vectors_of_another_size_are_refused(name, plant_fmu, plant3_fmu, tmp_path):
    """States, derivatives and nominals are exchanged only with as many elements as the model has states,
    in both FMI versions (one implementation, fmu_common.c, checks them for both)."""
    fmu = {"plant": plant_fmu, "plant3": plant3_fmu}[name]
    md = read_model_description(str(fmu))
    cls = FMU3Model if is_fmi3(md) else FMU2Model
    model = cls(guid=md.guid, unzipDirectory=extract(str(fmu), str(tmp_path / "me")),
                modelIdentifier=md.modelExchange.modelIdentifier, instanceName="m")
    model.instantiate()
    initialize(model, md, {"alpha": 0.2})
    (model.updateDiscreteStates if is_fmi3(md) else model.newDiscreteStates)()
    model.enterContinuousTimeMode()
    get_derivatives = model.getContinuousStateDerivatives if is_fmi3(md) else model.getDerivatives
    calls = (model.getContinuousStates, model.setContinuousStates, get_derivatives, model.getNominalsOfContinuousStates)
    n = md.numberOfContinuousStates if is_fmi3(md) else len(md.derivatives)
    for call in calls:
        for wrong in (n - 1, n + 1):
            with pytest.raises(FMICallException):
                call((ctypes.c_double * wrong)(), wrong)
    x, nominals = (ctypes.c_double * n)(), (ctypes.c_double * n)()
    model.getContinuousStates(x, n)
    model.setContinuousStates(x, n)
    model.getNominalsOfContinuousStates(nominals, n)
    assert x[:] != [0.0] * n and nominals[:] == [1.0] * n
    model.terminate()
    model.freeInstance()
