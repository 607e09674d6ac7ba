"""One FMU as a component of a loop: set, get, step, reset, with one error type.

Every place that steps an FMU (the co-simulation master, the lab session, the rig emulator's plant,
the calibration's virtual rig) holds :class:`Component` objects. fmpy loads the FMU and provides the
FMI calls; a component caches the C entry points it calls in a loop (fmpy's per-call Python wrappers
cost more than the plant's step itself), and reads or writes many variables at once through a
:class:`Port`. Any FMI call that fails raises :class:`SimulationError`.

Examples
--------
>>> from pendulab.cosim.component import Component
>>> from pendulab.fmu.build import ensure_fmu
>>> with Component("plant", ensure_fmu("Plant")) as plant:
...     plant.setup(0.0, {"alpha": 0.01})
...     for k in range(10):
...         plant.step(k * 1e-3, 1e-3)
...     port = plant.port(["alpha", "x"])
...     plant.read(port)
...     round(port.values["Real"][0], 5) > 0.01      # the pendulum falls away from upright
True
"""

from __future__ import annotations

import ctypes
import shutil
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

from fmpy import extract, read_model_description
from fmpy import platform as fmpy_platform
from fmpy.fmi2 import FMU2Slave

from pendulab.errors import UserError

#: The FMI 2.0 base types a :class:`Port` holds, and their ctypes.
BASE_TYPES = ("Real", "Integer", "Boolean")
C_TYPES = {"Real": ctypes.c_double, "Integer": ctypes.c_int, "Boolean": ctypes.c_int}


class SimulationError(RuntimeError):
    """An FMU reported an error (a failed FMI call: initialization, get, set or step)."""


@dataclass
class Port:
    """The variables of one component read or written together, one ctypes array per base type.

    ``values[base_type][i]`` is the ``i``-th variable of that type in ``names[base_type]``
    (:meth:`index` finds it).
    """

    vrs: dict[str, Any]
    values: dict[str, Any]
    names: dict[str, list[str]]

    @classmethod
    def create(cls, variables: Sequence[tuple[str, str, int]]) -> "Port":
        """From ``(name, base type, value reference)`` triples."""
        names: dict[str, list[str]] = {t: [] for t in BASE_TYPES}
        refs: dict[str, list[int]] = {t: [] for t in BASE_TYPES}
        for name, vtype, vr in variables:
            names[vtype].append(name)
            refs[vtype].append(vr)
        return cls(
            vrs={t: (ctypes.c_uint * len(refs[t]))(*refs[t]) for t in BASE_TYPES},
            values={t: (C_TYPES[t] * len(refs[t]))() for t in BASE_TYPES},
            names=names,
        )

    def index(self, name: str) -> tuple[str, int]:
        """``(base type, index)`` of a variable in :attr:`values`."""
        for t in BASE_TYPES:
            if name in self.names[t]:
                return t, self.names[t].index(name)
        raise KeyError(name)


def _needed_at_run_time(name: str) -> bool:
    return not name.startswith(("sources/", "binaries/", "documentation/")) or name.startswith(f"binaries/{fmpy_platform}/")


class Component:
    """One instantiated FMI 2.0 Co-Simulation FMU with its cached C entry points.

    Parameters
    ----------
    name : str
        The component's name in the loop (used in messages and as the FMU's instance name).
    fmu_path : path
        The ``.fmu`` file.
    start_values : mapping, optional
        Values set at every :meth:`setup` and :meth:`reset` before initialization.

    Raises
    ------
    UserError
        The file is missing, not an FMU, not FMI 2.0 Co-Simulation.
    """

    def __init__(self, name: str, fmu_path: str | Path, start_values: Mapping[str, Any] | None = None):
        fmu_path = Path(fmu_path)
        self.start_values = dict(start_values or {})
        self._unzipdir: str | None = None
        if not fmu_path.is_file():
            raise UserError(f"FMU {fmu_path} of component {name!r} does not exist; build it with 'pendulab build-fmus'")
        self.name = name
        # Only what a run needs: the description, resources and this platform's binary (not the
        # sources, documentation or other platforms' binaries; this halves the start-up time).
        try:
            unzipdir = extract(str(fmu_path), include=_needed_at_run_time)
        except zipfile.BadZipFile:
            raise UserError(f"{fmu_path} of component {name!r} is not an FMU (not a ZIP archive)") from None
        self._unzipdir = unzipdir
        try:
            self.description = read_model_description(unzipdir)
        except Exception as exc:  # fmpy raises plain exceptions for a missing or invalid modelDescription.xml
            raise UserError(f"{fmu_path} of component {name!r} is not a valid FMU: {exc}") from None
        if self.description.coSimulation is None:
            raise UserError(f"{fmu_path} has no Co-Simulation interface; the master runs Co-Simulation FMUs")
        if self.description.fmiVersion != "2.0":
            raise UserError(f"{fmu_path} is an FMI {self.description.fmiVersion} FMU; the master runs FMI 2.0 FMUs "
                            "(the FMI 3.0 plant is for other tools: pendulab simulate --ssp Plant3)")
        self.variables = {v.name: v for v in self.description.modelVariables}
        self.fmu = FMU2Slave(
            guid=self.description.guid,
            unzipDirectory=unzipdir,
            modelIdentifier=self.description.coSimulation.modelIdentifier,
            instanceName=name,
        )
        self.fmu.instantiate()
        self.handle = self.fmu.component
        dll = self.fmu.dll
        self.do_step = dll.fmi2DoStep
        self.get = {"Real": dll.fmi2GetReal, "Integer": dll.fmi2GetInteger, "Boolean": dll.fmi2GetBoolean}
        self.set = {"Real": dll.fmi2SetReal, "Integer": dll.fmi2SetInteger, "Boolean": dll.fmi2SetBoolean}

    @property
    def folder(self) -> str | None:
        """The folder the FMU is unpacked into (removed by :meth:`close`)."""
        return self._unzipdir

    # ------------------------------------------------------------------ life cycle
    def __enter__(self) -> "Component":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Free the instance and remove its unpacked folder (safe to call twice)."""
        fmu, self.fmu = getattr(self, "fmu", None), None
        if fmu is not None:
            try:
                fmu.freeInstance()
            except Exception:  # noqa: BLE001 - freeing must not hide the error that led here
                pass
        if self._unzipdir:
            shutil.rmtree(self._unzipdir, ignore_errors=True)
            self._unzipdir = None

    def setup(self, start_time: float, values: Mapping[str, Any] | None = None, *, stop_time: float | None = None) -> None:
        """Set the start values (with ``values`` on top) and initialize at ``start_time``."""
        self.fmu.setupExperiment(startTime=start_time, stopTime=stop_time)
        # One call per base type (a sweep sets some 60 start values per run), in the order given.
        batches: dict[str, tuple[list[int], list[Any]]] = {"Real": ([], []), "Integer": ([], []), "Boolean": ([], [])}
        for variable, value in {**self.start_values, **(values or {})}.items():
            v = self.variable(variable)
            kind = "Integer" if v.type == "Enumeration" else v.type
            if kind not in batches:
                raise UserError(f"variable {self.name}.{variable} of type {v.type} cannot be set by the master")
            batches[kind][0].append(v.valueReference)
            batches[kind][1].append({"Real": float, "Integer": int, "Boolean": bool}[kind](value))
        setters = {"Real": self.fmu.setReal, "Integer": self.fmu.setInteger, "Boolean": self.fmu.setBoolean}
        try:
            # A start value outside its variable's range is refused here, with the FMU's log line naming it.
            for kind, (refs, numbers) in batches.items():
                if refs:
                    setters[kind](refs, numbers)
            self.fmu.enterInitializationMode()
            self.fmu.exitInitializationMode()
        except UserError:
            raise
        except Exception as exc:  # fmpy raises FMICallException with the status only
            raise SimulationError(f"{self.name}: initialization failed ({exc}); check its start values") from exc

    def reset(self, start_time: float, values: Mapping[str, Any] | None = None) -> None:
        """``fmi2Reset``, then :meth:`setup` again at ``start_time`` (e.g. a new initial state in ``values``)."""
        self.fmu.reset()
        self.setup(start_time, values)

    def step(self, t: float, h: float) -> None:
        """One communication step ``fmi2DoStep(t, h)``."""
        if self.do_step(self.handle, t, h, 1) > 1:
            raise SimulationError(f"{self.name} failed at t={t:.4f} s (the FMU's log has the reason)")

    # ------------------------------------------------------------------ variables
    def variable(self, name: str) -> Any:
        """The variable's fmpy description (``type``, ``valueReference``, ``causality``, ...)."""
        try:
            return self.variables[name]
        except KeyError:
            raise UserError(f"component {self.name!r} has no variable {name!r}") from None

    def port(self, names: Iterable[str]) -> Port:
        """A :class:`Port` for reading or writing ``names`` together."""
        return Port.create([(n, self.variable(n).type, self.variable(n).valueReference) for n in names])

    def set_value(self, name: str, value: Any) -> None:
        """Set one variable by name (slow path: set-up and events)."""
        v = self.variable(name)
        if v.type == "Real":
            self.fmu.setReal([v.valueReference], [float(value)])
        elif v.type in ("Integer", "Enumeration"):
            self.fmu.setInteger([v.valueReference], [int(value)])
        elif v.type == "Boolean":
            self.fmu.setBoolean([v.valueReference], [bool(value)])
        else:
            raise UserError(f"variable {self.name}.{name} of type {v.type} cannot be set by the master")

    def get_value(self, name: str) -> float:
        """Read one variable by name (slow path)."""
        port = self.port([name])
        self.read(port)
        t, i = port.index(name)
        return port.values[t][i]

    def read(self, port: Port) -> None:
        """Fill ``port.values`` from the FMU."""
        for t in BASE_TYPES:
            n = len(port.names[t])
            if n and self.get[t](self.handle, port.vrs[t], n, port.values[t]) > 1:
                raise SimulationError(f"{self.name}: fmi2Get{t} failed")

    def write(self, port: Port) -> None:
        """Set the FMU's variables from ``port.values``."""
        for t in BASE_TYPES:
            n = len(port.names[t])
            if n and self.set[t](self.handle, port.vrs[t], n, port.values[t]) > 1:
                raise SimulationError(f"{self.name}: fmi2Set{t} failed")
