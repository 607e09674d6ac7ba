"""What a student reads off the old lab's runs: metrics of runs cut by the supervisor, the limit cycle.

The three reference runs of the old lab (SPEC §4 PIDs on the long pendulum, a 220 rad/s^2, 5 ms poke
at 1 s) settle after the poke, then drift into the track limit and are cut. Their metrics are checked
against an independent reading of the same run.mat (the extremes and the crossings, read directly).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import scipy.io

from pendulab.analysis.metrics import compute_metrics
from pendulab.cli.main import main

OLD_LAB_PIDS = ["600,200,5", "750,6,10", "1200,20,20"]
POKE = 1.0


def simulate(capsys, out, *args):
    status = main(["simulate", *args, "--out", str(out)])
    captured = capsys.readouterr()
    assert status == 0, captured.err
    metrics = json.loads((out / "metrics.json").read_text())
    run = scipy.io.loadmat(out / "run.mat", squeeze_me=True)
    return metrics, run, captured.out


@pytest.mark.parametrize("pid", OLD_LAB_PIDS)
def test_old_lab_runs_cut_by_the_supervisor_give_their_response_metrics(capsys, tmp_path, pid, loop_fmus):
    m, run, summary = simulate(capsys, tmp_path / "run", "--pid", pid, "--poke", "220,0.005,1")
    cut = m["safety_cut_time_s"]
    assert cut is not None and m["stable"] is False
    for key in ("natural_frequency_rad_s", "peak_time_s", "overshoot_percent", "final_value_rad", "settling_time_s"):
        assert m[key] is not None, key
    # Independent reading of the angle between the poke and the cut.
    t, alpha = run["t"], run["alpha"]
    w = (t >= POKE) & (t <= cut)
    tw, aw = t[w], alpha[w]
    i_peak = int(np.argmax(aw))
    assert m["peak_time_s"] == pytest.approx(tw[i_peak] - POKE, abs=2e-3)
    final = float(np.mean(aw[tw > cut - 0.1]))  # it had settled well before the cut
    assert m["final_value_rad"] == pytest.approx(final, abs=5e-4)
    i_trough = i_peak + int(np.argmin(aw[i_peak:]))
    overshoot = 100 * (final - aw[i_trough]) / (aw[i_peak] - final)
    assert m["overshoot_percent"] == pytest.approx(overshoot, abs=3.0)
    # Half a period from the peak to the trough: the damped frequency within 15 %.
    assert m["natural_frequency_rad_s"] == pytest.approx(math.pi / (tw[i_trough] - tw[i_peak]), rel=0.15)
    assert 0 < m["settling_time_s"] < cut - POKE
    assert summary.startswith(f"CUT at t = {cut:.3f} s: the cart reached the track limit") and "n/a" not in summary.split("natural frequency")[1].split("cart speed")[0]


def test_demo_summary_names_its_limit_cycle(capsys, tmp_path, loop_fmus):
    m, run, summary = simulate(capsys, tmp_path / "demo", "--demo")
    assert m["stable"] is True
    amplitude, frequency = m["limit_cycle_amplitude_rad"], m["limit_cycle_frequency_rad_s"]
    assert amplitude is not None and frequency is not None
    # Independent reading of the last 2 s: half the peak-to-peak, and the mean-crossing rate.
    t, alpha = run["t"], run["alpha"]
    tail = alpha[t >= t[-1] - 2.0]
    assert amplitude == pytest.approx(0.5 * np.ptp(tail), rel=0.15)
    dev = tail - tail.mean()
    crossings = np.flatnonzero(np.diff(np.signbit(dev)))
    tt = t[t >= t[-1] - 2.0]
    period = 2 * np.mean(np.diff(tt[crossings]))
    assert frequency == pytest.approx(2 * math.pi / period, rel=0.15)
    assert "limit cycle" in summary and f"{frequency:.3g} rad/s" in summary
    assert "overshoot" not in summary and m["overshoot_percent"] is None


# ------------------------------------------------------------------------ analytic cases
def _settle_then_drift(cut: float | None, t_end: float = 4.0):
    """Damped response about a final value of 5 mrad (zeta = 0.3, wn = 40), then a cut and a fall."""
    dt = 1e-3
    t = np.arange(0.0, t_end, dt)
    tau = np.clip(t - POKE, 0.0, None)
    zeta, wn, final = 0.3, 40.0, 0.005
    wd = wn * math.sqrt(1 - zeta**2)
    alpha = np.where(t >= POKE, final + 0.02 * np.exp(-zeta * wn * tau) * np.cos(wd * tau - 0.3), 0.0)
    if cut is not None:
        alpha = np.where(t > cut, final + 3.0 * (t - cut) ** 2, alpha)  # falls after the cut
    return t, alpha, wd, final, zeta


def test_metrics_of_a_cut_run_match_the_analytic_response_before_the_cut():
    t, alpha, wd, final, zeta = _settle_then_drift(cut=2.0)
    m = compute_metrics(t, alpha, poke_start=POKE, q_alpha=0.0, safety_cut_time=2.0)
    ref = compute_metrics(*_settle_then_drift(cut=None)[:2], poke_start=POKE, q_alpha=0.0)
    assert m["stable"] is False and ref["stable"] is True
    assert m["natural_frequency_rad_s"] == pytest.approx(wd, rel=0.01)
    assert m["final_value_rad"] == pytest.approx(final, abs=1e-5)
    for key in ("peak_time_s", "overshoot_percent", "settling_time_s", "natural_frequency_rad_s"):
        assert m[key] == pytest.approx(ref[key], rel=0.02), key
    assert m["overshoot_percent"] == pytest.approx(100 * math.exp(-zeta * math.pi / math.sqrt(1 - zeta**2)), rel=0.05)


def test_a_fall_without_a_cut_reads_the_part_before_the_fall():
    t, alpha, wd, final, _ = _settle_then_drift(cut=2.0)
    m = compute_metrics(t, alpha, poke_start=POKE, q_alpha=0.0)  # no supervisor: the pendulum just falls
    assert m["stable"] is False and m["natural_frequency_rad_s"] == pytest.approx(wd, rel=0.01)
    assert m["final_value_rad"] == pytest.approx(final, abs=1e-4)


def test_a_cut_while_still_swinging_gives_no_final_value():
    t, alpha, wd, _, _ = _settle_then_drift(cut=1.15)
    m = compute_metrics(t, alpha, poke_start=POKE, q_alpha=0.0, safety_cut_time=1.15)
    assert m["final_value_rad"] is None and m["settling_time_s"] is None and m["stable"] is False
    assert m["limit_cycle_amplitude_rad"] is None


def test_decaying_oscillation_is_not_a_limit_cycle_and_a_steady_one_is():
    t = np.arange(0.0, 8.0, 1e-3)
    tau = np.clip(t - POKE, 0.0, None)
    decaying = 0.02 * np.exp(-0.8 * tau) * np.sin(10.0 * tau)
    assert compute_metrics(t, decaying, poke_start=POKE, q_alpha=0.0)["limit_cycle_amplitude_rad"] is None
    steady = decaying + 0.008 * np.sin(12.0 * tau) * (t > POKE)
    q = 0.0015
    m = compute_metrics(t, np.round(steady / q) * q, poke_start=POKE, q_alpha=q)
    assert m["limit_cycle_amplitude_rad"] == pytest.approx(0.008, rel=0.15)
    assert m["limit_cycle_frequency_rad_s"] == pytest.approx(12.0, rel=0.03)
    tiny = 0.001 * np.sin(12.0 * tau)  # within one encoder step: the staircase, not a limit cycle
    assert compute_metrics(t, np.round(tiny / q) * q, poke_start=POKE, q_alpha=q)["limit_cycle_amplitude_rad"] is None
