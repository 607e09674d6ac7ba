"""The fit's global search (issue 19): where the local stages stop in a wrong basin, CMA-ES on the replay from the start.

On the unseen rig's triangle wave (3 V, 0.4 Hz) the cart stays in the slip region, leaving it only by force near the
peaks. From every start the observer search and the polish folded the slip drag ``B`` into ``Beq`` (``B`` -99.9 %,
``Beq`` +900 %) and replayed the log 4.5 encoder steps off, against the rig's own values' 1.27. The global search,
seeded, from the start with a step of a factor e, finds the rig's basin: its first seed without voltage noise, its
fourth with 10 mV (1 of 8 seeds tried there found it).
"""

from __future__ import annotations

import pytest

from pendulab.calibration.fit import GLOBAL_ABOVE_STEPS, fit_parameters
from pendulab.calibration.synthetic import corpus, held_out
from pendulab.model.parameters import PlantParameters


@pytest.mark.parametrize("noise", ["0 mV", "10 mV"])
def test_the_global_search_finds_the_rigs_basin_where_the_local_stages_fold_B_into_Beq(noise):
    cases = corpus()
    case = next(c for c in cases if c.name == f"triangle | unseen | {noise}")
    assert case.name not in held_out(cases)
    said: list[str] = []
    result = fit_parameters([case.log()], PlantParameters.preset("none"), on_progress=said.append)
    before = [s for s in said if s.startswith("polished on the replay")]
    assert before and any(s.startswith("the global search, and the polish") for s in said), said
    true = case.params
    steps = result.forward_rms / result.encoder_step
    # Measured: 0.72 steps; Beq -2.0 %, force gain -0.1 %, F1 -0.3 %, B +0.05 % (10 mV: 0.79; +1.8, -1.2, -2.3, -1.5 %).
    assert result.forward_ok and steps <= GLOBAL_ABOVE_STEPS, steps
    for name in ("Beq", "force_gain"):
        assert abs(result.values[name] / getattr(true, name) - 1) < 0.05, (name, result.values[name])
    for name in ("F1", "B"):
        assert abs(result.values[name] / getattr(true, name) - 1) < 0.10, (name, result.values[name])
    # Every range it reports holds the rig's value.
    for name, (low, high) in result.allowed.items():
        assert result.determination[name] == "determined" or low <= getattr(true, name) <= high, (name, low, high)
    # What it calls not identified kept its start value, as the calibration file says (v2, flat around the answer
    # at 0.48 m/s, replayed worse back at its start, 0.05: it is reported bounded instead).
    for name, status in result.determination.items():
        assert status != "not identified" or result.values[name] == result.initial[name], (name, result.values[name])
