"""The demo controller balances both pendulums (sampled loop with delay, and the nonlinear model); the loop module."""

from __future__ import annotations

import casadi as ca
import control
import numpy as np
import pytest

from pendulab.control.controller import Controller, Factor, demo_controller, unstable_example
from pendulab.control.loop import closed_loop_poles, poke_response, sampled_plant
from pendulab.control.realization import discretize
from pendulab.model.linear import linearize
from pendulab.model.parameters import PlantParameters
from pendulab.model.plant import PlantModel, substeps

H = 1e-3
PENDULUMS = ("long", "short")


def reference_loop_poles(controller: Controller, params: PlantParameters, delay: int) -> np.ndarray:
    """The loop built independently with python-control transfer functions: minimal alpha/V, ZOH, z^-delay."""
    tip = linearize(params).tf("alpha") * params.Lp
    plant = control.c2d(tip, H, method="zoh")
    ctl = control.c2d(controller.transfer_function(), H, method="tustin")
    open_loop = ctl * plant * control.tf([1.0], [1.0] + [0.0] * delay, H)
    return control.feedback(open_loop, 1).poles()


def continuous_equivalents(z: np.ndarray) -> np.ndarray:
    return np.log(z.astype(complex)) / H


@pytest.mark.parametrize("pendulum", PENDULUMS)
def test_demo_stabilizes_with_margin(pendulum):
    params = PlantParameters.preset(pendulum)
    z = closed_loop_poles(demo_controller(pendulum), params, h=H, delay=1)
    assert len(z) == 3 + 1 + 3  # plant without x, delay, controller
    # every mode decays at least e-fold per second
    assert np.max(np.abs(z)) < np.exp(-1.0 * H)
    # and is reasonably damped (modes faster than 1000 rad/s are the sampling's own)
    s = continuous_equivalents(z[np.abs(z) > np.exp(-1000 * H)])
    assert np.min(-s.real / np.abs(s)) > 0.5
    # the independent python-control construction agrees (to the accuracy of its polynomials' roots near z = 1)
    ref = reference_loop_poles(demo_controller(pendulum), params, delay=1)
    assert np.isclose(np.max(np.abs(ref)), np.max(np.abs(z)), rtol=1e-5)


@pytest.mark.parametrize("pendulum", PENDULUMS)
@pytest.mark.parametrize("factor", [0.75, 1.0, 4.0])
def test_demo_tolerates_loop_gain_errors(pendulum, factor):
    demo = demo_controller(pendulum)
    scaled = Controller([Factor(demo.kernel.zeros, demo.kernel.poles, demo.kernel.gain * factor), *demo.compensators])
    z = closed_loop_poles(scaled, PlantParameters.preset(pendulum))
    assert np.max(np.abs(z)) < 1.0


@pytest.mark.parametrize("pendulum", PENDULUMS)
def test_unstable_example_is_unstable(pendulum):
    z = closed_loop_poles(unstable_example(pendulum), PlantParameters.preset(pendulum))
    assert np.max(np.abs(z)) > np.exp(10 * H)  # grows faster than e-fold per 0.1 s


@pytest.mark.parametrize("delay", [0, 1, 2])
def test_loop_poles_match_python_control(delay):
    c = Controller.from_zpk([-3.0], [5.0, -60.0], 30000.0)
    params = PlantParameters.preset("short")
    ours = np.sort_complex(closed_loop_poles(c, params, delay=delay))
    ref = np.sort_complex(reference_loop_poles(c, params, delay))
    assert len(ours) == len(ref)
    assert np.allclose(ours, ref, atol=1e-7)


@pytest.mark.parametrize("pendulum", PENDULUMS)
def test_demo_poke_response_is_a_damped_few_degree_swing(pendulum):
    params = PlantParameters.preset(pendulum)  # poke 50 rad/s^2 for 5 ms at 1 s
    r = poke_response(demo_controller(pendulum), params, stop_time=4.0)
    after = r["t"] >= params.poke_start
    alpha = r["alpha"]
    peak = np.max(np.abs(alpha))
    assert np.all(alpha[~after] == 0)
    assert np.radians(0.3) < peak < np.radians(5.0)
    outside = np.flatnonzero(np.abs(alpha) > max(0.02 * peak, 1e-3))
    settling = r["t"][outside[-1]] - params.poke_start
    assert settling < 2.5
    assert np.max(np.abs(r["V"])) < 4.0  # far from the 10 V saturation
    assert np.abs(r["x"][-1]) < 0.2  # the cart drifts, but stays on the track
    # the lab's bigger poke still does not saturate the amplifier
    big = poke_response(demo_controller(pendulum), params.with_values(poke_magnitude=220.0), stop_time=2.0)
    assert np.max(np.abs(big["V"])) < 10.0


def test_poke_response_shapes_and_sampled_plant():
    params = PlantParameters.preset("long")
    r = poke_response(demo_controller(), params, stop_time=0.5, delay=0)
    assert all(len(r[k]) == 500 for k in ("t", "x", "alpha", "V"))
    A, B, C, Bw = sampled_plant(params, H)
    assert A.shape == (3, 3) and B.shape == (3, 1) and C.shape == (1, 3) and Bw.shape == (3, 1)
    A4, *_ = sampled_plant(params, H, with_cart_position=True)
    assert A4.shape == (4, 4) and np.isclose(np.max(np.abs(np.linalg.eigvals(A4))), np.exp(4.84 * H), rtol=1e-3)


def simulate_nonlinear(controller: Controller, params: PlantParameters, stop_time: float) -> dict[str, np.ndarray]:
    """The CasADi plant (friction, quantization, saturation) with the discrete controller, one sample of delay."""
    model = PlantModel()
    lti = discretize(controller, h=H)
    p = np.asarray(params.as_vector())
    n_sub = substeps(H)
    # One CasADi call per sample: the plant's RK4 sub-steps chained.
    x_sym, v_sym, p_sym, t_sym = ca.MX.sym("x", 4), ca.MX.sym("V"), ca.MX.sym("p", len(p)), ca.MX.sym("t")
    x_next = x_sym
    for i in range(n_sub):
        x_next = model.rk4(x_next, v_sym, p_sym, t_sym + i * H / n_sub, H / n_sub)
    step = ca.Function("step", [x_sym, v_sym, p_sym, t_sym], [x_next])
    state, xc, V = np.zeros(4), np.zeros(lti.order), 0.0
    out: dict[str, list[float]] = {"t": [], "alpha": [], "x": [], "V": []}
    for k in range(int(round(stop_time / H))):
        t = k * H
        alpha_measured = float(model.outputs(state, V, p, t)[0])
        for key, value in (("t", t), ("alpha", state[2]), ("x", state[0]), ("V", V)):
            out[key].append(float(value))
        state = np.asarray(step(state, V, p, t)).ravel()
        e = -params.Lp * alpha_measured
        V = float(lti.C[0] @ xc + lti.D[0, 0] * e)  # applied from the next sample on
        xc = lti.A @ xc + lti.B[:, 0] * e
        if abs(state[2]) > 0.5:
            break
    return {k: np.asarray(v) for k, v in out.items()}


@pytest.mark.parametrize("pendulum", PENDULUMS)
def test_demo_balances_the_nonlinear_plant_with_friction_and_encoders(pendulum):
    params = PlantParameters.preset(pendulum)
    r = simulate_nonlinear(demo_controller(pendulum), params, stop_time=3.0)
    assert r["t"][-1] > 2.99  # did not fall
    assert np.max(np.abs(r["alpha"])) < np.radians(4.0)
    assert np.max(np.abs(r["V"])) < 8.0 and np.max(np.abs(r["x"])) < 0.3


def test_unstable_example_falls_soon_after_the_poke():
    params = PlantParameters.preset("long")
    r = simulate_nonlinear(unstable_example(), params, stop_time=2.0)
    over = np.flatnonzero(np.abs(r["alpha"]) > np.radians(15))
    assert over.size and r["t"][over[0]] - params.poke_start < 0.3
