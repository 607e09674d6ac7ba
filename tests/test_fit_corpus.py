"""A representative part of bench/fit_corpus.py (issue 19), run as the bench runs it: three shapes (slow ramps with
holds, the closed loop, a triangle wave), three rigs, with and without voltage noise, about a minute in all (63 s, one process) (random steps and
the chirp of the unseen rig are test_fit_shapes.py's, the calibrate ramp test test_fit.py's and
test_calibration_cli.py's). The whole corpus, with its table, is ``python bench/fit_corpus.py``; its held-out third
is not used here.

Each case is judged by what the issue asks of every case: the fit accepts the log, and every parameter it
calls determined lies within 3 of its reported standard uncertainties of the true value. Where the case
meets the issue's whole bar with room to spare (the replay within 2 encoder steps, Beq and the force gain
within 5 %, each determined friction value within 10 %), the bar is asserted too. With 10 mV on the logged voltage, a force threshold
called determined is uncertain by at least the drive of that noise.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parent.parent / "bench" / "fit_corpus.py"

#: The cases, and whether the issue's whole bar is asserted on them (measured here: see the note at each). The largest
#: z (error / reported sigma) of a determined parameter was 0.51 (F2 of the closed loop); over the development corpus's
#: cases that meet the bar, 1.40 (B of the unseen rig's chirp).
CASES = {
    "closed loop | unseen | 0 mV": True,  # replay 0.53 steps, errors <= 0.3 %, all but v1 determined
    "ramps with holds | heavy drag, weak drive | 10 mV": True,  # replay 0.79 steps, errors <= 0.5 % but v1 +0.8 %
    # The cart leaves the slip region at v2 and slides: the escape's timing is a needle in v2 and F1 (fit.RESCAN).
    # Replay 0.66 steps (3.54 before the rescan, F2 -36 %), F1 v2 B Beq gain determined within 0.7 %, z <= 1.2.
    "ramps with holds | sticky | 0 mV": True,
    # Replay 2.68 steps (the rig's own values: 2.51; 1.53 before the short rests restarted the position only): the common
    # scale 4 % low. The z of F1, F2, Beq and the gain were 3.9 to 4.5 before their uncertainty held how the scale moves
    # with the other estimate of the voltage (fit._voltage_shift).
    "triangle | heavy drag, weak drive | 10 mV": False,
}
#: Bounded parameters whose range is not asserted to hold the rig's value. The heavy rig's triangle with 10 mV: the search
#: stops with v1 11 times the rig's (0.045 m/s), farther than the profile reaches (a factor 2 either way), and replays the
#: log worse than the rig's own values (2.68 steps against 2.51); the issue does not judge the case (beyond 1.5 steps).
RANGE_UNTESTED = {"triangle | heavy drag, weak drive | 10 mV": {"v1"}}
#: Determined parameters whose z is not asserted: measured too close to 3 for a test (within 25 %).
Z_UNTESTED = {"triangle | heavy drag, weak drive | 10 mV": {"v2"}}  # v2 +0.8 %, z 2.51


def _load_bench():
    spec = importlib.util.spec_from_file_location("fit_corpus", BENCH)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # as an import would: its dataclasses look their module up there
    spec.loader.exec_module(module)  # type: ignore[union-attr]
    return module


bench = _load_bench()  # its top level imports only the standard library


@pytest.mark.parametrize("name", list(CASES))
def test_corpus_case_is_accepted_and_honest(name):
    from pendulab.calibration.synthetic import corpus, held_out

    cases = corpus()
    case = next(c for c in cases if c.name == name)
    assert name not in held_out(cases)  # the held-out third is looked at only at the end
    row = bench.run_case(case)
    print("\n" + bench.line(row))
    assert row["accepted"], row.get("refused", row)
    for parameter, status in row["status"].items():
        if status == "determined" and parameter not in Z_UNTESTED.get(name, ()):
            assert row["z"][parameter] <= 3.0, (parameter, row["errors"][parameter], row["z"][parameter])
    # A bounded parameter's range holds the rig's value (bench/fit_corpus.py's '?': 6 in the 32 development cases, where
    # the rig's own values replay 1.8 to 15 times worse than the answer, and RANGE_UNTESTED's).
    assert not any(v for n, v in row["outside"].items() if n not in RANGE_UNTESTED.get(name, ())), bench.line(row)
    # The stick speed is only ever bounded, within a range that holds the truth (fit.V1_SCATTER).
    low, high = row["allowed"]["v1"]
    assert row["status"]["v1"] != "determined", row["status"]["v1"]
    assert "v1" in RANGE_UNTESTED.get(name, ()) or low < case.params.v1 < high, (low, high)
    assert row["steps"] <= 3.5, bench.line(row)  # measured at most 2.68 steps
    if CASES[name]:  # the bar's other points, with room (measured: see CASES)
        e, s = row["errors"], row["status"]
        assert row["steps"] <= 2.0 and abs(e["Beq"]) <= 0.05 and abs(e["force_gain"]) <= 0.05, bench.line(row)
        assert all(abs(e[n]) <= 0.10 for n in ("F1", "v1", "F2", "v2", "B") if s[n] == "determined"), bench.line(row)
        assert {"Beq", "force_gain", "F1", "B"} <= {n for n in s if s[n] == "determined"}, bench.line(row)
    if case.shape == "closed loop":  # the pendulum swung, and its unstable replay restarts from the fit's state estimates
        alpha = case.log().alpha
        assert float(max(alpha) - min(alpha)) > 0.02 and row["restarts"] > 0
        # Settled restarts (each replays its stretch best) replay it at 0.53 steps; the observer's own, causal, at 1.39.
        assert row["steps"] <= 1.0, bench.line(row)
    if case.voltage_noise > 0:  # a force threshold is no better known than the noisy voltage it is read against
        from pendulab.calibration._polish import voltage_noise  # private: the fit's estimate of the logged voltage's noise
        from pendulab.calibration.extract import motor_constants

        K, _ = motor_constants(case.params.with_values(force_gain=1.0))
        floor = row["values"]["force_gain"] * K * voltage_noise(case.log().V)
        for parameter in ("F1", "F2"):
            if row["status"][parameter] == "determined":
                assert row["sigma"][parameter] >= 0.99 * floor, (parameter, row["sigma"][parameter], floor)
    print("z of the determined parameters:", {n: round(z, 2) for n, z in row["z"].items() if row["status"][n] == "determined"})
