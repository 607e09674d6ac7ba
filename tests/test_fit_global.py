"""The fit's escapes from a wrong basin (issue 19) on the unseen rig's triangle wave (3 V, 0.4 Hz).

The cart stays in the slip region there, leaving it only by force near the peaks. From every start the observer
search and the polish folded the slip drag ``B`` into ``Beq`` (``B`` -99.9 %, ``Beq`` +900 %, ``F2 = F1``) and replayed
the log 4.5 encoder steps off, against the rig's own values' 1.27. Only the global search's luckier seeds found the
rig's basin (1 of 8 with 10 mV on the voltage). The scan of the drag's split now also tries the slip region with ``F2``
out of the way (``_polish.SLIP_F2_FACTORS``): the drive left the slip region at ``F2`` right after each breakaway, so no
share of ``B`` could lower the cost (tests/test_fit_scans.py shows the scan with and without it). And where the cart stays in the slip region, the common scale of the gain, forces
and drags is searched (``fit._in_the_slip_region_only``): the polish stopped with the force gain 5-7 % low.
"""

from __future__ import annotations

import pytest

from pendulab.calibration.fit import GLOBAL_ABOVE_STEPS, fit_parameters
from pendulab.calibration.synthetic import corpus, held_out
from pendulab.model.parameters import PlantParameters


def _case(noise: str):
    cases = corpus()
    case = next(c for c in cases if c.name == f"triangle | unseen | {noise}")
    assert case.name not in held_out(cases)
    return case


@pytest.mark.parametrize("noise", ["0 mV", "10 mV"])
def test_the_split_scan_leaves_the_basin_where_the_local_stages_fold_B_into_Beq(noise):
    case = _case(noise)
    said: list[str] = []
    result = fit_parameters([case.log()], PlantParameters.preset("none"), on_progress=said.append)
    assert any(s.startswith("scans along scale, split") for s in said), said
    assert not any(s.startswith("the global search") for s in said), said  # no seed's luck
    assert any(s.startswith("the cart stays in the slip region") for s in said), said
    true = case.params
    steps = result.forward_rms / result.encoder_step
    # Measured: 0.70 steps; force gain -1.2 %, F1 -1.2 %, B -0.2 %, Beq -11.3 % (10 mV: 0.77 steps; +0.7, +0.3, +1.2, -3.7 %).
    # Beq and B are only bounded here: the cart stays in the slip region, where the replay sees mostly their sum.
    assert result.forward_ok and steps <= GLOBAL_ABOVE_STEPS, steps
    assert abs(result.values["force_gain"] / true.force_gain - 1) < 0.05, result.values["force_gain"]
    for name in ("F1", "B", "Beq"):
        assert abs(result.values[name] / getattr(true, name) - 1) < 0.15, (name, result.values[name])
    # Every range it reports holds the rig's value.
    for name, (low, high) in result.allowed.items():
        assert result.determination[name] == "determined" or low <= getattr(true, name) <= high, (name, low, high)
    for name, status in result.determination.items():
        assert status != "not identified" or result.values[name] == result.initial[name], (name, result.values[name])
