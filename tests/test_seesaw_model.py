"""The seesaw's CasADi model against independent references (issue 20, must-show 1).

- an independent derivation of the equations of motion: Lagrange's equations in sympy, from the
  kinetic and potential energy of the cart (a point mass on the track, D_T above the pivot) and the
  seesaw (mass M_sw with its centre of gravity D_C above the pivot, inertia J_sw about it);
- Quanser's linear model, ``SEESAW_ABCD_eqns.m`` of the 2012 courseware, transcribed below;
- Quanser's LQR gain for Q = diag(1000, 5000, 0, 0, 2000), R = 0.5, printed in the SEESAW Laboratory
  Guide (2012), section 3.1.1: K = [180.797, -224.3485, 16.6684, -66.9969, -63.2456].
"""

from __future__ import annotations

import math

import control
import numpy as np
import pytest
import sympy as sp

from pendulab.errors import ParameterError
from pendulab.model.seesaw import SEESAW_COUNT, SeesawModel, SeesawParameters, linearize_seesaw


def _lagrange_accelerations(p: SeesawParameters):
    """xddot, thetaddot as sympy-lambdified functions of (x, xdot, theta, thetadot, F_net)."""
    t = sp.symbols("t")
    x, th = sp.Function("x")(t), sp.Function("theta")(t)
    F = sp.symbols("F")
    mc, Dt, Dc, Msw, Jsw, g, Bsw = (sp.nsimplify(v) for v in (p.M_cart, p.D_T, p.D_C, p.M_sw, p.J_sw, p.g, p.B_sw))
    J_rotor = sp.nsimplify(p.rotor_inertia * p.eta_g * p.Kg**2 * p.Jm / p.r_mp**2)
    # The cart's position in the world: rotate (x, D_T) by theta about the pivot.
    cart = sp.Matrix([x * sp.cos(th) - Dt * sp.sin(th), x * sp.sin(th) + Dt * sp.cos(th)])
    v = cart.diff(t)
    T = mc * (v.T * v)[0] / 2 + Jsw * th.diff(t) ** 2 / 2 + J_rotor * x.diff(t) ** 2 / 2
    V = mc * g * cart[1] + Msw * g * Dc * sp.cos(th)
    L = T - V
    # Generalized forces: the motor's net force acts along the track (between cart and seesaw).
    forces = {x: F, th: -Bsw * th.diff(t)}
    eqs = [sp.diff(L.diff(q.diff(t)), t) - L.diff(q) - forces[q] for q in (x, th)]
    xdd, thdd = sp.symbols("xdd thdd")
    X, Xd, TH, THd = sp.symbols("X Xd TH THd")
    subs = {x.diff(t, 2): xdd, th.diff(t, 2): thdd}
    eqs = [e.subs(subs) for e in eqs]
    subs = {x.diff(t): Xd, th.diff(t): THd}
    eqs = [e.subs(subs).subs({x: X, th: TH}) for e in eqs]
    solution = sp.solve(eqs, [xdd, thdd], dict=True)[0]
    return sp.lambdify((X, Xd, TH, THd, F), [solution[xdd], solution[thdd]], "math")


@pytest.mark.parametrize("rotor_inertia", [0.0, 1.0])
def test_the_casadi_equations_equal_an_independent_lagrange_derivation(rotor_inertia: float) -> None:
    # Friction and the amplifier's limits off, no stops within reach: the mechanics alone, with the
    # motor's force (and Beq) computed from the state exactly as SPEC §2 writes it.
    p = SeesawParameters(rotor_inertia=rotor_inertia, B_sw=0.01).with_values(
        F1=0.0, F2=0.0, tap_magnitude=0.0, theta_stop=3.0, track_half_length=10.0
    )
    accelerations = _lagrange_accelerations(p)
    ode = SeesawModel().ode
    rng = np.random.default_rng(20)
    for _ in range(25):
        x, xdot, theta, thetadot = rng.uniform([-0.4, -1, -0.2, -2], [0.4, 1, 0.2, 2])
        V = rng.uniform(-8, 8)
        F_motor = p.force_gain * p.eta_g * p.Kg * p.eta_m * p.Kt * (V - p.Km * p.Kg * xdot / p.r_mp) / (p.Rm * p.r_mp)
        expected = accelerations(x, xdot, theta, thetadot, F_motor - p.Beq * xdot)
        got = np.asarray(ode([x, xdot, theta, thetadot], V, p.as_vector(), 0.0)).ravel()
        assert got[0] == pytest.approx(xdot, abs=0) and got[2] == pytest.approx(thetadot, abs=0)
        assert got[1] == pytest.approx(float(expected[0]), rel=1e-12, abs=1e-12)
        assert got[3] == pytest.approx(float(expected[1]), rel=1e-12, abs=1e-12)


def _courseware_ab(p: SeesawParameters) -> tuple[np.ndarray, np.ndarray]:
    """``SEESAW_ABCD_eqns.m``, state order [xc, theta, xc_dot, theta_dot], as the courseware writes it."""
    mc, Dt, g, Jsw, msw, Dc, Beq, Bsw = p.M_cart, p.D_T, p.g, p.J_sw, p.M_sw, p.D_C, p.Beq, p.B_sw
    A = np.array([
        [0, 0, 1, 0],
        [0, 0, 0, 1],
        [-mc * Dt * g / Jsw, (-g * mc * Jsw + mc * Dt * g * msw * Dc) / mc / Jsw, (-mc * Dt**2 * Beq - Beq * Jsw) / mc / Jsw, -Dt * Bsw / Jsw],
        [-g * mc / Jsw, g * msw * Dc / Jsw, -Dt * Beq / Jsw, -Bsw / Jsw],
    ])
    B = np.array([[0], [0], [(Jsw + mc * Dt**2) / mc / Jsw], [Dt / Jsw]])
    emf = p.eta_g * p.Kg**2 * p.eta_m * p.Kt * p.Km / p.r_mp**2 / p.Rm
    A[2, 2] -= B[2, 0] * emf
    A[3, 2] -= B[3, 0] * emf
    return A, p.eta_g * p.Kg * p.eta_m * p.Kt / p.r_mp / p.Rm * B


QUANSER_ORDER = [0, 2, 1, 3]  # ours [x, xdot, theta, thetadot] -> Quanser's [x, theta, xdot, thetadot]


def test_the_linear_model_is_the_courseware_s_a_and_b() -> None:
    p = SeesawParameters()
    lin = linearize_seesaw(p)
    A = lin.ss.A[np.ix_(QUANSER_ORDER, QUANSER_ORDER)]
    B = lin.ss.B[QUANSER_ORDER]
    A_ref, B_ref = _courseware_ab(p)
    np.testing.assert_allclose(A, A_ref, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(B, B_ref, rtol=1e-10, atol=1e-12)
    # With the rotor inertia lumped in, the model departs from Quanser's (a heavier cart along the track).
    lumped = linearize_seesaw(p.with_values(rotor_inertia=1.0)).ss.B[QUANSER_ORDER]
    assert lumped[2, 0] < 0.9 * B_ref[2, 0]


def test_quanser_s_lqr_gain_is_reproduced() -> None:
    lin = linearize_seesaw()
    A = np.zeros((5, 5))
    A[:4, :4] = lin.ss.A[np.ix_(QUANSER_ORDER, QUANSER_ORDER)]
    A[4, 1] = 1.0  # the integral of the tilt
    B = np.vstack([lin.ss.B[QUANSER_ORDER], [[0.0]]])
    K, _, poles = control.lqr(A, B, np.diag([1000, 5000, 0, 0, 2000]), 0.5)
    published = [180.797, -224.3485, 16.6684, -66.9969, -63.2456]
    np.testing.assert_allclose(np.ravel(K), published, rtol=2e-5)
    assert np.all(np.real(poles) < 0)


def test_the_seesaw_alone_falls_toward_the_cart_and_stops_at_its_tilt_stop() -> None:
    p = SeesawParameters().with_values(F1=0.0, F2=0.0, tap_magnitude=0.0)
    states = SeesawModel().simulate(p, np.zeros(3000), x0=(0.05, 0.0, 0.0, 0.0))
    theta = states[:, 2]
    assert theta[200] < 0  # the cart on the +x side takes that side down (theta < 0)
    assert theta.min() == pytest.approx(-p.theta_stop, abs=1e-12)
    assert np.all(np.abs(theta) <= p.theta_stop + 1e-12)


def test_the_tilt_encoder_counts_a_4096_line_quadrature_encoder_behind_a_3_to_1_gear() -> None:
    assert SEESAW_COUNT == pytest.approx(5.113e-4, rel=1e-3)
    out = SeesawModel().outputs([0.0, 0.0, 2.6 * SEESAW_COUNT, 0.0], 0.0, SeesawParameters().as_vector(), 0.0)
    assert float(out[0]) == pytest.approx(3 * SEESAW_COUNT, rel=1e-12)


@pytest.mark.parametrize("bad", [{"J_sw": 0.0}, {"M_sw": -1.0}, {"rotor_inertia": 0.5}, {"D_T": math.nan}])
def test_bad_seesaw_parameters_are_refused_with_the_name(bad: dict[str, float]) -> None:
    with pytest.raises(ParameterError, match=next(iter(bad))):
        SeesawParameters(**bad)


def test_the_seesaw_modules_examples_run() -> None:
    import doctest

    from pendulab.control import state_feedback
    from pendulab.model import seesaw

    for module in (seesaw, state_feedback):
        result = doctest.testmod(module)
        assert result.attempted > 0 and result.failed == 0


@pytest.mark.parametrize("method", ["tustin", "zoh"])
def test_quanser_s_controller_realized_with_its_filters_stabilizes_the_sampled_seesaw(method: str) -> None:
    from scipy.signal import cont2discrete

    from pendulab.control.state_feedback import design_state_feedback, realize_state_feedback

    h = 1e-3
    design = design_state_feedback("seesaw")
    block = realize_state_feedback(design, h, method)
    lin = linearize_seesaw().ss
    measured = np.array([[0, 0, 1, 0], [1, 0, 0, 0]])  # the controller's inputs: [theta, x]
    Ap, Bp, _, _, _ = cont2discrete((lin.A, lin.B, measured, np.zeros((2, 1))), h, "zoh")
    closed = np.block([[Ap + Bp @ block.D @ measured, Bp @ block.C], [block.B @ measured, block.A]])
    radii = np.sort(np.abs(np.linalg.eigvals(closed)))
    assert radii[-1] < 1
    # The slowest closed-loop pole is the ideal state feedback's slowest (the filters are 10x faster).
    slowest = min(abs(p.real) for p in design.closed_loop_poles)
    assert -np.log(radii[-1]) / h == pytest.approx(slowest, rel=0.05)


def test_the_derivative_filter_estimates_a_ramp_s_slope() -> None:
    from pendulab.control.state_feedback import design_state_feedback, realize_state_feedback

    design = design_state_feedback("seesaw", integral=False, q=(1, 1, 0, 0))
    block = realize_state_feedback(design.__class__(design.plant, design.states, np.array([0.0, 0.0, 1.0, 0.0]), design.closed_loop_poles, design.q, design.r))
    z = np.zeros(block.order)
    for k in range(1000):  # the cart moves at 0.2 m/s for 1 s
        u = np.array([0.0, 0.2 * k * block.h])
        V = (block.C @ z + block.D @ u).item()
        z = block.A @ z + block.B @ u
    assert -V == pytest.approx(0.2, rel=1e-3)  # V = -K_xdot * xdot_estimate
