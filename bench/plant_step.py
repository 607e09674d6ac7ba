#!/usr/bin/env python3
"""Cost of one 1 ms co-simulation step of Plant.fmu, beside fmpy's own call overhead (SPEC §11).

Bar: one 1 ms step (ten RK4 sub-steps of 0.1 ms) costs at most 2 us (median).

Everything is measured in this one run, so the ratios hold on any machine:

* ``fmi2DoStep`` called through ctypes directly: the cached function pointer with prebuilt
  arguments, in a tight loop of ``--steps`` steps, timed per batch with ``time.perf_counter_ns``;
  the median over ``--repeats`` batches;
* the same loop calling a trivial FMI function (``fmi2SetReal`` of one variable), the cost of a
  ctypes call from a Python loop; subtracting it leaves the step itself;
* fmpy's own wrappers (``FMU2Slave.doStep``, ``setReal``, ``getReal`` of one variable), what a
  plain fmpy master pays per call;
* a small C host calling ``fmi2DoStep`` through ``dlopen`` (when a C compiler is present): the
  native step cost without any Python in between, as the compiled plan runner of the master sees it.

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

static double now_ns(void) { struct timespec t; clock_gettime(CLOCK_MONOTONIC, &t); return 1e9 * t.tv_sec + t.tv_nsec; }

int main(int argc, char **argv) {
    void *lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    fmi2CallbackFunctions cb = {NULL, calloc, free, NULL, NULL};
    fmi2ValueReference alpha_ref = (fmi2ValueReference)atoi(argv[3]);
    int steps = atoi(argv[4]), repeats = atoi(argv[5]), r, k;
    double alpha = 3.14159265358979 + 0.2, t = 0, t0;
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
        t0 = now_ns();
        for (k = 0; k < steps; k++) { if (do_step(c, t, 1e-3, fmi2True) != fmi2OK) return 5; t += 1e-3; }
        printf("%.3f\n", (now_ns() - t0) / steps);
    }
    return 0;
}
"""


def batches(call: Callable[[int], None], steps: int, repeats: int) -> list[float]:
    """Mean ns per call of ``call(k)`` for k in range(steps), once per repeat (after one warm-up batch)."""
    call_range = range(steps)
    results = []
    for r in range(repeats + 1):
        t0 = time.perf_counter_ns()
        for k in call_range:
            call(k)
        elapsed = time.perf_counter_ns() - t0
        if r:
            results.append(elapsed / steps)
    return results


def native_step_ns(so: Path, guid: str, alpha_ref: int, steps: int, repeats: int) -> list[float] | None:
    compiler = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if not compiler:
        return None
    with tempfile.TemporaryDirectory() as tmp:
        source, host = Path(tmp) / "host.c", Path(tmp) / "host"
        source.write_text(C_HOST)
        subprocess.run([compiler, "-O2", "-std=gnu99", f"-I{FMI_HEADERS}", str(source), "-o", str(host), "-ldl"],
                       check=True, capture_output=True)
        out = subprocess.run([str(host), str(so), guid, str(alpha_ref), str(steps), str(repeats + 1)],
                             check=True, capture_output=True, text=True).stdout
    return [float(v) for v in out.split()][1:]


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

        # The raw C entry points with prebuilt arguments (what a fast master calls).
        do_step = fmu._functions["fmi2DoStep"]
        set_real = fmu._functions["fmi2SetReal"]
        ref = (ctypes.c_uint * 1)(vr["V"])
        value = (ctypes.c_double * 1)(0.0)
        clock = {"t": 0.0}

        def raw_step(k: int) -> None:
            do_step(c, clock["t"], STEP, 1)
            clock["t"] += STEP

        def raw_trivial(k: int) -> None:
            set_real(c, ref, 1, value)

        def fmpy_step(k: int) -> None:
            fmu.doStep(clock["t"], STEP)
            clock["t"] += STEP

        measurements = {
            "fmi2DoStep via ctypes (1 ms step)": batches(raw_step, steps, repeats),
            "fmi2SetReal(1 var) via ctypes (call overhead)": batches(raw_trivial, steps, repeats),
            "fmpy FMU2Slave.doStep": batches(fmpy_step, steps // 4, repeats),
            "fmpy FMU2Slave.setReal(1 var)": batches(lambda k: fmu.setReal([vr["V"]], [0.0]), steps // 4, repeats),
            "fmpy FMU2Slave.getReal(1 var)": batches(lambda k: fmu.getReal([vr["alpha"]]), steps // 4, repeats),
        }
        final = fmu.getReal([vr["x"], vr["alpha"]])
        fmu.terminate()
        fmu.freeInstance()
        native = native_step_ns(Path(unzipdir) / "binaries" / "linux64" / "Plant.so", md.guid, vr["alpha"], steps, repeats) \
            if sys.platform.startswith("linux") else None

    med = {name: statistics.median(v) for name, v in measurements.items()}
    print(f"Plant.fmu, one {STEP * 1e3:g} ms co-simulation step = 10 RK4 sub-steps; "
          f"{steps} calls per batch, median of {repeats} batches ({sum(len(v) for v in measurements.values())} batches in all)")
    print(f"{'measurement':48s} {'median ns':>10s} {'min ns':>10s}")
    for name, values in measurements.items():
        print(f"{name:48s} {med[name]:10.0f} {min(values):10.0f}")
    if native:
        print(f"{'fmi2DoStep from C (dlopen, no Python)':48s} {statistics.median(native):10.0f} {min(native):10.0f}")

    gross = med["fmi2DoStep via ctypes (1 ms step)"]
    overhead = med["fmi2SetReal(1 var) via ctypes (call overhead)"]
    net = gross - overhead
    fmpy_call = med["fmpy FMU2Slave.getReal(1 var)"]
    print()
    print(f"step through ctypes          {gross:8.0f} ns   = {gross / BAR_NS:5.2f} x bar (2 us)   = {gross / overhead:5.2f} x ctypes call   = {gross / fmpy_call:5.2f} x fmpy getReal")
    print(f"step minus ctypes call       {net:8.0f} ns   = {net / BAR_NS:5.2f} x bar (2 us)   = {net / overhead:5.2f} x ctypes call   = {net / fmpy_call:5.2f} x fmpy getReal")
    if native:
        nat = statistics.median(native)
        print(f"step native (C host)         {nat:8.0f} ns   = {nat / BAR_NS:5.2f} x bar (2 us)   = {nat / overhead:5.2f} x ctypes call   = {nat / fmpy_call:5.2f} x fmpy getReal")
    step_cost = statistics.median(native) if native else net
    verdict = "meets" if step_cost <= BAR_NS else "MISSES"
    print(f"\nthe step itself ({'native' if native else 'ctypes minus call overhead'}): {step_cost:.0f} ns median -> {verdict} the 2 us bar "
          f"(one fmpy getReal costs {fmpy_call / step_cost:.2f} steps)")
    print(f"(sanity: after the runs x = {final[0]:.4f} m, alpha = {final[1]:.4f} rad)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
