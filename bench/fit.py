#!/usr/bin/env python3
"""Least-squares fit of a 60 s ramp-test log at 1 kHz (SPEC §11, issue "Calibration" must-show 3).

Bar: < 20 s (issue 8), parameters within 5 % (Beq and the force gain within 5 %, F1 within 10 %).
The fit's forward check (a replay of the whole log under the true stick-slip law) is printed too.

A synthetic log is made on the virtual rig with known parameters (non-default friction, Beq and
force gain), Gaussian position noise (10 um) and the encoder's quantization (22.75 um). The fit
starts from the lab defaults, as ``fit_parameters(logs, PlantParameters.preset("none"))`` does.

Measured in the same run, so that the ratios hold on any machine:

* **baseline**: one plain forward simulation of the same log with the reference integrator
  (``PlantModel().simulate``: the plant's RK4 with 0.1 ms sub-steps, the logged voltage held per
  sample) -- what replaying the log once costs;
* **fit, cold**: the first fit on a machine, including compiling its shooting functions to C (an
  empty cache folder);
* **fit, warm**: the same fit again, with the compiled functions cached (every later fit).

Each is timed by wall clock and by this process's CPU time; on a loaded machine the wall clock also
counts the time spent waiting for a core.

Usage::

    python bench/fit.py [--duration 60] [--seed 1]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

BAR_S = 20.0


def timed(function):
    wall, cpu = time.perf_counter(), time.process_time()
    value = function()
    return value, time.perf_counter() - wall, time.process_time() - cpu


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=60.0, help="log length (s), default 60")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()

    from pendulab.calibration.fit import fit_parameters
    from pendulab.calibration.synthetic import TEST_RIG, synthetic_ramp_log
    from pendulab.model.parameters import PlantParameters
    from pendulab.model.plant import PlantModel

    true = TEST_RIG
    start = PlantParameters.preset("none")
    log = synthetic_ramp_log(true, duration=args.duration, noise=1e-5, seed=args.seed)
    print(f"log: {log.duration:.1f} s, {len(log)} samples at {1 / log.period:.0f} Hz, noise 10 um + encoder step {true.q_x * 1e6:.2f} um")

    _, base_wall, base_cpu = timed(lambda: PlantModel().simulate(true, log.V[:-1], log.period, (log.x[0], 0, 0, 0)))
    print(f"baseline, one forward simulation (PlantModel.simulate): {base_wall:6.2f} s wall, {base_cpu:6.2f} s CPU")

    results = {}
    with tempfile.TemporaryDirectory(prefix="pendulab-bench-cache-") as cache:
        os.environ["PENDULAB_CACHE"] = cache
        for label in ("cold", "warm"):
            result, wall, cpu = timed(lambda: fit_parameters([log], start))
            results[label] = (result, wall, cpu)
            print(
                f"fit, {label} ({'compiles its C functions' if label == 'cold' else 'compiled functions cached'}): "
                f"{wall:6.2f} s wall, {cpu:6.2f} s CPU, {result.iterations} IPOPT iterations ({result.status}); "
                f"{wall / base_wall:.2f}x the baseline"
            )
    result = results["warm"][0]
    print(f"\n{'parameter':<11}{'true':>10}{'start':>10}{'fitted':>11}{'± 1 sigma':>11}{'error':>9}")
    errors = {}
    for name in result.names:
        truth = getattr(true, name)
        errors[name] = result.values[name] / truth - 1
        print(
            f"{name:<11}{truth:>10.4g}{result.initial[name]:>10.4g}{result.values[name]:>11.4g}"
            f"{result.uncertainty[name]:>11.2g}{100 * errors[name]:>8.2f}%"
        )
    print(f"residual RMS {result.residual_rms * 1e6:.1f} um")
    print(
        f"forward check: replay RMS {result.forward_rms * 1e6:.0f} um, max {result.forward_max * 1e6:.0f} um "
        f"(accepted up to {result.forward_limit * 1e6:.0f} um: {'accepted' if result.forward_ok else 'REJECTED, exit 3'})"
    )

    cold_wall = results["cold"][1]
    worst = max(abs(e) for e in errors.values())
    must = abs(errors["Beq"]) < 0.05 and abs(errors["force_gain"]) < 0.05 and abs(errors["F1"]) < 0.10
    print(f"\nbar: fit < {BAR_S:.0f} s -> cold {cold_wall:.1f} s, warm {results['warm'][1]:.1f} s: {'PASS' if cold_wall < BAR_S else 'FAIL'}")
    print(f"bar: Beq, force gain within 5 %, F1 within 10 %: {'PASS' if must else 'FAIL'}")
    print(f"     every fitted parameter within 5 % (largest error {100 * worst:.1f} %): {'PASS' if worst < 0.05 else 'FAIL'}")
    return 0 if cold_wall < BAR_S and must else 1


if __name__ == "__main__":
    sys.exit(main())
