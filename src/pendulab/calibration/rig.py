"""The rig interface of the calibration procedure, and the virtual rig.

A :class:`Rig` takes one voltage per period and returns the measured cart position. The ramp test only talks to this interface, so the same code runs
against the real rig (the hardware-in-the-loop link, SPEC §9) and the virtual rig here: the plant FMU without the pendulum.

Examples
--------
>>> from pendulab.calibration.rig import VirtualRig
>>> with VirtualRig(friction=(2.0, 0.005, 3.5, 0.05, 25.0), x0=0.0) as rig:
...     x = rig.reset()
...     for _ in range(100):
...         x = rig.step(0.5)          # 0.86 N < F1: the cart sticks
>>> x
0.0
"""

from __future__ import annotations

import abc
import warnings
from typing import Callable, Sequence

from pendulab.errors import CalibrationError, FmuBuildError
from pendulab.model.parameters import FRICTION_NAMES, PlantParameters

#: The pendulum's fields, zeroed for the cart alone.
NO_PENDULUM = {"Mp": 0.0, "Lp": 0.0, "lp": 0.0, "Ip": 0.0, "Bp": 0.0}


class RigEnded(Exception):
    """The rig ended the test early (a fault, a restart, its watchdog, a lost link, its track limit).

    The ramp test stops there, the motor off, and keeps what was measured (like Ctrl-C); the message names the cause.
    """


class Rig(abc.ABC):
    """A cart on a track that takes a voltage each period and reports its measured position.

    Implementations: :class:`VirtualRig` and, later, the HIL rig. ``step`` blocks for one period on real hardware, returns at once on a virtual rig.
    """

    #: Control period (s).
    period: float = 1e-3
    #: Short text for logs and metadata.
    description: str = "rig"

    @property
    @abc.abstractmethod
    def time(self) -> float:
        """Time (s) since :meth:`reset`."""

    @abc.abstractmethod
    def reset(self) -> float:
        """Start a new run (time 0, motor off) and return the measured position (m)."""

    @abc.abstractmethod
    def step(self, voltage: float) -> float:
        """Apply ``voltage`` (V) for one period and return the measured position (m) at its end."""

    def stop(self) -> None:
        """Motor off (voltage 0). The default applies 0 V for one period."""
        self.step(0.0)

    def close(self) -> None:
        """Release the rig (files, links)."""

    def __enter__(self) -> "Rig":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class VirtualRig(Rig):
    """The plant FMU with the pendulum removed, stepped every :attr:`Rig.period` (1 ms).

    Parameters
    ----------
    params : PlantParameters, optional
        The cart's true parameters (default: IP02 cart, lab friction). The pendulum fields are zeroed whatever is given.
    friction : sequence of 5 floats, optional
        True friction vector ``[F1, v1, F2, v2, B]`` (overrides ``params``).
    x0 : float
        Where the cart stands when the run starts (m); off centre, so the procedure must centre it.
    backend : {"auto", "fmu", "casadi"}
        ``"fmu"`` steps ``Plant.fmu`` through fmpy (built on first use); ``"casadi"`` steps the CasADi model in-process (the same equations, no
        compiler needed); ``"auto"`` uses the FMU and falls back to CasADi when it cannot be built.
    progress : callable(str), optional
        Told when the plant FMU is being built (first use).
    """

    def __init__(
        self,
        params: PlantParameters | None = None,
        *,
        friction: Sequence[float] | None = None,
        x0: float = 0.05,
        backend: str = "auto",
        progress: Callable[[str], None] | None = None,
    ) -> None:
        params = params or PlantParameters.preset(pendulum="none")
        if friction is not None:
            friction = [float(f) for f in friction]
            if len(friction) != 5:
                raise CalibrationError(f"the virtual rig's friction needs 5 numbers F1,v1,F2,v2,B, got {len(friction)}")
            params = params.with_values(**dict(zip(FRICTION_NAMES, friction)))
        self.params = params.with_values(**NO_PENDULUM)
        self.x0 = float(x0)
        if backend not in ("auto", "fmu", "casadi"):
            raise CalibrationError(f"unknown virtual rig backend {backend!r}; choose auto, fmu or casadi")
        self._stepper: _FmuStepper | _CasadiStepper | None = None
        if backend in ("auto", "fmu"):
            try:
                self._stepper = _FmuStepper(self.params, self.period, progress)
            except (FmuBuildError, OSError) as exc:
                if backend == "fmu":
                    raise CalibrationError(f"cannot use the plant FMU for the virtual rig: {exc}") from None
                warnings.warn(f"plant FMU unavailable ({exc}); the virtual rig steps the CasADi model instead", stacklevel=2)
        self._stepper = self._stepper or _CasadiStepper(self.params, self.period)
        self.backend = self._stepper.name
        self.description = f"virtual rig ({self.backend}, friction {list(self.params.friction)})"
        self._k = 0

    @property
    def time(self) -> float:
        return self._k * self.period

    def reset(self) -> float:
        self._k = 0
        return self._stepper.reset(self.x0)

    def step(self, voltage: float) -> float:
        x = self._stepper.step(float(voltage), self.time)
        self._k += 1
        return x

    def close(self) -> None:
        self._stepper.close()


class _FmuStepper:
    """Co-simulation of ``Plant.fmu`` through fmpy: set ``V``, ``doStep``, read ``x_measured``."""

    name = "fmu"

    def __init__(self, params: PlantParameters, period: float, progress: Callable[[str], None] | None = None) -> None:
        from pendulab.cosim.component import Component
        from pendulab.fmu.build import ensure_fmu

        self._fmu = Component("virtual_rig", ensure_fmu("Plant", progress=progress), params.as_dict())
        self._period = period
        self._in = self._fmu.port(["V"])
        self._out = self._fmu.port(["x_measured"])
        self._live = False

    def reset(self, x0: float) -> float:
        (self._fmu.reset if self._live else self._fmu.setup)(0.0, {"x": x0, "xdot": 0.0, "alpha": 0.0, "alphadot": 0.0, "V": 0.0})
        self._live = True
        self._fmu.read(self._out)
        return self._out.values["Real"][0]

    def step(self, voltage: float, t: float) -> float:
        self._in.values["Real"][0] = voltage
        self._fmu.write(self._in)
        self._fmu.step(t, self._period)  # SimulationError if the FMU refuses (it checks for non-finite states)
        self._fmu.read(self._out)
        return self._out.values["Real"][0]

    def close(self) -> None:
        self._fmu.close()
        self._live = False


class _CasadiStepper:
    """The same plant stepped in-process by the CasADi model (``PlantModel`` sub-steps + encoder)."""

    name = "casadi"

    def __init__(self, params: PlantParameters, period: float) -> None:
        import casadi as ca

        from pendulab.model.plant import MAX_SUBSTEP, PlantModel, step_function, substeps

        n_sub = substeps(period, MAX_SUBSTEP)
        model = PlantModel()
        state, V, t = ca.MX.sym("state", 4), ca.MX.sym("V"), ca.MX.sym("t")
        p = ca.MX.sym("p", model.n_parameters)
        after = step_function(False, n_sub)(state, V, p, t, period / n_sub)
        self._f = ca.Function("virtual_rig_step", [state, V, p, t], [after, model.outputs(after, V, p, t + period)[1]]).expand()  # state, measured
        self._measure = model.outputs
        self._p = ca.DM(params.as_vector())
        self._state = ca.DM.zeros(4)

    def reset(self, x0: float) -> float:
        import casadi as ca

        self._state = ca.DM([x0, 0.0, 0.0, 0.0])
        return float(self._measure(self._state, 0.0, self._p, 0.0)[1])

    def step(self, voltage: float, t: float) -> float:
        self._state, measured = self._f(self._state, voltage, self._p, t)
        return float(measured)

    def close(self) -> None:
        pass
