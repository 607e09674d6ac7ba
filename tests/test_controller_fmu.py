"""Controller.fmu (issue 3, must-show 2): its discrete response equals ``control.c2d`` of the same
transfer function, Tustin and ZOH; orders up to 16; a larger order or another step size is refused.

The FMU is driven step by step through fmpy's ``FMU2Slave`` as a master does: set the input at
``t_k``, read ``V_command`` (the same communication point: ``y[k] = C x[k] + D e[k]``), ``doStep``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

import control
import fmi_harness
import numpy as np
import pytest
from fmpy import extract
from fmpy.fmi1 import FMICallException

from pendulab.control.controller import Controller, Factor, demo_controller, unstable_example
from pendulab.control.realization import MAX_ORDER, discretize
from pendulab.cosim.master import Master
from pendulab.cosim.pendulum import pendulum_system
from pendulab.model.parameters import PlantParameters

H = 1e-3
LP = 0.6413

#: The lab's controllers and two high-order ones (6 factors each), by name.
CONTROLLERS: dict[str, Controller] = {
    "demo": demo_controller(),
    "unstable demo": unstable_example(),
    "pid": Controller.pid(40.0, 5.0, 4.0),
    "six factors": Controller(
        [
            Factor([-5.0], [6.0], 3e6, label="kernel"),
            Factor([-2.0], [-20.0]),
            Factor([-15.0], [-150.0]),
            Factor([-0.5], [-0.05]),
            Factor([complex(-10, 20), complex(-10, -20)], [complex(-30, 40), complex(-30, -40)]),
            Factor([], [-400.0], 2.0),
        ]
    ),
    "order 16": Controller(  # the gain spread over the factors keeps every realization well scaled
        [
            Factor([-3.0, -40.0], [-2.0, complex(-5, 12), complex(-5, -12)], 3000.0, label="kernel"),
            Factor([-20.0], [-60.0, -150.0], 150.0),
            Factor([complex(-8, 30), complex(-8, -30)], [complex(-15, 25), complex(-15, -25)]),
            Factor([-1.0], [-0.5, -90.0], 90.0),
            Factor([], [-300.0, complex(-40, 70), complex(-40, -70)], 2e6),
            Factor([-6.0], [-7.0, -250.0, -700.0, 3.0], 5e5),
        ]
    ),
}


@pytest.fixture(scope="module")
def unzipdir(controller_fmu: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return Path(extract(str(controller_fmu), unzipdir=str(tmp_path_factory.mktemp("Controller"))))


class ControllerSlave(fmi_harness.Slave):
    """Controller.fmu through fmpy, initialized with the given start values."""

    def __init__(self, unzipdir: Path, start: Mapping[str, float]):
        super().__init__(unzipdir, start, name="controller")

    def respond(self, r=None, alpha=None, h: float = H) -> np.ndarray:
        """``V_command`` for the input sequence (reference ``r`` or measured angle ``alpha``)."""
        name, values = ("r", r) if r is not None else ("alpha_measured", alpha)
        out = np.empty(len(values))
        for k, value in enumerate(values):
            self.set({name: value})
            out[k] = self.get(["V_command"])[0]
            self.step(h)
        return out

    def close(self) -> None:
        self.terminate()
        super().close()


def fmu_response(unzipdir, controller, method, u, *, via_angle=False) -> np.ndarray:
    lti = discretize(controller, h=H, method=method)
    slave = ControllerSlave(unzipdir, {**lti.to_parameters(), "h": H, "Lp": LP})
    try:
        return slave.respond(alpha=-u / LP) if via_angle else slave.respond(r=u)
    finally:
        slave.close()


def c2d_response(controller: Controller, method: str, u: np.ndarray) -> np.ndarray:
    """python-control's ``c2d`` of G(s), simulated by python-control.

    G(s) enters as python-control's own series connection of the factors' transfer functions (the
    same G(s), realized by python-control): ``c2d`` of one high-order *polynomial* transfer function
    loses the roots near z = 1 to round-off, the very problem the FMU's sectioned realization avoids.
    """
    g = control.ss(controller.factors[0].transfer_function())
    for factor in controller.factors[1:]:
        g = control.series(g, control.ss(factor.transfer_function()))
    return control.forced_response(control.c2d(g, H, method=method), U=u).outputs


def excitation() -> np.ndarray:
    """Noise plus a step: every mode is excited, and the step shows the DC gain."""
    u = np.random.default_rng(3).normal(scale=0.01, size=600)
    u[300:] += 0.02
    return u


@pytest.mark.parametrize("method", ["tustin", "zoh"])
@pytest.mark.parametrize("name", list(CONTROLLERS))
def test_fmu_response_equals_control_c2d(unzipdir, name, method):
    controller = CONTROLLERS[name]
    u = excitation()
    y = fmu_response(unzipdir, controller, method, u)
    reference = c2d_response(controller, method, u)
    assert np.max(np.abs(reference)) > 1e-3
    assert np.max(np.abs(y - reference)) <= 1e-9 * np.max(np.abs(reference))


@pytest.mark.parametrize("method", ["tustin", "zoh"])
def test_demo_equals_c2d_of_its_transfer_function(unzipdir, method):
    """For a low order, c2d straight of the polynomial transfer function G(s) = num/den."""
    controller = demo_controller()
    u = excitation()
    y = fmu_response(unzipdir, controller, method, u)
    gd = control.c2d(controller.transfer_function(), H, method=method)
    reference = control.forced_response(gd, U=u).outputs
    assert np.max(np.abs(y - reference)) <= 1e-8 * np.max(np.abs(reference))


def test_the_error_is_formed_from_the_measured_angle(unzipdir):
    """e = r - Lp*alpha_measured: feeding alpha = -u/Lp gives the response to u."""
    u = excitation()
    via_r = fmu_response(unzipdir, demo_controller(), "tustin", u)
    via_angle = fmu_response(unzipdir, demo_controller(), "tustin", u, via_angle=True)
    np.testing.assert_allclose(via_angle, via_r, rtol=1e-12, atol=1e-12 * np.max(np.abs(via_r)))


def test_orders_cover_the_fmu_capacity():
    assert CONTROLLERS["order 16"].order == MAX_ORDER == 16
    assert len(CONTROLLERS["six factors"].factors) == len(CONTROLLERS["order 16"].factors) == 6


def test_the_loop_runs_the_discretized_controller(loop_fmus):
    """In the closed loop the master's log of V_command is the discrete controller's response to
    the logged error -Lp*alpha_measured (same step, no delay inside the controller)."""
    params = PlantParameters.preset().with_values(poke_start=0.2)
    lti = discretize(demo_controller(), h=H, method="zoh")
    with Master(pendulum_system(params, lti.to_parameters(), step=H)) as master:
        log = master.run(1.0, ["plant.alpha_measured", "controller.V_command"])
    e = -params.Lp * log["plant.alpha_measured"]
    assert np.ptp(e) > 1e-3
    np.testing.assert_allclose(log["controller.V_command"], lti.step_response(e), rtol=0, atol=1e-9 * np.max(np.abs(log["controller.V_command"])))


# ---------------------------------------------------------------- refusals
@pytest.mark.parametrize("n", [MAX_ORDER + 1, -1])
def test_an_order_beyond_16_is_refused(unzipdir, n):
    with pytest.raises(FMICallException):
        ControllerSlave(unzipdir, {"n": n})


def test_an_order_16_with_nothing_else_set_is_accepted(unzipdir):
    slave = ControllerSlave(unzipdir, {"n": MAX_ORDER})
    try:
        assert np.all(slave.respond(r=np.ones(3)) == 0)
    finally:
        slave.close()


@pytest.mark.parametrize("h", [2e-3, 5e-4, 1.01e-3])
def test_a_step_other_than_the_sample_period_is_refused(unzipdir, h):
    lti = discretize(demo_controller(), h=H)
    slave = ControllerSlave(unzipdir, {**lti.to_parameters(), "h": H})
    try:
        slave.respond(r=np.ones(2))  # the period it was made for is fine
        with pytest.raises(FMICallException):
            slave.respond(r=np.ones(1), h=h)
    finally:
        slave.fmu.freeInstance()


@pytest.mark.parametrize("name, value", [("h", 0.0), ("h", -1e-3), ("D", float("nan")), ("A[1,1]", float("inf"))])
def test_bad_parameters_are_refused_at_initialization(unzipdir, name, value):
    with pytest.raises(FMICallException):
        ControllerSlave(unzipdir, {"n": 1, name: value})
