"""Response metrics on synthetic poke responses with known answers."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from pendulab.analysis.metrics import METRIC_KEYS, compute_metrics
from pendulab.errors import UserError

POKE = 1.0
DT = 1e-3


def damped(wn: float, zeta: float, *, amplitude: float = 0.05, stop: float = 6.0, q: float = 0.0):
    """Impulse-like response ``A e^(-zeta wn tau) sin(wd tau)`` starting at the poke, optionally quantized."""
    t = np.arange(0.0, stop, DT)
    tau = np.clip(t - POKE, 0.0, None)
    wd = wn * math.sqrt(1 - zeta**2)
    alpha = amplitude * np.exp(-zeta * wn * tau) * np.sin(wd * tau)
    if q:
        alpha = quantize(alpha, q)
    return t, alpha, wd


def quantize(values: np.ndarray, q: float) -> np.ndarray:
    """Round half away from zero to multiples of q, like the plant's encoder."""
    return np.sign(values) * np.floor(np.abs(values) / q + 0.5) * q


def analytic_overshoot(zeta: float) -> float:
    return 100.0 * math.exp(-zeta * math.pi / math.sqrt(1 - zeta**2))


@pytest.mark.parametrize("wn, zeta", [(10.0, 0.1), (10.0, 0.3), (6.0, 0.5), (20.0, 0.05)])
def test_damped_sine_matches_second_order_formulas(wn, zeta):
    t, alpha, wd = damped(wn, zeta)
    m = compute_metrics(t, alpha, poke_start=POKE, q_alpha=0.0)
    assert set(m) == set(METRIC_KEYS)
    assert m["natural_frequency_rad_s"] == pytest.approx(wd, rel=0.01)
    assert m["overshoot_percent"] == pytest.approx(analytic_overshoot(zeta), rel=0.02)
    # Extrema of e^(-a t) sin(wd t) are at wd t = arccos(zeta).
    assert m["peak_time_s"] == pytest.approx(math.acos(zeta) / wd, abs=2 * DT)
    assert m["final_value_rad"] == pytest.approx(0.0, abs=1e-3 * 0.05)
    assert m["stable"] is True and m["safety_cut_time_s"] is None


@pytest.mark.parametrize("wn, zeta", [(10.0, 0.1), (6.0, 0.3)])
def test_settling_time_is_consistent_with_the_envelope(wn, zeta):
    t, alpha, wd = damped(wn, zeta, stop=8.0)
    m = compute_metrics(t, alpha, poke_start=POKE, q_alpha=0.0)
    sigma = zeta * wn
    first_peak = 0.05 * math.exp(-sigma * m["peak_time_s"]) * math.sin(wd * m["peak_time_s"])
    band = 0.02 * first_peak
    # The envelope A e^(-sigma t) enters the band at t_env; the signal itself enters it at its last
    # extremum beyond the band, which is at most half a period earlier.
    t_env = math.log(0.05 / band) / sigma
    assert t_env - math.pi / wd - 2 * DT <= m["settling_time_s"] <= t_env + 2 * DT
    # And the signal really stays inside the band after the settling time.
    after = t >= POKE + m["settling_time_s"] + DT
    assert np.max(np.abs(alpha[after])) <= band * 1.001


@pytest.mark.parametrize("q", [0.001, 2 * math.pi / 4096])
@pytest.mark.parametrize("wn, zeta", [(10.0, 0.1), (10.0, 0.3), (6.0, 0.5)])
def test_quantized_staircase_gives_sane_values(wn, zeta, q):
    t, exact, wd = damped(wn, zeta)
    alpha = quantize(exact, q)
    assert len(np.unique(alpha)) < 200  # really a staircase
    m = compute_metrics(t, alpha, poke_start=POKE, q_alpha=q)
    ref = compute_metrics(t, exact, poke_start=POKE, q_alpha=0.0)
    assert m["natural_frequency_rad_s"] == pytest.approx(wd, rel=0.03)
    assert m["peak_time_s"] == pytest.approx(ref["peak_time_s"], abs=0.01)
    # Overshoot within a couple of encoder steps of the first peak's size.
    peak = 0.05 * math.exp(-zeta * wn * ref["peak_time_s"]) * math.sin(wd * ref["peak_time_s"])
    assert m["overshoot_percent"] == pytest.approx(ref["overshoot_percent"], abs=100 * 2 * q / peak)
    assert abs(m["final_value_rad"]) <= q
    assert m["stable"] is True
    # The band is at least one step, so a quantized signal settles no later than the exact one.
    assert 0 < m["settling_time_s"] <= ref["settling_time_s"] + 0.01


def test_overdamped_response_has_no_overshoot_and_no_frequency():
    t = np.arange(0.0, 5.0, DT)
    tau = np.clip(t - POKE, 0.0, None)
    alpha = 0.05 * (np.exp(-3.0 * tau) - np.exp(-20.0 * tau))
    m = compute_metrics(t, alpha, poke_start=POKE)
    assert m["overshoot_percent"] == 0.0
    assert m["natural_frequency_rad_s"] is None
    assert m["peak_time_s"] == pytest.approx(math.log(20 / 3) / 17, abs=2 * DT)
    assert m["stable"] is True


def test_diverging_signal_with_a_safety_cut_is_unstable_and_reports_the_cut():
    t = np.arange(0.0, 4.0, DT)
    tau = np.clip(t - POKE, 0.0, None)
    alpha = 0.01 * np.sinh(4.0 * tau)
    cut = float(t[np.argmax(np.abs(alpha) > math.radians(15))])
    alpha = np.minimum(alpha, 1.7)  # fallen over after the cut
    xdot = np.where(t > POKE, 0.3 * tau, 0.0)
    m = compute_metrics(t, alpha, poke_start=POKE, xdot=xdot, safety_cut_time=cut)
    assert m["stable"] is False
    assert m["safety_cut_time_s"] == cut
    assert m["peak_time_s"] is None and m["settling_time_s"] is None and m["final_value_rad"] is None
    # The mean speed over the last second before the cut (here from the poke on: the cut is 0.99 s
    # after it), minus the speed before the poke (0): 0.3 * mean(tau) over [0, cut - poke].
    assert m["cart_speed_change_m_s"] == pytest.approx(0.3 * (cut - POKE) / 2, rel=1e-3)
    json.dumps(m, allow_nan=False)


def test_cut_oscillation_keeps_what_was_measured_before_the_cut():
    t, alpha, wd = damped(10.0, 0.1)
    cut = POKE + 1.5
    m = compute_metrics(t, alpha, poke_start=POKE, safety_cut_time=cut)
    assert m["stable"] is False and m["settling_time_s"] is None
    assert m["natural_frequency_rad_s"] == pytest.approx(wd, rel=0.01)


def test_flat_signal_gives_none_fields():
    t = np.arange(0.0, 3.0, DT)
    m = compute_metrics(t, np.full(t.size, 0.002), poke_start=POKE, xdot=np.zeros(t.size))
    for key in ("natural_frequency_rad_s", "peak_time_s", "overshoot_percent", "settling_time_s"):
        assert m[key] is None, key
    assert m["final_value_rad"] == pytest.approx(0.002)
    assert m["cart_speed_change_m_s"] == 0.0
    assert m["stable"] is True
    assert "NaN" not in json.dumps(m)


def test_sustained_oscillation_never_settles_but_is_stable():
    t = np.arange(0.0, 5.0, DT)
    alpha = 0.01 * np.sin(10.0 * np.clip(t - POKE, 0.0, None))
    m = compute_metrics(t, alpha, poke_start=POKE)
    assert m["natural_frequency_rad_s"] == pytest.approx(10.0, rel=1e-3)
    assert m["settling_time_s"] is None
    assert m["final_value_rad"] == pytest.approx(0.0, abs=2e-3)  # mean of the tail
    assert m["stable"] is True  # a limit cycle that does not grow: the pendulum stayed up


def test_growing_oscillation_is_not_stable():
    t = np.arange(0.0, 5.0, DT)
    tau = np.clip(t - POKE, 0.0, None)
    alpha = 0.005 * np.exp(0.5 * tau) * np.sin(10.0 * tau)
    m = compute_metrics(t, alpha, poke_start=POKE)
    assert m["stable"] is False


def test_negative_poke_and_offset_between_initial_and_final_value():
    t = np.arange(0.0, 5.0, DT)
    tau = np.clip(t - POKE, 0.0, None)
    # Resting 3 mrad off before the poke, then a negative swing that decays to 0.
    alpha = 0.003 * (t < POKE) - 0.04 * np.exp(-3.0 * tau) * np.sin(9.0 * tau)
    m = compute_metrics(t, alpha, poke_start=POKE, q_alpha=0.0)
    assert m["peak_time_s"] == pytest.approx(math.atan(3.0) / 9.0, abs=2 * DT)
    assert m["overshoot_percent"] == pytest.approx(100 * math.exp(-3.0 * math.pi / 9.0), rel=0.02)


def test_non_finite_samples_make_the_run_unbounded():
    t, alpha, _ = damped(10.0, 0.3)
    alpha[4000:] = np.nan
    m = compute_metrics(t, alpha, poke_start=POKE)
    assert m["stable"] is False and m["final_value_rad"] is None
    assert "NaN" not in json.dumps(m)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(t=[0.0, 1.0, 2.0], alpha=[0.0, 0.0]), "samples"),
        (dict(t=[0.0, 2.0, 1.0, 3.0], alpha=[0.0] * 4), "increasing"),
        (dict(t=np.arange(10.0), alpha=np.zeros(10), poke_start=20.0), "outside the record"),
        (dict(t=np.arange(10.0), alpha=np.zeros(10), q_alpha=-1.0), "q_alpha"),
        (dict(t=np.arange(10.0), alpha=["a"] * 10), "numeric"),
    ],
)
def test_bad_input_is_a_one_line_user_error(kwargs, match):
    kwargs.setdefault("poke_start", 1.0)
    with pytest.raises(UserError, match=match) as info:
        compute_metrics(**kwargs)
    assert "\n" not in str(info.value)


def test_small_first_bump_before_a_larger_swing_and_a_wandering_end():
    # Like the rig with stick-slip friction: a small bump from the poke, a larger swing back while
    # the cart moves, then a wander about an offset that never settles within one encoder step.
    t = np.arange(0.0, 5.0, DT)
    tau = t - POKE
    alpha = np.where((tau >= 0) & (tau < 0.14), 0.0123 * np.sin(np.pi * tau / 0.14), 0.0)
    alpha = np.where((tau >= 0.14) & (tau < 0.64), -0.0155 * np.sin(np.pi * (tau - 0.14) / 0.5), alpha)
    alpha = np.where(tau >= 0.64, -0.004 + 0.012 * np.sin(4.0 * (tau - 0.64)), alpha)
    for signal, q in ((alpha, 0.0), (quantize(alpha, 0.001), 0.001)):
        m = compute_metrics(t, signal, poke_start=POKE, q_alpha=q)
        assert m["peak_time_s"] == pytest.approx(0.07, abs=0.003)
        assert m["settling_time_s"] is None
        assert m["final_value_rad"] == pytest.approx(-0.004, abs=3e-3)
        assert m["stable"] is True  # wanders within twice the first peak: stayed up, not growing
        assert m["overshoot_percent"] > 50  # the swing back is larger than the bump
