#!/usr/bin/env python3
"""Cost of one 1 ms co-simulation step of Plant.fmu, beside fmpy's own call overhead (SPEC §11).

Bar: one 1 ms step (ten RK4 sub-steps of 0.1 ms) costs at most 2 us (median).

Everything is measured in this one run, so the ratios hold on any machine:

* ``fmi2DoStep`` called through ctypes directly: the cached function pointer with prebuilt
  arguments, in a tight loop of ``--steps`` steps, timed per batch; the median over ``--repeats``
  batches;
* the same loop calling a trivial FMI function (``fmi2SetReal`` of one variable) instead: the cost of
  a ctypes call from a Python loop. Subtracting it leaves the step itself;
* fmpy's own wrappers (``FMU2Slave.doStep``, ``setReal``, ``getReal`` of one variable): what a
  plain fmpy master pays per call;
* a small C host calling ``fmi2DoStep`` through ``dlopen`` (when a C compiler is present): the
  native step cost with no Python in between, as the master's compiled plan runner sees it.

Each batch is timed twice: wall clock (``time.perf_counter_ns``) and the thread's CPU time
(``time.thread_time_ns``; ``CLOCK_THREAD_CPUTIME_ID`` in C). On a shared, loaded machine the wall
clock also counts the time the process waited for a core; the CPU time does not, so the verdict
uses it. On an idle machine the two agree.

Usage::

    python bench/plant_step.py [--steps 20000] [--repeats 7]
"""

from __future__ import annotations

import argparse
import ctypes
import math
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

from fmpy import extract, read_model_description  # noqa: E402
from fmpy.fmi2 import FMU2Slave  # noqa: E402

from pendulab.fmu.build import FMI_HEADERS, ensure_fmu  # noqa: E402

BAR_NS = 2000.0
STEP = 1e-3

C_HOST = r"""
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "fmi2Functions.h"

static double ns(clockid_t clock) { struct timespec t; clock_gettime(clock, &t); return 1e9 * t.tv_sec + t.tv_nsec; }

int main(int argc, char **argv) {
    void *lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    fmi2CallbackFunctions cb = {NULL, calloc, free, NULL, NULL};
    fmi2ValueReference alpha_ref = (fmi2ValueReference)atoi(argv[3]);
    int steps = atoi(argv[4]), repeats = atoi(argv[5]), r, k;
    double alpha = 3.14159265358979 + 0.2, t = 0, wall, cpu;
    fmi2Component c;
    fmi2DoStepTYPE *do_step;
    if (!lib) { fprintf(stderr, "%s\n", dlerror()); return 2; }
    c = ((fmi2InstantiateTYPE *)dlsym(lib, "fmi2Instantiate"))("plant", fmi2CoSimulation, argv[2], "", &cb, 0, 0);
    if (!c) return 3;
    ((fmi2SetupExperimentTYPE *)dlsym(lib, "fmi2SetupExperiment"))(c, 0, 0, 0, 0, 0);
    ((fmi2EnterInitializationModeTYPE *)dlsym(lib, "fmi2EnterInitializationMode"))(c);
    ((fmi2SetRealTYPE *)dlsym(lib, "fmi2SetReal"))(c, &alpha_ref, 1, &alpha);
    if (((fmi2ExitInitializationModeTYPE *)dlsym(lib, "fmi2ExitInitializationMode"))(c) != fmi2OK) return 4;
    do_step = (fmi2DoStepTYPE *)dlsym(lib, "fmi2DoStep");
    for (r = 0; r < repeats; r++) {
        wall = ns(CLOCK_MONOTONIC); cpu = ns(CLOCK_THREAD_CPUTIME_ID);
        for (k = 0; k < steps; k++) { if (do_step(c, t, 1e-3, fmi2True) != fmi2OK) return 5; t += 1e-3; }
        printf("%.3f %.3f\n", (ns(CLOCK_MONOTONIC) - wall) / steps, (ns(CLOCK_THREAD_CPUTIME_ID) - cpu) / steps);
    }
    return 0;
}
"""


class Timing:
    """Per-call nanoseconds of each batch, by wall clock and by the thread's CPU time."""

    def __init__(self) -> None:
        self.wall: list[float] = []
        self.cpu: list[float] = []

    def add(self, wall_ns: float, cpu_ns: float, calls: int) -> None:
        self.wall.append(wall_ns / calls)
        self.cpu.append(cpu_ns / calls)

    def median(self, cpu: bool = True) -> float:
        return statistics.median(self.cpu if cpu else self.wall)


def timed_batches(loop: Callable[[int], None], calls: int, repeats: int) -> Timing:
    """Run ``loop(calls)`` once to warm up, then ``repeats`` timed times."""
    timing = Timing()
    loop(calls)
    for _ in range(repeats):
        w0, c0 = time.perf_counter_ns(), time.thread_time_ns()
        loop(calls)
        timing.add(time.perf_counter_ns() - w0, time.thread_time_ns() - c0, calls)
    return timing


def native_timing(so: Path, guid: str, alpha_ref: int, steps: int, repeats: int) -> Timing | None:
    compiler = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if not compiler or not sys.platform.startswith("linux"):
        return None
    with tempfile.TemporaryDirectory() as tmp:
        source, host = Path(tmp) / "host.c", Path(tmp) / "host"
        source.write_text(C_HOST)
        subprocess.run([compiler, "-O2", "-std=gnu99", f"-I{FMI_HEADERS}", str(source), "-o", str(host), "-ldl"],
                       check=True, capture_output=True)
        out = subprocess.run([str(host), str(so), guid, str(alpha_ref), str(steps), str(repeats + 1)],
                             check=True, capture_output=True, text=True).stdout
    timing = Timing()
    for line in out.splitlines()[1:]:  # the first batch is the warm-up
        wall, cpu = map(float, line.split())
        timing.add(wall, cpu, 1)
    return timing


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20000, help="steps per timed batch (default 20000)")
    parser.add_argument("--repeats", type=int, default=7, help="timed batches per measurement (default 7)")
    args = parser.parse_args()
    steps, repeats = args.steps, args.repeats

    fmu_path = ensure_fmu("Plant", progress=print)
    md = read_model_description(str(fmu_path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    with tempfile.TemporaryDirectory(prefix="pendulab-bench-") as tmp:
        unzipdir = extract(str(fmu_path), unzipdir=tmp)
        fmu = FMU2Slave(guid=md.guid, modelIdentifier="Plant", unzipDirectory=unzipdir, instanceName="plant")
        fmu.instantiate()
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.setReal([vr["alpha"]], [math.pi + 0.2])  # a swinging pendulum, lab friction on: a realistic state
        fmu.exitInitializationMode()
        c = fmu.component

        # The raw C entry points with prebuilt arguments (what a fast master calls), in tight loops that
        # differ only in the function called, so that their difference is the step itself.
        do_step = fmu._functions["fmi2DoStep"]
        set_real = fmu._functions["fmi2SetReal"]
        ref = (ctypes.c_uint * 1)(vr["V"])
        value = (ctypes.c_double * 1)(0.0)
        clock = {"t": 0.0}

        def raw_steps(n: int) -> None:
            t = clock["t"]
            for _ in range(n):
                do_step(c, t, STEP, 1)
                t += STEP
            clock["t"] = t

        def raw_trivial_calls(n: int) -> None:
            t = 0.0
            for _ in range(n):
                set_real(c, ref, 1, value)
                t += STEP

        def fmpy_steps(n: int) -> None:
            t = clock["t"]
            for _ in range(n):
                fmu.doStep(t, STEP)
                t += STEP
            clock["t"] = t

        def fmpy_set(n: int) -> None:
            for _ in range(n):
                fmu.setReal([vr["V"]], [0.0])

        def fmpy_get(n: int) -> None:
            for _ in range(n):
                fmu.getReal([vr["alpha"]])

        fmpy_calls = max(1, steps // 4)
        timings = {
            "fmi2DoStep via ctypes (1 ms step)": timed_batches(raw_steps, steps, repeats),
            "fmi2SetReal(1 var) via ctypes (call overhead)": timed_batches(raw_trivial_calls, steps, repeats),
            "fmpy FMU2Slave.doStep": timed_batches(fmpy_steps, fmpy_calls, repeats),
            "fmpy FMU2Slave.setReal(1 var)": timed_batches(fmpy_set, fmpy_calls, repeats),
            "fmpy FMU2Slave.getReal(1 var)": timed_batches(fmpy_get, fmpy_calls, repeats),
        }
        final = fmu.getReal([vr["x"], vr["alpha"]])
        fmu.terminate()
        fmu.freeInstance()
        native = native_timing(Path(unzipdir) / "binaries" / "linux64" / "Plant.so", md.guid, vr["alpha"], steps, repeats)
    if native:
        timings["fmi2DoStep from C (dlopen, no Python)"] = native

    print(f"Plant.fmu, one {STEP * 1e3:g} ms co-simulation step = 10 RK4 sub-steps of 0.1 ms; "
          f"{steps} calls per batch ({fmpy_calls} for fmpy's wrappers), median of {repeats} batches")
    print(f"{'per call':48s} {'CPU ns':>9s} {'wall ns':>9s} {'min CPU':>9s}")
    for name, timing in timings.items():
        print(f"{name:48s} {timing.median():9.0f} {timing.median(cpu=False):9.0f} {min(timing.cpu):9.0f}")

    def ratios(label: str, cost: float, overhead: float, fmpy_call: float) -> None:
        print(f"{label:30s} {cost:7.0f} ns = {cost / BAR_NS:5.2f} x bar (2 us) = {cost / overhead:5.2f} x ctypes call"
              f" = {cost / fmpy_call:5.2f} x fmpy getReal")

    for cpu in (True, False):
        gross = timings["fmi2DoStep via ctypes (1 ms step)"].median(cpu)
        overhead = timings["fmi2SetReal(1 var) via ctypes (call overhead)"].median(cpu)
        fmpy_call = timings["fmpy FMU2Slave.getReal(1 var)"].median(cpu)
        print(f"\nratios by {'CPU time' if cpu else 'wall clock'}:")
        ratios("step through ctypes", gross, overhead, fmpy_call)
        ratios("step minus ctypes call", gross - overhead, overhead, fmpy_call)
        if native:
            ratios("step native (C host)", native.median(cpu), overhead, fmpy_call)

    step_cost = native.median() if native else (
        timings["fmi2DoStep via ctypes (1 ms step)"].median() - timings["fmi2SetReal(1 var) via ctypes (call overhead)"].median()
    )
    verdict = "meets" if step_cost <= BAR_NS else "MISSES"
    source = "native C host" if native else "ctypes minus the call overhead"
    print(f"\nthe step itself ({source}, CPU time): {step_cost:.0f} ns median -> {verdict} the 2 us bar")
    print(f"(sanity: after the runs x = {final[0]:.4f} m, alpha = {final[1]:.4f} rad; load average {os.getloadavg()[0]:.1f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
