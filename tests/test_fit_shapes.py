"""The fit on logs of shapes its own code never generates (issue 8, must-show 1).

Each log is the plant under the true stick-slip law (or the closed loop of the FMUs) with parameters the
defaults have never seen, 10 um of position noise and the encoder's quantization. The fit starts from the
lab's defaults, not from the answer.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from fit_helpers import simulate

from pendulab.calibration._polish import rests  # private: the fit's rest detection is checked on known shapes
from pendulab.calibration._replay import replay  # private: the fit's replay (restarts at rests) is checked
from pendulab.calibration.fit import fit_parameters
from pendulab.calibration.synthetic import TRUE, calibrate_ramp_log, synthetic_log
from pendulab.model.parameters import PlantParameters

WITHIN = {"Beq": 0.05, "force_gain": 0.05, "F1": 0.10, "F2": 0.10, "B": 0.10}


def determined_within(result, true: PlantParameters, sigmas: float) -> set[str]:
    """Asserts that every parameter ``result`` calls determined lies within ``sigmas`` of its uncertainties of ``true``'s; returns their names."""
    determined = {n for n in result.names if result.determination[n] == "determined"}
    for name in determined:
        error = abs(result.values[name] - getattr(true, name))
        assert error <= sigmas * result.uncertainty[name], (name, result.values[name], result.uncertainty[name])
    return determined


def relative_errors(result, true: PlantParameters) -> dict[str, float]:
    return {n: result.values[n] / getattr(true, n) - 1 for n in WITHIN}


#: (shape, noise on the logged voltage (V), the replay's RMS asserted, in encoder steps): the issue's bar,
#: two steps. Measured here: 0.85 and 1.05 (the chirp was 1.9 before the observer search, 2.9 while the
#: replay chose among the observer search's answers).
OPEN_LOOP = [("random steps", 0.0, 2.0), ("chirp", 0.0, 2.0)]


@pytest.fixture(scope="module", params=OPEN_LOOP, ids=lambda case: f"{case[0]}, {case[1] * 1e3:.0f} mV")
def open_loop(request):
    shape, voltage_noise, steps = request.param
    log = synthetic_log(shape, duration=20.0, voltage_noise=voltage_noise)
    return log, fit_parameters([log], PlantParameters.preset("none")), steps


def test_open_loop_shapes_recover_the_parameters_and_replay_the_log(open_loop):
    log, result, steps = open_loop
    errors = relative_errors(result, TRUE)
    for name, limit in WITHIN.items():
        assert abs(errors[name]) <= limit, f"{log.source}: {name} {100 * errors[name]:+.1f} %"
    # The replay of the whole log with the answer, in encoder steps (the true values: about one).
    assert result.forward_ok
    assert result.forward_rms <= steps * TRUE.q_x, f"{log.source}: replay RMS {result.forward_rms * 1e6:.0f} um"


def test_each_parameter_is_determined_within_three_sigmas_or_reported_bounded_or_not_identified(open_loop):
    log, result, _ = open_loop
    # Every parameter, v2 included (on the chirp: -0.09 % at +-1.0 %; before the observer search it was
    # 1.2 % off at +-0.12 % and had to be left out). No uncertainty is below 0.3 %, the profile's finest offset.
    for name in result.names:
        status, sigma = result.determination[name], result.uncertainty[name]
        error = abs(result.values[name] - getattr(TRUE, name))
        if status == "determined":
            assert 0 < sigma < 0.5 * abs(result.values[name])
            assert error <= 3 * sigma, f"{log.source}: {name} off by {error:.3g}, sigma {sigma:.3g}"
        else:  # never a small uncertainty for what the log does not determine
            assert status in ("bounded", "not identified") and sigma == math.inf
    # Fast steps and a sweep show the drive and the drag.
    assert result.determination["Beq"] == result.determination["force_gain"] == "determined"
    # (The force thresholds' floor from a noisy logged voltage: test_fit_corpus.py, on its noisy case.)


# The closed loop with the pendulum up (the same log and start): tests/test_fit_corpus.py, its 'closed loop | unseen' case.


def test_replay_restarts_at_rests_so_the_true_values_replay_a_log_to_the_noise():
    log = synthetic_log("random steps", duration=8.0)
    spans = rests(log.x, TRUE.q_x, 1e-5, log.period)
    assert len(spans) >= 3
    # The compiled replay equals the reference simulation when it never restarts.
    x0 = np.array([log.x[0], 0.0, 0.0, 0.0])
    compiled = replay([TRUE], log.V[:-1], log.t[:-1], x0)[0, :, 0]
    reference = simulate(TRUE, log.V[:-1], log.period, x0)[1:, 0]
    assert np.max(np.abs(compiled - reference)) < 1e-9
    # A restart replaces the state: restarting on the reference trajectory changes nothing after it.
    k = len(log) // 2
    state = simulate(TRUE, log.V[:k], log.period, x0)[-1]
    restarted = replay([TRUE], log.V[:-1], log.t[:-1], x0 + np.array([0.01, 0, 0, 0]), {k: state})[0, :, 0]
    assert np.max(np.abs(restarted[k:] - reference[k:])) < 1e-9
    assert np.max(np.abs(restarted[: k - 1] - reference[: k - 1])) > 0.009
    # A restart with a nan speed (a short rest, _polish.RESTART_REST) replaces the position only: the replay's own speed goes on.
    moved = replay([TRUE], log.V[:-1], log.t[:-1], x0, {k: state + np.array([0.002, np.nan, 0, 0])})[0]
    assert np.max(np.abs(moved[k:, 0] - reference[k:] - 0.002)) < 1e-9
    assert np.array_equal(moved[:k, 0], compiled[:k]) and np.max(np.abs(moved[k:, 1] - simulate(TRUE, log.V[:-1], log.period, x0)[k + 1 :, 1])) < 1e-9


def test_a_short_rest_restarts_the_position_only_so_a_creeping_cart_tells_its_drag_split():
    # The unseen rig's slow ramps stop in short "rests" where the cart creeps near v1 (3 mm/s) and the encoder's steps
    # hide its speed. Restarted from the speeds a line through them gives (0.64 mm/s RMS off), the true values replayed
    # this log at 0.92 steps and Beq 10 % high (B + Beq kept) at 0.66: the fit found Beq +12 %. The position only: 0.62
    # for the true values, 0.75 and 0.97 for Beq 5 and 10 % high, 0.70 and 1.01 for 5 and 10 % low.
    from fit_helpers import prepared

    from pendulab.calibration._polish import RESTART_REST  # private: the short-rest restart rule is what this checks
    from pendulab.calibration.synthetic import RIGS

    p = RIGS["unseen"]
    log = synthetic_log("ramps with holds", p, duration=16.0, voltage_noise=0.0)
    (a,), _ = prepared(log, p.q_x)
    short = [k for k, s in a.restarts.items() if np.isnan(s[1])]
    assert len(short) >= 10 and len(a.restarts) - len(short) >= 3  # most rests are short; the long ones keep their speed
    assert RESTART_REST >= 0.05

    def steps(factor: float) -> float:
        q = p.with_values(Beq=factor * p.Beq, B=p.B + p.Beq - factor * p.Beq)
        x = replay([q], a.V, a.t, a.x0, a.restarts)[0, :, 0]
        return float(np.sqrt(np.mean((x - a.measured[:, 0]) ** 2))) / p.q_x

    at = {f: steps(f) for f in (0.9, 0.95, 1.0, 1.05, 1.1)}
    assert at[1.0] < 0.8  # measured 0.62
    assert min(at, key=at.get) == 1.0 and at[1.05] > 1.1 * at[1.0] and at[0.95] > 1.05 * at[1.0]


def test_a_replay_with_wrong_values_is_rejected():
    from pendulab.calibration.fit import FORWARD_LIMIT_STEPS

    log = synthetic_log("chirp", duration=10.0, voltage_noise=0.0)
    limit = FORWARD_LIMIT_STEPS * TRUE.q_x  # the check a fit's answer must pass (FitResult.forward_limit)
    x0 = np.array([log.x[0], 0, 0, 0])
    x = replay([TRUE], log.V[:-1], log.t[:-1], x0)[0, :, 0]
    assert math.sqrt(np.mean((x - log.x[1:]) ** 2)) < 0.25 * limit  # the true values pass it by far
    # The same check on values 16 % off (as the report): far above the encoder step.
    wrong = TRUE.with_values(Beq=TRUE.Beq * 0.84, force_gain=TRUE.force_gain * 0.84)
    x = replay([wrong], log.V[:-1], log.t[:-1], x0)[0, :, 0]
    assert math.sqrt(np.mean((x - log.x[1:]) ** 2)) > limit


def test_a_log_that_starts_with_the_cart_moving_settles_its_first_state():
    # A log cut from a run where the cart was fastest (helper's audit: v2 came out 12 % high, "determined" to 3 %, and
    # the replay missed by 2.1 encoder steps): the smoothed speed at the log's edge is no known state.
    whole = synthetic_log("random steps", TRUE, duration=20.0, voltage_noise=0.0)
    k = 2000 + int(np.argmax(np.abs(np.gradient(whole.x, whole.t)[2000:10000])))
    log = whole.slice(k, len(whole))
    assert abs(np.gradient(log.x, log.t)[0]) > 0.3  # m/s
    result = fit_parameters([log], PlantParameters.preset("none"))
    assert result.forward_rms < 1.25 * TRUE.q_x  # measured 0.89 steps
    for name, error in relative_errors(result, TRUE).items():
        assert abs(error) < WITHIN[name], (name, error)
    if result.determination["v2"] == "determined":
        assert abs(result.values["v2"] - TRUE.v2) < 3 * result.uncertainty["v2"]  # measured -0.3 % +- 1.2 %


def test_a_log_whose_first_step_is_long_replays_at_its_median_period():
    # The helper's audit (session 20): the replay took the period from the first two samples; a log whose first step
    # was 4.5 % long fitted the force gain 8.4 % low, "determined" to 0.3 %, and exited 0.
    from dataclasses import replace

    from pendulab.calibration.synthetic import TEST_RIG

    log = synthetic_log("random steps", TEST_RIG, duration=12.0, voltage_noise=0.0)
    t = log.t.copy()
    t[0] -= 0.045 * log.period
    result = fit_parameters([replace(log, t=t)], PlantParameters.preset("none"))
    for name in ("Beq", "force_gain"):  # measured -0.0 % and -0.0 % (with the first step: -8.4 % on the gain)
        assert abs(result.values[name] / getattr(TEST_RIG, name) - 1) < 0.02, (name, result.values[name])


@pytest.mark.parametrize("rate, seed", [(100, 1), (200, 1), (100, 2)])
def test_a_log_sampled_at_100_or_200_hz_fits(rate, seed):
    # The helper's audit (session 20): docs/ta.md says 100 to 2000 Hz, but at 100 Hz the rests (3 samples, within 6
    # noise sigmas read off a curved motion: 99 um) held a moving cart, the replay restarted it from rest, and the fit
    # refused the log at 54 encoder steps; at 200 Hz it missed by 4.6 and determined nothing.
    from pendulab.calibration.logs import RampLog
    from pendulab.calibration.synthetic import TEST_RIG
    from pendulab.model.plant import PlantModel

    period = 1.0 / rate
    fine = synthetic_log("random steps", TEST_RIG, duration=12.0, voltage_noise=0.0)
    V = fine.V[: len(fine) - 1 : round(period / fine.period)]  # held for a whole sample, as a rig at that rate drives it
    x = PlantModel().simulate(TEST_RIG, V, period)[:, 0] + np.random.default_rng(seed).normal(0.0, 1e-5, V.size + 1)
    log = RampLog(np.arange(V.size + 1) * period, np.r_[V, 0.0], TEST_RIG.q_x * np.round(x / TEST_RIG.q_x), source=f"{rate} Hz")
    result = fit_parameters([log], PlantParameters.preset("none"))
    assert result.forward_ok  # was refused at 100 Hz (54 steps)
    for name in ("Beq", "force_gain"):  # measured within 0.3 % at both rates
        assert abs(result.values[name] / getattr(TEST_RIG, name) - 1) < 0.02, (name, result.values[name])
    # No determined value outside 3 sigmas. At 100 Hz with the second noise seed F1 (-5.6 %) and F2 (+4.3 %) were reported
    # to +-0.3 % (z 19.6 and 13.6): a threshold's cost is a staircase, and the first step up said they were known
    # (_polish.profile: now at least to where the cost stays within twice the answer's). Measured now: z <= 1.8.
    determined_within(result, TEST_RIG, 3.0)
    if (rate, seed) == (200, 1):  # at 100 Hz this log's replay misses by 4 steps (another noise seed's: 2.5), and says so: all bounded
        assert result.forward_rms < 2.5 * TEST_RIG.q_x  # measured 1.1 steps
        for name in ("F1", "F2", "B"):  # measured 4-6 % off (docs/ta.md: read them to about 10 % at these rates)
            assert abs(result.values[name] / getattr(TEST_RIG, name) - 1) < 0.2, (name, result.values[name])


# Each sign once, on two shapes (each case fits twice, some 45 CPU-s; random steps a sample early also passed, session 33).
@pytest.mark.parametrize("shape, lag", [("random steps", -1), ("chirp", 1)])
def test_a_voltage_logged_a_sample_early_or_late_is_found_and_fitted_shifted(shape, lag, tmp_path):
    # Loggers differ on whether a row's voltage is the one applied from its time on or the one that brought the cart
    # there. Random steps (unseen rig, 12 s) with the voltage a sample early: the answer missed by 2.9 steps, every
    # value 2-26 % off and called determined. Found, they fit as the unshifted log does (0.7-0.8 steps, within 0.5 %).
    # On the unseen rig a chirp's lag was not found when the probe was the replay, polished (fit.LAG_PROBE_ITER).
    from dataclasses import replace

    from pendulab.calibration.files import load_calibration, save_calibration
    from pendulab.calibration.synthetic import TEST_RIG

    log = synthetic_log(shape, TEST_RIG, duration=12.0, voltage_noise=0.0)
    n = len(log)
    shifted = replace(log, V=np.r_[log.V[1:], log.V[-1]]) if lag > 0 else replace(log, V=np.r_[log.V[0], log.V[: n - 1]])
    result = fit_parameters([shifted], PlantParameters.preset("none"))
    assert result.voltage_lag == lag
    assert result.forward_rms < 1.5 * TEST_RIG.q_x  # measured 0.8 steps, as the unshifted log's
    for name in ("F2", "v2", "B", "Beq", "force_gain"):  # measured within 0.5 %
        assert abs(result.values[name] / getattr(TEST_RIG, name) - 1) < 0.03, (name, result.values[name])
    assert f"the voltage replayed 1 sample(s) {'later' if lag > 0 else 'earlier'} than logged" in result.summary()
    save_calibration(result.to_calibration(), tmp_path / "c.json")
    assert load_calibration(tmp_path / "c.json").metadata["voltage_lag_samples"] == lag


def test_a_closed_loop_log_a_sample_off_is_fitted_with_uncertainties_that_hold_the_rig():
    # With the pendulum up the voltage follows the motion, and the logs cannot tell a voltage logged a sample late from
    # one on time (fit.LAG_SPREAD_SHIFTS). The unseen rig's closed loop a sample off replays at 1.7 steps with Beq 2.8 %
    # off; it was reported to +-0.3 % (z 8.9, the gain 3.7). Measured now: every determined value within 1.1 sigmas.
    from dataclasses import replace

    from pendulab.calibration.fit import shifted_voltage
    from pendulab.calibration.synthetic import RIGS, closed_loop_log, closed_loop_params

    true = closed_loop_params(RIGS["unseen"])
    lab = PlantParameters.preset("none")
    log = closed_loop_log(RIGS["unseen"])
    start = true.with_values(**{n: getattr(lab, n) for n in ("F1", "v1", "F2", "v2", "B", "Beq", "force_gain")})  # the lab's friction and drive
    result = fit_parameters([replace(log, V=shifted_voltage(log.V, 1))], start)
    assert result.forward_ok
    assert {"Beq", "force_gain"} <= determined_within(result, true, 3.0)
    assert "the voltage's alignment" in result.uncertainty_method


@pytest.mark.xfail(strict=True, reason="a known honesty failure since the global search (session 27): see the comment")
def test_a_cart_log_a_sample_off_that_replays_well_counts_the_shift_in_its_uncertainties():
    # Slow ramps of the heavy rig with the voltage a sample early replay within 1.5 steps, so the lag is not looked for
    # (fit.LAG_ABOVE_STEPS); the common scale comes out 1.5 % off, at z up to 2.6. The shift that undoes it replayed,
    # after its Gauss-Newton step, at 0.78 times the answer's cost (fit.LAG_TOLD), and counted: z <= 0.82.
    # Since the global search (CMA-ES from the search's answer) the answer replays at 0.84 steps with the common scale
    # 1.8 % high, and the undoing shift's step replays at 2.5 to 3 times its cost: told apart, not counted, and B, Beq
    # and the force gain are called determined at z 5.8-6.1 (counted, LAG_TOLD 3: z <= 2.0, but on-time logs measured 3).
    from dataclasses import replace

    from pendulab.calibration.fit import shifted_voltage
    from pendulab.calibration.synthetic import corpus

    case = next(c for c in corpus() if c.name == "ramps with holds | heavy drag, weak drive | 0 mV")
    log, true = case.log(), case.params
    result = fit_parameters([replace(log, V=shifted_voltage(log.V, 1))], PlantParameters.preset("none"))
    assert result.forward_rms < 2.0 * true.q_x and result.voltage_lag == 0  # measured 1.42 steps
    assert "the voltage's alignment" in result.uncertainty_method
    assert {"Beq", "force_gain"} <= determined_within(result, true, 1.5)


def test_the_voltage_alignment_does_not_widen_a_cart_log_that_tells_it(open_loop):
    # Random steps and a chirp on time: each shift, after its Gauss-Newton step, replays at 3 to 45 times the cost.
    log, result, _ = open_loop
    assert "the voltage's alignment" not in result.uncertainty_method


def test_a_triangle_wave_on_a_rig_nine_times_less_sticky_fits():
    # A probe of session 37 on a rig none of the corpus's resembles: the ramp extraction read the breakaway as 4.6 N (true 0.5), and
    # the first speed was the smoothing's edge (5.8 mm/s; the cart breaks away at its first sample); the fit ended 7.7 encoder steps
    # off with F2 +4456 % and B -58 % (all only bounded). Measured now: 0.72 steps, F2 +0.06 %, B +0.1 %, 11 CPU-s. (The same wave
    # on the session-22 audit's rig, Beq 2.7, F1 0.66, B 40: 1.35 steps, v2 -19 % at z 7, then widened by the first state's move;
    # from rest now 0.78 steps, every determined value within 2 % at z <= 0.2.)
    rig = PlantParameters.preset("none", Beq=2.0, force_gain=0.7, F1=0.5, v1=0.008, F2=0.9, v2=0.1, B=8.0)
    result = fit_parameters([synthetic_log("triangle", rig, duration=16.0, voltage_noise=0.0)], PlantParameters.preset("none"))
    assert result.forward_rms < 1.25 * rig.q_x
    assert {"F1", "F2", "B", "Beq", "force_gain"} <= determined_within(result, rig, 3.0)
    assert all(abs(e) < 0.05 for e in relative_errors(result, rig).values())


def test_a_threshold_on_a_cliff_of_the_cost_is_checked_by_its_profile_with_the_others_polished():
    # A probe of session 37 on another rig nobody here made, its calibrate ramp test: the search stopped with F2 30 % low, where the
    # drive at one slowdown met F2 to a hair. The replay cost rises 8.5 times at F2 +2.5 % and 900 times at -2.5 %, then falls slowly
    # to the rig's value 43 % higher, so the profile called F2 determined to 1.9 % (z -23). Moved +35 % with the others polished, F2
    # replays cheaper than that answer. Measured now: F2 -4.4 %, bounded (1.4 to 3.7 N: the cliff's answer replays within twice the cost),
    # 0.93 encoder steps (1.11 before).
    rig = PlantParameters.preset("none", Beq=9.5, force_gain=1.05, F1=1.9, v1=0.0035, F2=2.9, v2=0.045, B=35.0)
    said: list[str] = []
    result = fit_parameters([calibrate_ramp_log(rig)], PlantParameters.preset("none"), on_progress=said.append)
    assert any(line.startswith("F2 moved +35% with the others polished replays better") for line in said)
    determined_within(result, rig, 3.0)
    low, high = result.allowed["F2"]
    assert low <= rig.F2 <= high
    assert result.forward_rms < 1.25 * rig.q_x
    assert abs(result.values["Beq"] / rig.Beq - 1) < 0.05 and abs(result.values["force_gain"] / rig.force_gain - 1) < 0.05


def test_a_drag_in_one_of_two_equally_good_basins_is_not_reported_determined():
    # A probe of session 38 on a worn rig (v2 0.02 m/s, B 60), its chirp: the fit replays it as well as the rig's values do (1.05 encoder
    # steps against 1.04), but with v2 +11 % and B -16 %, each "determined" to about 1 % (z +10 and -7.3): the rig's values are as good a
    # minimum behind a barrier, which no profile around the answer sees. B held 35 % higher with the others polished finds that basin, a
    # rival within twice the cost: both are bounded now, their ranges holding the rig's values (measured: v2 0.0186-0.0225, B 50-68).
    rig = PlantParameters.preset("none", Beq=6.0, force_gain=0.85, F1=3.0, v1=0.002, F2=3.6, v2=0.02, B=60.0)
    result = fit_parameters([synthetic_log("chirp", rig, duration=16.0, voltage_noise=0.0)], PlantParameters.preset("none"))
    determined_within(result, rig, 3.0)
    for name in ("v2", "B"):
        low, high = result.allowed[name]
        assert result.determination[name] == "determined" or low <= getattr(rig, name) <= high, (name, result.values[name], low, high)
    assert result.forward_rms < 1.5 * rig.q_x


def test_a_log_cut_where_the_cart_moves_slowly_is_not_widened_by_a_first_state_at_rest_the_log_tells_apart():
    # The same rig's triangle wave cut where the smoothed speed is 80 mm/s: the cart moves there, and replays better from that speed
    # than from rest. The uncertainties counted the move to rest regardless: F1 +-14 % and B only bounded, both within 0.5 % (z <= 0.2).
    # Now the move to rest, after its Gauss-Newton step, costs over 1.25 times the answer's (told apart, as a voltage a sample off is).
    from pendulab.calibration.fit import _initial_states  # private: the smoothed first speed the log is cut at

    rig = PlantParameters.preset("none", Beq=2.0, force_gain=0.7, F1=0.5, v1=0.008, F2=0.9, v2=0.1, B=8.0)
    log = synthetic_log("triangle", rig, duration=16.0, voltage_noise=0.0)
    speed = np.abs(_initial_states(log, False)[:, 1])
    k = int(np.flatnonzero((speed > 0.03) & (speed < 0.08) & (np.arange(len(log)) > 200))[0])
    result = fit_parameters([log.slice(k, len(log))], PlantParameters.preset("none"))
    assert "the first state's speed" not in result.uncertainty_method
    assert {"F1", "B", "Beq", "force_gain"} <= determined_within(result, rig, 3.0)
    assert result.forward_rms < 1.0 * rig.q_x  # measured 0.74 steps
