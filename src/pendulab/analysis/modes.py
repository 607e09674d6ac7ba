"""When the supervisor's modes acted in a run: re-centring, the swing-up, its catches (issue 21).

Read from the recorded columns (``supervisor_state`` and, when re-centring was on, ``recentring``),
the same way for a simulated run and a rig's log, so that metrics, plots and the printed summary all
mark the same moments.

Examples
--------
>>> import numpy as np
>>> from pendulab.fmu.models.supervisor.config import RUNNING, SWINGING
>>> t = np.arange(6) * 0.5
>>> state = np.array([SWINGING, SWINGING, RUNNING, RUNNING, RUNNING, RUNNING])
>>> recentring = np.array([0, 0, 0, 1, 1, 0])
>>> m = mode_metrics(t, state, recentring=recentring, x=np.array([0, .1, .2, .1, 0, 0]))
>>> m["swing_start_s"], m["catch_time_s"], m["recentre_intervals_s"], m["max_abs_x_m"]
(0.0, 1.0, [[1.5, 2.5]], 0.2)
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pendulab.fmu.models.supervisor.config import RUNNING, STATES, SWINGING


def _runs(flag: np.ndarray, t: np.ndarray) -> list[list[float]]:
    """``[start, end]`` of each run of True in ``flag`` (end: the first sample after it, or the last time)."""
    edges = np.diff(np.concatenate(([0], flag.astype(np.int8), [0])))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return [[float(t[a]), float(t[min(b, t.size - 1)])] for a, b in zip(starts, ends)]


def mode_metrics(t: Any, state: Any, *, recentring: Any = None, x: Any = None) -> dict[str, Any]:
    """The modes' moments: swing start, catches, missed catches, re-centring intervals, largest ``|x|``.

    Parameters
    ----------
    t, state : 1-D arrays
        Time and the supervisor's ``state`` code at each sample.
    recentring : 1-D array, optional
        The supervisor's ``recentring`` output (1 while re-centring is engaged).
    x : 1-D array, optional
        Cart position, for ``max_abs_x_m``.

    Returns
    -------
    dict
        ``swing_start_s`` (first sample swinging up, or None), ``catch_time_s`` (the first hand-over
        to the controller after a swing, or None), ``catch_times_s`` (every hand-over),
        ``missed_catches`` (hand-overs followed by swinging again), ``recentre_intervals_s``
        (``[on, off]`` pairs), ``recentre_time_s`` (their total) and ``max_abs_x_m``.
    """
    t = np.asarray(t, dtype=float).reshape(-1)
    state = np.asarray(state, dtype=float).reshape(-1)
    swinging = state == SWINGING
    caught = np.flatnonzero(swinging[:-1] & (state[1:] == RUNNING)) + 1
    missed = np.flatnonzero((state[:-1] == RUNNING) & swinging[1:])
    out: dict[str, Any] = {
        "swing_start_s": float(t[np.argmax(swinging)]) if swinging.any() else None,
        "catch_time_s": float(t[caught[0]]) if caught.size else None,
        "catch_times_s": [float(t[i]) for i in caught],
        "missed_catches": int(sum(1 for i in missed if caught.size and i >= caught[0])),
    }
    if recentring is not None:
        intervals = _runs(np.asarray(recentring, dtype=float).reshape(-1) > 0.5, t)
        out["recentre_intervals_s"] = intervals
        out["recentre_time_s"] = float(sum(b - a for a, b in intervals))
    if x is not None:
        out["max_abs_x_m"] = float(np.max(np.abs(np.asarray(x, dtype=float)))) if np.size(x) else None
    return out


def mode_events(t: Any, state: Any, *, recentring: Any = None) -> list[str]:
    """Every change of the supervisor's state and of re-centring, as ``"t=1.234 s: ..."`` lines in time order."""
    t = np.asarray(t, dtype=float).reshape(-1)
    state = np.asarray(state, dtype=float).reshape(-1)
    events: list[tuple[float, str]] = []
    for i in np.flatnonzero(np.diff(state)) + 1:
        before, after = STATES.get(int(state[i - 1]), "?"), STATES.get(int(state[i]), "?")
        why = " (caught)" if int(state[i - 1]) == SWINGING and int(state[i]) == RUNNING else \
            " (catch missed)" if int(state[i - 1]) == RUNNING and int(state[i]) == SWINGING else ""
        events.append((float(t[i]), f"{before} -> {after}{why}"))
    if recentring is not None:
        for start, end in _runs(np.asarray(recentring, dtype=float).reshape(-1) > 0.5, t):
            events.append((start, "re-centring engaged"))
            if end < t[-1]:
                events.append((end, "re-centring released"))
    return [f"t={when:.3f} s: {text}" for when, text in sorted(events, key=lambda e: e[0])]
