"""The raw fmpy harness the FMU tests share: one FMI 2.0 Co-Simulation instance driven call by call, a
logger that captures an FMU's messages.

The FMU tests drive the FMUs through fmpy's own classes (not pendulab's component layer): what they test
is the FMI calls themselves. This module holds the calls they all make the same way, once.
"""

from __future__ import annotations

import ctypes
import functools
import math
import os
import platform
import tempfile
from ctypes import CFUNCTYPE, c_char_p, c_int, c_void_p
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from fmpy import calloc, extract, free, read_model_description
from fmpy.fmi2 import (
    FMU2Slave,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
)


def unzipped(fmu: str | os.PathLike[str]) -> Path:
    """The FMU's folder: ``fmu`` itself if it is one, else the ``.fmu`` extracted into a temporary folder (once
    per file and modification time in this test session)."""
    path = Path(fmu).resolve()
    return path if path.is_dir() else _extracted(path, path.stat().st_mtime_ns)


@functools.lru_cache(maxsize=None)
def _extracted(path: Path, mtime_ns: int) -> Path:
    return Path(extract(str(path), unzipdir=tempfile.mkdtemp(prefix=f"{path.stem}-")))


def value_references(fmu: str | os.PathLike[str]) -> tuple[str, dict[str, int]]:
    """``(guid, {name: value reference})`` of an FMU (its file or its folder)."""
    md = read_model_description(str(fmu))
    return md.guid, {v.name: v.valueReference for v in md.modelVariables}


class Slave:
    """An FMI 2.0 Co-Simulation instance through fmpy's ``FMU2Slave``, instantiated and (unless
    ``initialize=False``) initialized at t = 0 with the ``start`` values set in initialization mode.

    ``set``/``get`` call the setter/getter of each variable's type; ``step(h)`` steps from ``self.t``.
    ``close()`` frees the instance (after ``terminate()`` if the run ended normally); it is a context manager.
    ``initialize=False`` leaves the instance just instantiated, for a test of the initialization calls;
    ``description`` (fmpy's ModelDescription of the FMU) saves reading it again for each instance.
    """

    def __init__(self, fmu: str | os.PathLike[str], start: Mapping[str, Any] | None = None, *, name: str | None = None,
                 callbacks: fmi2CallbackFunctions | None = None, logging: bool = False, initialize: bool = True,
                 description: Any = None):
        folder = unzipped(fmu)
        self.description = description or read_model_description(str(folder))
        self.variables = {v.name: v for v in self.description.modelVariables}
        self.refs = {n: v.valueReference for n, v in self.variables.items()}
        identifier = self.description.coSimulation.modelIdentifier
        self.fmu = FMU2Slave(guid=self.description.guid, unzipDirectory=str(folder), modelIdentifier=identifier,
                             instanceName=name or identifier.lower())
        self.fmu.instantiate(callbacks=callbacks, loggingOn=logging)
        self.t = 0.0
        if initialize:
            try:
                self.initialize(start)
            except BaseException:
                self.fmu.freeInstance()
                raise

    def initialize(self, start: Mapping[str, Any] | None = None) -> None:
        """setupExperiment(0), initialization mode, the ``start`` values set, and out of it."""
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        self.set(start or {})
        self.fmu.exitInitializationMode()

    def set(self, values: Mapping[str, Any]) -> None:
        """Set each variable by the setter of its type (Real, Integer or Boolean)."""
        for name, value in values.items():
            v = self.variables[name]
            if v.type == "Real":
                self.fmu.setReal([v.valueReference], [float(value)])
            elif v.type == "Integer":
                self.fmu.setInteger([v.valueReference], [int(value)])
            else:
                self.fmu.setBoolean([v.valueReference], [value])

    def get(self, names: Sequence[str]) -> list:
        """The variables' values, each by the getter of its type."""
        getters = {"Real": self.fmu.getReal, "Integer": self.fmu.getInteger, "Boolean": self.fmu.getBoolean}
        if all(self.variables[n].type == "Real" for n in names):  # one call, as a master reads outputs
            return list(self.fmu.getReal([self.refs[n] for n in names]))
        return [getters[self.variables[n].type]([self.refs[n]])[0] for n in names]

    def step(self, h: float, t: float | None = None) -> None:
        """doStep from ``t`` (default: where the last step ended) over ``h``."""
        self.fmu.doStep(self.t if t is None else t, h)
        self.t = (self.t if t is None else t) + h

    def terminate(self) -> None:
        self.fmu.terminate()

    def close(self) -> None:
        self.fmu.freeInstance()

    def __enter__(self) -> "Slave":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def run_cs(fmu: str | os.PathLike[str], outputs: Sequence[str], inputs: Mapping[str, Sequence[float]] | None = None, *,
           n_steps: int | None = None, step: float | Sequence[float] = 1e-3, start: Mapping[str, Any] | None = None,
           first_row: bool = True) -> np.ndarray:
    """An open-loop Co-Simulation: each input held over its step; rows are ``outputs`` at t = 0 (unless
    ``first_row=False``), t1, ..., tn.

    A fixed ``step`` steps from ``t_k = k * step`` (the CasADi reference's grid); a sequence of steps from
    their running sum. ``n_steps`` defaults to the inputs' length.
    """
    inputs = {name: np.asarray(values, dtype=float) for name, values in (inputs or {}).items()}
    n = n_steps if n_steps is not None else len(next(iter(inputs.values())))
    if np.ndim(step):
        steps = [float(h) for h in step]
        times = list(np.cumsum([0.0, *steps[:-1]]))
    else:
        steps = [float(step)] * n
        times = [k * float(step) for k in range(n)]
    with Slave(fmu, start) as slave:
        rows = [slave.get(outputs)] if first_row else []
        for k, (t, h) in enumerate(zip(times, steps)):
            slave.set({name: values[k] for name, values in inputs.items()})
            slave.step(h, t)
            rows.append(slave.get(outputs))
        slave.terminate()
    return np.array(rows)


# ---------------------------------------------------------------- an FMU's log messages
# The wrapper logs like FMI 2.0 says: logger(..., "%s", text). ctypes callbacks cannot take varargs, and
# fmpy's addLoggerProxy keeps ONE global target (it would redirect fmpy's default logger to this test's
# callback, which crashes once the callback is collected). On x86-64 and Linux aarch64 a variadic argument
# arrives like a fixed one, so a sixth c_char_p parameter receives the text.
_LoggerWithText = CFUNCTYPE(None, c_void_p, c_char_p, c_int, c_char_p, c_char_p, c_char_p)
#: Whether :func:`capturing_callbacks` sees the messages' text (else the tests skip checking it).
VARARGS_AS_FIXED = platform.system() == "Linux" and platform.machine() in ("x86_64", "aarch64")


def capturing_callbacks(messages: list[str]) -> fmi2CallbackFunctions:
    """FMI 2.0 callbacks whose logger appends each message's text to ``messages``."""
    def logger(env, instance, status, category, message, first_arg):  # noqa: ANN001
        text = first_arg if message == b"%s" and VARARGS_AS_FIXED else message
        messages.append(text.decode(errors="replace"))

    callbacks = fmi2CallbackFunctions()
    callbacks.logger = ctypes.cast(_LoggerWithText(logger), fmi2CallbackLoggerTYPE)
    callbacks._keep = logger  # the Structure keeps the C thunk; keep the closure too
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    return callbacks


def hanging_plant_run(plant: str | os.PathLike[str], n_steps: int = 1500, step: float = 1e-3) -> np.ndarray:
    """The plain C hosts' open-loop case through fmpy (test_fmu_build's host, tests/hosts/fmu_host.c): the
    hanging pendulum released at 0.3 rad, V a 1 Hz sine of 12 V (saturating); the states after each step."""
    V = [12.0 * math.sin(2 * math.pi * k * step) for k in range(n_steps)]  # math.sin, as the C hosts' sin()
    return run_cs(plant, ("x", "xdot", "alpha", "alphadot"), {"V": V}, step=step, start={"alpha": math.pi + 0.3}, first_row=False)


def ecos_run(fmu: str | os.PathLike[str], outputs: Sequence[str], V: Sequence[float], start: Mapping[str, float] | None = None,
             step: float = 1e-3) -> np.ndarray:
    """The open-loop run of :func:`run_cs` in Ecos (ecospy), an independent FMI engine: ``V`` held over each
    step; rows are ``outputs`` at t = 0, t1, ..., tn. The caller skips without ecospy (``pytest.importorskip``)."""
    import ecospy

    name = Path(fmu).stem.lower()
    with ecospy.EcosSimulationStructure() as structure:
        structure.add_model(name, str(fmu))
        structure.add_parameter_set("initial", {f"{name}::{k}": float(v) for k, v in (start or {}).items()})
        with ecospy.EcosSimulation(structure=structure, step_size=step) as sim:
            assert sim.init(parameter_set="initial")
            rows = [[sim.get_real(f"{name}::{s}") for s in outputs]]
            for v in V:
                sim.set_real(f"{name}::V", float(v))
                sim.step()
                rows.append([sim.get_real(f"{name}::{s}") for s in outputs])
            assert math.isclose(sim.get_time(), len(V) * step, rel_tol=1e-9), sim.get_time()
            sim.terminate()
    return np.array(rows)
