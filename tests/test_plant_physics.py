"""Physics of Plant.fmu against answers derived by hand (issue 2, must-show 5; SPEC §2).

All runs are co-simulations of the FMU itself (10 ms communication steps, each split into RK4
sub-steps of 0.1 ms), so these tests check the compiled plant, not only the CasADi expressions.
The poke is switched off unless a test is about it.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Mapping

import fmi_harness
import numpy as np
import pytest

from pendulab.model.parameters import PlantParameters

SIGNALS = ("x", "xdot", "alpha", "alphadot", "alpha_measured", "x_measured", "V_applied", "F_friction")
UNDISTURBED = {"poke_magnitude": 0.0, "track_half_length": 1e4}  # no poke, and no end stop within reach
FRICTION_OFF = {"F1": 0.0, "F2": 0.0}


def simulate(unzipdir: Path, params: PlantParameters, V: float, stop: float, step: float = 0.01,
             start: Mapping[str, float] | None = None) -> dict[str, np.ndarray]:
    """Co-simulate Plant.fmu with ``params`` (all of them set), a constant ``V`` and initial ``start`` states."""
    n = int(round(stop / step))
    data = fmi_harness.run_cs(unzipdir, SIGNALS, n_steps=n, step=step, start={**params.as_dict(), **(start or {}), "V": V})
    return {"t": np.arange(n + 1) * step, **{s: data[:, i] for i, s in enumerate(SIGNALS)}}


def motor_force_per_volt(p: PlantParameters) -> float:
    """``F_motor = k (V - Km Kg xdot / r_mp)`` with ``k = force_gain eta_g Kg eta_m Kt / (Rm r_mp)`` (SPEC §2)."""
    return p.force_gain * p.eta_g * p.Kg * p.eta_m * p.Kt / (p.Rm * p.r_mp)


def period(t: np.ndarray, signal: np.ndarray) -> float:
    """Mean period from the upward zero crossings (linear interpolation between samples)."""
    up = np.nonzero((signal[:-1] < 0) & (signal[1:] >= 0))[0]
    crossings = t[up] - signal[up] * (t[up + 1] - t[up]) / (signal[up + 1] - signal[up])
    assert len(crossings) >= 4, "too few swings to measure a period"
    return float(np.mean(np.diff(crossings)))


# ---------------------------------------------------------------- small swings of the hanging pendulum
def test_small_swings_with_a_free_cart(plant_unzipdir: Path) -> None:
    """A frictionless free cart (Beq = 0, no back-EMF, no friction, no pivot damping).

    Linearizing SPEC §2 about alpha = pi + theta (sin ~ -theta, cos ~ -1) with F = 0 and the quadratic
    term dropped gives ``theta'' = -(Mc+Mp) Mp g lp / D0 * theta``, ``D0 = (Mc+Mp) Ip + Mc Mp lp^2``:
    ``w^2 = Mp g lp (Mc+Mp) / ((Mc+Mp) Ip + Mc Mp lp^2)``. The cart swings against the pendulum, so the
    period is shorter than with a fixed pivot. (Amplitude correction for 0.05 rad: ~1.6e-4, negligible.)
    """
    p = PlantParameters.preset("long", Beq=0.0, Km=0.0, Bp=0.0, **FRICTION_OFF, **UNDISTURBED)
    Mc, Mp, lp, Ip = p.lumped_cart_mass, p.Mp, p.lp, p.Ip
    w = math.sqrt(Mp * p.g * lp * (Mc + Mp) / ((Mc + Mp) * Ip + Mc * Mp * lp**2))
    run = simulate(plant_unzipdir, p, 0.0, stop=8.0, start={"alpha": math.pi + 0.05})
    measured = period(run["t"], run["alpha"] - math.pi)
    assert measured == pytest.approx(2 * math.pi / w, rel=0.01)
    # Horizontal momentum is conserved: the centre of mass stays put, so the cart moves opposite the bob.
    centre = (Mc + Mp) * run["x"] - Mp * lp * np.sin(run["alpha"])  # x_cm * (Mc+Mp), with the bob at x - lp sin(alpha)
    assert np.ptp(centre) < 1e-6
    assert np.ptp(run["x"]) > 1e-3


def test_small_swings_with_a_held_cart(plant_unzipdir: Path) -> None:
    """Cart held by a huge viscous damping (Beq = 1000 N s/m; sub-step stable since h Beq / Mc ~ 0.14).

    The cart barely moves, so the pendulum swings about a fixed pivot: ``w^2 = Mp g lp / (Ip + Mp lp^2)``.
    (The stick-slip friction does not hold the cart: it only cancels the motor force, not the pendulum's
    reaction, so it is not used for this check.)
    """
    p = PlantParameters.preset("long", Beq=1000.0, Bp=0.0, **FRICTION_OFF, **UNDISTURBED)
    w = math.sqrt(p.Mp * p.g * p.lp / (p.Ip + p.Mp * p.lp**2))
    run = simulate(plant_unzipdir, p, 0.0, stop=8.0, start={"alpha": math.pi + 0.05})
    assert period(run["t"], run["alpha"] - math.pi) == pytest.approx(2 * math.pi / w, rel=0.01)
    assert np.max(np.abs(run["x"])) < 1e-4


def test_free_swing_decay_from_pivot_damping(plant_unzipdir: Path) -> None:
    """With pivot damping Bp the free-cart swing decays as exp(-s t), ``s = (Mc+Mp) Bp / (2 D0)``."""
    p = PlantParameters.preset("long", Beq=0.0, Km=0.0, Bp=0.01, **FRICTION_OFF, **UNDISTURBED)
    Mc = p.lumped_cart_mass
    D0 = (Mc + p.Mp) * p.Ip + Mc * p.Mp * p.lp**2
    sigma = (Mc + p.Mp) * p.Bp / (2 * D0)
    run = simulate(plant_unzipdir, p, 0.0, stop=10.0, start={"alpha": math.pi + 0.05})
    theta = run["alpha"] - math.pi
    # Envelope: the swing's peaks in the first and last two seconds.
    early = np.max(np.abs(theta[run["t"] < 2.0]))
    late_mask = run["t"] > 8.0
    late = np.max(np.abs(theta[late_mask]))
    t_early = run["t"][np.argmax(np.abs(theta) * (run["t"] < 2.0))]
    t_late = run["t"][late_mask][np.argmax(np.abs(theta[late_mask]))]
    assert math.log(early / late) / (t_late - t_early) == pytest.approx(sigma, rel=0.02)


def test_lab_cart_swing_lies_between_free_and_held(plant_unzipdir: Path) -> None:
    """With the lab's Beq, back-EMF and friction the cart is neither free nor held: the period is in between."""
    p = PlantParameters.preset("long", **UNDISTURBED)
    Mc, Mp, lp, Ip = p.lumped_cart_mass, p.Mp, p.lp, p.Ip
    free = 2 * math.pi / math.sqrt(Mp * p.g * lp * (Mc + Mp) / ((Mc + Mp) * Ip + Mc * Mp * lp**2))
    held = 2 * math.pi / math.sqrt(Mp * p.g * lp / (Ip + Mp * lp**2))
    run = simulate(plant_unzipdir, p, 0.0, stop=8.0, start={"alpha": math.pi + 0.05})
    assert free < period(run["t"], run["alpha"] - math.pi) < held * 1.001


# ---------------------------------------------------------------- stick-slip friction
def breakaway_voltage(p: PlantParameters) -> float:
    """At rest the motor force is k V; the cart sticks while it is below F1."""
    return p.F1 / motor_force_per_volt(p)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_cart_sticks_below_the_breakaway_force_and_moves_above(plant_unzipdir: Path, sign: float) -> None:
    """Just above breakaway the cart creeps: as it speeds up, the back-EMF lowers the motor force until it
    falls back to F1 and the cart re-sticks, so it crawls at ``v* = (k V - F1) / (k Km Kg / r_mp)`` (< v1)."""
    p = PlantParameters.preset("long", **UNDISTURBED)
    k = motor_force_per_volt(p)
    V_break = breakaway_voltage(p)  # 0.869 V for the lab's F1 = 1.5 N
    below = simulate(plant_unzipdir, p, sign * 0.98 * V_break, stop=1.0, start={"alpha": math.pi})
    assert np.max(np.abs(below["x"])) < 1e-9, "the cart must not creep below the breakaway force"
    np.testing.assert_allclose(below["F_friction"][1:], -sign * 0.98 * V_break * k, rtol=1e-12)
    V = sign * 1.02 * V_break
    above = simulate(plant_unzipdir, p, V, stop=1.0, start={"alpha": math.pi})
    assert sign * above["x"][-1] > 1e-3, "above the breakaway force the cart moves, in the direction of V"
    creep = (k * abs(V) - p.F1) / (k * p.Km * p.Kg / p.r_mp)
    assert creep < p.v1
    half = above["t"] >= 0.5
    mean_speed = np.polyfit(above["t"][half], above["x"][half], 1)[0]
    assert sign * mean_speed == pytest.approx(creep, rel=0.05)
    # Well above breakaway (and above F2) the cart runs off at speed.
    assert sign * simulate(plant_unzipdir, p, 2 * V, stop=1.0, start={"alpha": math.pi})["x"][-1] > 0.2


def test_breakaway_follows_the_friction_vector(plant_unzipdir: Path) -> None:
    """Raising F1 raises the breakaway voltage in proportion."""
    p = PlantParameters.preset("none", F1=2.5, F2=4.0, **UNDISTURBED)
    V_break = breakaway_voltage(p)
    assert simulate(plant_unzipdir, p, 0.98 * V_break, stop=0.5)["x"][-1] == 0.0
    assert simulate(plant_unzipdir, p, 1.02 * V_break, stop=0.5)["x"][-1] > 0.005


def test_slip_region_drags_with_B(plant_unzipdir: Path) -> None:
    """Between F1 and F2 at low speed the drag is -B xdot: the cart creeps at k V / (B + Beq + k Km Kg / r_mp)."""
    p = PlantParameters.preset("none", F1=0.5, v1=1e-4, F2=3.0, v2=0.5, B=20.0, **UNDISTURBED)
    k = motor_force_per_volt(p)
    V = 1.0  # k V = 1.73 N: between F1 and F2
    creep = k * V / (p.B + p.Beq + k * p.Km * p.Kg / p.r_mp)  # 0.054 m/s < v2
    run = simulate(plant_unzipdir, p, V, stop=1.0)
    assert run["xdot"][-1] == pytest.approx(creep, rel=1e-3)
    assert run["F_friction"][-1] == pytest.approx(-p.B * creep, rel=1e-3)


# ---------------------------------------------------------------- amplifier and motor
def test_voltage_saturation(plant_unzipdir: Path) -> None:
    p = PlantParameters.preset("long", **UNDISTURBED)
    start = {"alpha": math.pi + 0.1}
    for command, limit in ((100.0, 10.0), (-100.0, -10.0)):
        big = simulate(plant_unzipdir, p, command, stop=0.5, start=start)
        capped = simulate(plant_unzipdir, p, limit, stop=0.5, start=start)
        for s in ("x", "xdot", "alpha", "alphadot"):
            np.testing.assert_array_equal(big[s], capped[s])
        assert np.all(big["V_applied"] == limit)
    below = simulate(plant_unzipdir, p, 9.9, stop=0.5, start=start)
    full = simulate(plant_unzipdir, p, 10.0, stop=0.5, start=start)
    assert np.all(below["V_applied"] == 9.9), "no saturation below V_max"
    assert 0 < below["x"][-1] < full["x"][-1]
    lowered = p.with_values(V_max=5.0)
    np.testing.assert_array_equal(
        simulate(plant_unzipdir, lowered, 7.0, stop=0.3)["x"], simulate(plant_unzipdir, lowered, 5.0, stop=0.3)["x"]
    )


@pytest.mark.parametrize(
    "overrides",
    [{}, {"force_gain": 0.8, "eta_g": 0.9, "eta_m": 0.85}, {"Beq": 0.9, "M_cart": 0.52}],
    ids=["ip02", "calibrated-gains", "ip01-like"],
)
def test_back_emf_terminal_speed_and_time_constant(plant_unzipdir: Path, overrides: dict) -> None:
    """Cart alone (Mp = 0), friction off, V = 5 V.

    ``Mc v' = k (V - Km Kg v / r_mp) - Beq v`` with ``k = force_gain eta_g Kg eta_m Kt / (Rm r_mp)``:
    ``v_terminal = F_stall / (Beq + force_gain eta_g eta_m Kt Km Kg^2 / (Rm r_mp^2))``, ``F_stall = k V``,
    reached with the time constant ``Mc / (Beq + ...)`` where Mc includes the rotor inertia.
    """
    p = PlantParameters.preset("none", **FRICTION_OFF, **UNDISTURBED, **overrides)
    V = 5.0
    damping = p.Beq + p.force_gain * p.eta_g * p.eta_m * p.Kt * p.Km * p.Kg**2 / (p.Rm * p.r_mp**2)
    v_terminal = motor_force_per_volt(p) * V / damping
    tau = p.lumped_cart_mass / damping
    run = simulate(plant_unzipdir, p, V, stop=30 * tau, step=tau / 50)
    assert run["xdot"][-1] == pytest.approx(v_terminal, rel=0.005)
    assert run["xdot"][50] == pytest.approx(v_terminal * (1 - math.exp(-1)), rel=0.005)
    # With the pendulum hanging still, the same cart reaches the same speed (the bob rides along).
    hanging = simulate(plant_unzipdir, PlantParameters.preset("long", **FRICTION_OFF, **UNDISTURBED, **overrides), V,
                       stop=30 * tau + 20, step=0.05, start={"alpha": math.pi})
    assert hanging["xdot"][-1] == pytest.approx(v_terminal, rel=0.005)


def test_terminal_speed_with_the_lab_friction(plant_unzipdir: Path) -> None:
    """At 5 V the cart runs faster than v2 and pushes harder than F2, so friction is zero and the speed is as without it."""
    p = PlantParameters.preset("none", **UNDISTURBED)
    damping = p.Beq + p.eta_g * p.eta_m * p.Kt * p.Km * p.Kg**2 / (p.Rm * p.r_mp**2)
    run = simulate(plant_unzipdir, p, 5.0, stop=1.5)
    assert run["xdot"][-1] == pytest.approx(motor_force_per_volt(p) * 5.0 / damping, rel=0.005)
    assert run["F_friction"][-1] == 0.0


def test_current_limit_caps_the_force(plant_unzipdir: Path) -> None:
    """I_max = 1 A, V = 10 V: the current stays clamped (10 V minus the back-EMF still exceeds Rm I_max),
    so the force is ``F_max = force_gain eta_g Kg eta_m Kt I_max / r_mp`` and the terminal speed F_max / Beq."""
    p = PlantParameters.preset("none", I_max=1.0, **FRICTION_OFF, **UNDISTURBED)
    F_max = p.force_gain * p.eta_g * p.Kg * p.eta_m * p.Kt * p.I_max / p.r_mp
    v = F_max / p.Beq
    assert (10.0 - p.Km * p.Kg * v / p.r_mp) / p.Rm > p.I_max, "the clamp is active at terminal speed"
    limited = simulate(plant_unzipdir, p, 10.0, stop=2.0)
    assert limited["xdot"][-1] == pytest.approx(v, rel=0.005)
    # Initial acceleration F_max / Mc over the first 1 ms (the speed is still tiny there).
    first = simulate(plant_unzipdir, p, 10.0, stop=0.001, step=0.001)
    assert first["xdot"][1] / 0.001 == pytest.approx(F_max / p.lumped_cart_mass, rel=0.01)
    # A limit the motor never reaches changes nothing; no limit is faster.
    loose = simulate(plant_unzipdir, p.with_values(I_max=100.0), 10.0, stop=2.0)
    free = simulate(plant_unzipdir, p.with_values(I_max=0.0), 10.0, stop=2.0)
    np.testing.assert_array_equal(loose["xdot"], free["xdot"])
    assert free["xdot"][-1] > 1.3 * limited["xdot"][-1]


# ---------------------------------------------------------------- encoders
def _initial_outputs(unzipdir: Path, params: PlantParameters, x: float, alpha: float) -> dict[str, float]:
    run = simulate(unzipdir, params, 0.0, stop=0.0, start={"x": x, "alpha": alpha})
    return {s: float(run[s][0]) for s in SIGNALS}


def test_quantization_rounds_half_away_from_zero(plant_unzipdir: Path) -> None:
    q = 2.0**-10  # a power of two: the half steps are exact in binary
    p = PlantParameters.preset("long", q_alpha=q, q_x=q / 4)
    for counts, expected in ((2.5, 3), (-2.5, -3), (2.4999, 2), (-0.5, -1), (0.49, 0), (7.0, 7)):
        out = _initial_outputs(plant_unzipdir, p, x=counts * q / 4, alpha=counts * q)
        assert out["alpha_measured"] == expected * q, (counts, out["alpha_measured"] / q)
        assert out["x_measured"] == expected * q / 4


def test_quantization_off_reads_the_true_values(plant_unzipdir: Path) -> None:
    p = PlantParameters.preset("long", q_alpha=0.0, q_x=0.0, **UNDISTURBED)
    run = simulate(plant_unzipdir, p, 3.0, stop=1.0, step=0.001, start={"alpha": math.pi + 0.3})
    np.testing.assert_array_equal(run["alpha_measured"], run["alpha"])
    np.testing.assert_array_equal(run["x_measured"], run["x"])


@pytest.mark.parametrize("q_alpha, q_x", [(0.001, 22.75e-6), (2 * math.pi / 4096, 1e-4)], ids=["spec-default", "ip02-encoder"])
def test_quantized_outputs_are_exact_multiples_of_the_steps(plant_unzipdir: Path, q_alpha: float, q_x: float) -> None:
    p = PlantParameters.preset("long", q_alpha=q_alpha, q_x=q_x)
    run = simulate(plant_unzipdir, p, 3.0, stop=2.0, step=0.001, start={"alpha": math.pi + 0.3})
    for measured, true, q in ((run["alpha_measured"], run["alpha"], q_alpha), (run["x_measured"], run["x"], q_x)):
        counts = np.round(measured / q)
        np.testing.assert_array_equal(measured, counts * q)  # bit-exact multiples of the step
        np.testing.assert_array_equal(counts, np.sign(true) * np.floor(np.abs(true) / q + 0.5))
        assert np.all(np.abs(measured - true) <= q / 2 * (1 + 1e-12))
        assert len(np.unique(counts)) > 20, "the signal moved through many steps"
