#!/usr/bin/env python3
"""How the fit does on logs of shapes its own code never generates (issue 8, must-show 1).

Shapes (``tests/fit_logs.py``): slow ramps with rests, fast steps, a sine sweep; the plant under the
true stick-slip law with parameters the defaults have never seen, 10 um position noise, the encoder's
quantization and optionally voltage noise. Each is fitted as ``pendulab fit LOG`` does (ramp-test
start where one is found, else the defaults) and the recovered values, their errors, the fit's time
and its forward check are printed, beside the forward check of the true values on the same log.

Usage::

    python bench/fit_shapes.py [--duration 20] [--voltage-noise 0.0] [--rig NAME] [--shapes S,S]

``--rig`` picks the parameters (``tests/fit_logs.py``'s RIGS: "unseen" by default, and three far
from the lab's defaults); the replay is also given in encoder steps (the issue's bar: two).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=20.0)
    parser.add_argument("--voltage-noise", type=float, default=0.0)
    parser.add_argument("--rig", default="unseen", help="parameters of the log (tests/fit_logs.py RIGS)")
    parser.add_argument("--shapes", default="ramps with rests,fast steps,sine sweep,closed loop")
    args = parser.parse_args()

    import numpy as np
    from fit_logs import RIGS, closed_loop_log, synthetic_log

    if args.rig not in RIGS:
        parser.error(f"--rig {args.rig!r}: choose among {', '.join(RIGS)}")
    TRUE = RIGS[args.rig]

    from pendulab.calibration._simulation import simulate
    from pendulab.calibration.fit import fit_parameters, ramp_start
    from pendulab.model.parameters import PlantParameters

    for shape in [s.strip() for s in args.shapes.split(",") if s.strip()]:
        if shape == "closed loop":
            log, true = closed_loop_log(duration=min(args.duration, 8.0))
            start, note = true.with_values(F1=1.5, v1=0.005, F2=3.0, v2=0.05, B=20.0, Beq=4.3, force_gain=1.0), "starting from the lab's defaults"
            true_rms = math.nan  # the free replay of an upright pendulum diverges
            reference = true  # closed_loop_log's own rig (TRUE's friction on the long pendulum)
        else:
            log = synthetic_log(shape, TRUE, duration=args.duration, voltage_noise=args.voltage_noise)
            x_true = simulate(TRUE, log.V[:-1], log.period, (log.x[0], 0, 0, 0))[:, 0]
            true_rms = float(np.sqrt(np.mean((x_true - log.x) ** 2)))
            start, note = ramp_start([log], PlantParameters.preset("none"))
            reference = TRUE
        t0 = time.perf_counter()
        result = fit_parameters([log], start)
        seconds = time.perf_counter() - t0
        errors = "  ".join(
            f"{n} {100 * (result.values[n] / getattr(reference, n) - 1):+.1f}% (±{100 * result.uncertainty[n] / getattr(reference, n):.1f})" for n in result.names
        )
        print(f"{shape} ({log.duration:.0f} s, travel {np.ptp(log.x) * 1e3:.0f} mm, rig {args.rig}): {seconds:.1f} s, {result.status}; {note}")
        print(f"    {errors}")
        print(
            f"    forward RMS (restarted at rests): fitted {result.forward_rms * 1e6:.0f} um = {result.forward_rms / reference.q_x:.2f} encoder steps "
            f"(max {result.forward_max * 1e6:.0f} um){'; voltage median-filtered' if result.voltage_filtered else ''}; true values, "
            f"free-running: {true_rms * 1e6:.0f} um; limit {result.forward_limit * 1e6:.0f} um -> {'accepted' if result.forward_ok else 'rejected (exit 3)'}",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
