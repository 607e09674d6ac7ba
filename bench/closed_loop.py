#!/usr/bin/env python3
"""The closed loop of the three native FMUs, 10 s at 1 kHz, beside Ecos and a plain-Python loop (SPEC §11).

Bars: pendulab's master runs the loop at >= 100x real time, and takes <= 1.5x the time Ecos takes
for the same FMUs.

All in one run, each variant repeated (``--repeats``, default 5) in turns, so that a change of the
machine's load hits every variant alike; the medians are compared:

* **native**: :class:`pendulab.cosim.master.Master` with its compiled plan runner, recording the 9
  signals of ``run.mat`` at every step (as ``pendulab simulate`` does); also recording nothing;
* **python loop**: the same plan stepped by the master's Python loop (cached ctypes pointers);
* **Ecos**: ``ecospy`` on the SSP export of the same system (the same FMUs and start values):
  ``EcosSimulation(ssp_path, step_size).init(parameter_set)`` then ``step_until(10)``. Ecos records
  nothing here (no CSV writer, no listener);
* **plain Python**: the same equations without FMUs: the CasADi plant stepped per 1 ms
  (:func:`pendulab.model.plant.step_function`, ten RK4 sub-steps) with its output function (encoder
  quantization, amplifier saturation), the same discrete controller in numpy, and the supervisor's
  angle/track check in Python, recording the same 9 signals.

Each variant is timed from loading the FMUs (unpacking, instantiation) to the end of the run
("total"), and the stepping alone ("run": for the master ``Master.run`` with its initialization,
for Ecos ``step_until``). Times are wall clock and process CPU time (all threads).

Usage::

    python bench/closed_loop.py [--repeats 5] [--stop-time 10]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

import numpy as np  # noqa: E402

from pendulab.control.controller import demo_controller  # noqa: E402
from pendulab.control.realization import discretize  # noqa: E402
from pendulab.cosim.master import Master, native_runner  # noqa: E402
from pendulab.cosim.pendulum import RECORDED, pendulum_system  # noqa: E402
from pendulab.cosim.ssp import PARAMETER_SET, export_ssp  # noqa: E402
from pendulab.fmu.models.supervisor.config import ALPHA_MAX_DEFAULT, RUNNING, TRIPPED, X_MAX_DEFAULT  # noqa: E402
from pendulab.model.parameters import PlantParameters  # noqa: E402
from pendulab.model.plant import PlantModel, step_function, substeps  # noqa: E402

H = 1e-3
RTF_BAR = 100.0
ECOS_BAR = 1.5


class Timing:
    def __init__(self) -> None:
        self.total_wall: list[float] = []
        self.total_cpu: list[float] = []
        self.run_wall: list[float] = []
        self.run_cpu: list[float] = []


def clocks() -> tuple[float, float]:
    return time.perf_counter(), time.process_time()


def master_variant(system, stop_time: float, native: bool, record: list[str]) -> Callable[[Timing], dict]:
    def once(timing: Timing) -> dict:
        w0, c0 = clocks()
        with Master(system, native=native) as master:
            w1, c1 = clocks()
            log = master.run(stop_time, record)
            w2, c2 = clocks()
        timing.total_wall.append(w2 - w0)
        timing.total_cpu.append(c2 - c0)
        timing.run_wall.append(w2 - w1)
        timing.run_cpu.append(c2 - c1)
        return log

    return once


def ecos_variant(ssp: Path, stop_time: float) -> Callable[[Timing], dict]:
    import ecospy

    def once(timing: Timing) -> dict:
        w0, c0 = clocks()
        with ecospy.EcosSimulation(ssp_path=str(ssp), step_size=H) as sim:
            if not sim.init(parameter_set=PARAMETER_SET):
                raise RuntimeError("Ecos could not initialize the SSP")
            w1, c1 = clocks()
            sim.step_until(stop_time)
            w2, c2 = clocks()
            final = {"plant.alpha": sim.get_real("plant::alpha"), "plant.x": sim.get_real("plant::x"),
                     "supervisor.state": sim.get_integer("supervisor::state"), "time": sim.get_time()}
            sim.terminate()
        timing.total_wall.append(w2 - w0)
        timing.total_cpu.append(c2 - c0)
        timing.run_wall.append(w2 - w1)
        timing.run_cpu.append(c2 - c1)
        return final

    return once


def plain_python_variant(params: PlantParameters, lti, stop_time: float) -> Callable[[Timing], dict]:
    """The loop of the same equations in Python: CasADi plant per step, numpy controller, Python supervisor."""

    def once(timing: Timing) -> dict:
        w0, c0 = clocks()
        n_sub = substeps(H)
        step = step_function(False, n_sub)  # ten RK4 sub-steps of the ONE CasADi model, as in Plant.fmu
        outputs = PlantModel().outputs  # encoder quantization, amplifier saturation, friction force
        p = np.asarray(params.as_vector(), dtype=float)
        A, B, C, D = lti.A, lti.B[:, 0], lti.C[0], float(lti.D[0, 0])
        n = int(round(stop_time / H))
        log = np.zeros((n + 1, 9))
        state = np.zeros(4)
        xc = np.zeros(lti.order)
        tripped = False
        w1, c1 = clocks()
        for k in range(n + 1):
            t = k * H
            y = outputs(state, 0.0, p, t).full().ravel()  # measured values do not depend on V
            alpha_m, x_m = y[0], y[1]
            e = -params.Lp * alpha_m
            command = float(C @ xc) + D * e
            if not tripped and (abs(alpha_m) > ALPHA_MAX_DEFAULT or abs(x_m) > X_MAX_DEFAULT or not np.isfinite(command)):
                tripped = True
            V = 0.0 if tripped else min(max(command, -10.0), 10.0)
            V_applied = outputs(state, V, p, t).full().ravel()[2]
            log[k] = (t, state[0], state[1], state[2], alpha_m, command, V_applied, TRIPPED if tripped else RUNNING, e)
            if k == n:
                break
            xc = A @ xc + B * e
            state = step(state, V, p, t, H / n_sub).full().ravel()
        w2, c2 = clocks()
        timing.total_wall.append(w2 - w0)
        timing.total_cpu.append(c2 - c0)
        timing.run_wall.append(w2 - w1)
        timing.run_cpu.append(c2 - c1)
        return {"time": log[:, 0], "plant.x": log[:, 1], "plant.alpha": log[:, 3], "supervisor.state": log[:, 7]}

    return once


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5, help="timed runs per variant (default 5)")
    parser.add_argument("--stop-time", type=float, default=10.0, help="simulated seconds (default 10)")
    args = parser.parse_args()
    stop_time, repeats = args.stop_time, args.repeats

    params = PlantParameters.preset()  # long pendulum, IP02, lab friction and encoders, poke 50 rad/s^2 at 1 s
    lti = discretize(demo_controller(), h=H)
    system = pendulum_system(params, lti.to_parameters(), step=H)
    record = list(RECORDED)
    if native_runner() is None:
        print("warning: no C compiler: the 'native' variant falls back to the Python loop")

    with tempfile.TemporaryDirectory(prefix="pendulab-bench-") as tmp:
        ssp = export_ssp(system, Path(tmp) / "loop.ssp", stop_time=stop_time)
        variants: dict[str, Callable[[Timing], dict]] = {
            f"pendulab native, {len(record)} signals": master_variant(system, stop_time, True, record),
            "pendulab native, nothing recorded": master_variant(system, stop_time, True, []),
            f"pendulab Python loop, {len(record)} signals": master_variant(system, stop_time, False, record),
            "Ecos (ecospy), nothing recorded": ecos_variant(ssp, stop_time),
            "plain Python (CasADi plant), 9 signals": plain_python_variant(params, lti, stop_time),
        }
        timings = {name: Timing() for name in variants}
        finals: dict[str, dict] = {}
        for name, once in variants.items():  # warm-up: libraries loaded, helper compiled, caches filled
            finals[name] = once(Timing())
        for _ in range(repeats):
            for name, once in variants.items():
                finals[name] = once(timings[name])

    print(f"closed loop plant -> controller -> supervisor -> plant, {stop_time:g} s at {1 / H:g} Hz "
          f"({int(round(stop_time / H))} steps), demo controller, long pendulum, poke at {params.poke_start:g} s; "
          f"median of {repeats} runs (load average {os.getloadavg()[0]:.1f})")
    print(f"{'variant':44s} {'total s':>8s} {'CPU s':>7s} {'run s':>7s} {'x real time':>12s} {'us/step':>8s}")
    steps = stop_time / H
    for name, t in timings.items():
        total = statistics.median(t.total_wall)
        print(f"{name:44s} {total:8.4f} {statistics.median(t.total_cpu):7.4f} {statistics.median(t.run_wall):7.4f}"
              f" {stop_time / total:12.0f} {1e6 * total / steps:8.2f}")

    ours = f"pendulab native, {len(record)} signals"
    names = list(variants)
    ecos, python_loop, plain = names[3], names[2], names[4]

    def med(name: str, kind: str) -> float:
        return statistics.median(getattr(timings[name], kind))

    print("\nratios (pendulab native, 9 signals recorded, against ...):")
    for kind, label in (("total_wall", "total, wall"), ("total_cpu", "total, CPU"), ("run_wall", "stepping only, wall")):
        ours_t = med(ours, kind)
        print(f"  {label:20s} Ecos {ours_t / med(ecos, kind):5.2f}x its time   Python loop {med(python_loop, kind) / ours_t:6.1f}x faster"
              f"   plain Python {med(plain, kind) / ours_t:6.1f}x faster")
    print("  (Ecos records nothing in this run; pendulab records 9 signals per step, the columns of run.mat)")

    rtf = stop_time / med(ours, "total_wall")
    rtf_cpu = stop_time / med(ours, "total_cpu")
    vs_ecos = med(ours, "total_wall") / med(ecos, "total_wall")
    vs_ecos_cpu = med(ours, "total_cpu") / med(ecos, "total_cpu")
    print(f"\nbar >= {RTF_BAR:g}x real time: {rtf:.0f}x (wall), {rtf_cpu:.0f}x (CPU) -> "
          f"{'meets' if min(rtf, rtf_cpu) >= RTF_BAR else 'MISSES'}")
    print(f"bar <= {ECOS_BAR:g}x the Ecos time: {vs_ecos:.2f}x (wall), {vs_ecos_cpu:.2f}x (CPU) -> "
          f"{'meets' if max(vs_ecos, vs_ecos_cpu) <= ECOS_BAR else 'MISSES'}")

    # Sanity: every variant ran the same loop and kept the pendulum up.
    print("\nsanity (end of the run):")
    for name, final in finals.items():
        if "plant.alpha" not in final:
            continue  # recorded nothing
        alpha = np.atleast_1d(final["plant.alpha"])
        state = int(np.atleast_1d(final["supervisor.state"])[-1])
        print(f"  {name:44s} t = {float(np.atleast_1d(final['time'])[-1]):6.3f} s, alpha = {alpha[-1]:+.4f} rad, "
              f"x = {float(np.atleast_1d(final['plant.x'])[-1]):+.4f} m, supervisor {'running' if state == RUNNING else state}")
    a = finals[ours]["plant.alpha"]
    b = finals[plain]["plant.alpha"]
    k = int(round((params.poke_start + 0.5) / H))
    print(f"  plain Python vs pendulab: max |alpha difference| over the first 0.5 s after the poke "
          f"{np.max(np.abs(a[:k] - b[:k])):.2e} rad (of a {np.max(np.abs(a[:k])):.3f} rad swing)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
