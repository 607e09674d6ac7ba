#!/usr/bin/env python3
"""Issue 21's figures: the supervisor's re-centring and swing-up, in one reproducible run.

Sections (each prints a table; ``--out FILE`` also writes every number as JSON):

``recentre``
    The demo controller and the old lab's three PIDs, the lab's 220 rad/s^2, 5 ms poke at 1 s, 60 s, at
    ``--delay`` 0 and 2, with and without re-centring (``pendulab.simulate``, the product's own path): the
    safety cut, the largest |x|, the angle's NRMSE over the first second after the poke against the run
    without re-centring, the settling time, how long re-centring acted. For the PIDs, why none is held:
    the cart's speed right after the poke, and the cut time with re-centring many times stronger than
    the default (larger reference, faster slew).
``law``
    The re-centring law's trade-off on the demo (delay 0 and 2, the worse of the two): the reference's
    size (``recentre_r_max``) against acting on the cart position predicted ahead (``recentre_lead``), and a
    smoother engagement (slower slew): largest |x| (bar 0.30 m) and first-second NRMSE (bar 5 %).
``catch``
    The swing-up's hand-over window: the issue's 15 degrees (Quanser's) down to the 6 degrees used,
    at delay 0, 2 and 4: the catches, missed catches, how the run ends, largest |x| (bar 0.35 m).
``swing``
    The swing-up from hanging in simulation (the defaults, with re-centring), delay 0 and 2: the catch time
    (bar 15 s), the largest |x| (bar 0.35 m), how long it is held.
``lab`` (only with ``--lab``; real time, about 20 s each, best on a quiet machine)
    ``pendulab lab --demo --swing-up --recentre --delay 4 --stop-time 17`` against ``pendulab rig-emulator``
    and against the firmware twin (``rig-emulator --firmware``): the catch time, the largest |x|, held.

Usage::

    python bench/modes.py [--out numbers.json] [--lab] [--only recentre,law]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

import pendulab  # noqa: E402
from pendulab.control.controller import Controller, demo_controller  # noqa: E402
from pendulab.control.realization import discretize  # noqa: E402
from pendulab.cosim.master import Master  # noqa: E402
from pendulab.cosim.pendulum import pendulum_system  # noqa: E402
from pendulab.fmu.models.supervisor.config import RUNNING, SWINGING, TRIP_REASONS, TRIPPED  # noqa: E402
from pendulab.spec import Plant, Poke, RunSpec, Supervisor, Timing  # noqa: E402

OLD_LAB_PIDS = ((600.0, 200.0, 5.0), (750.0, 6.0, 10.0), (1200.0, 20.0, 20.0))
BIG_POKE = Poke(220.0, 0.005, 1.0)
RECORD = ("plant.x", "plant.alpha", "supervisor.r", "supervisor.state", "supervisor.trip_time", "supervisor.trip_reason",
          "supervisor.recentring", "supervisor.misses")


def controllers() -> dict[str, Controller]:
    return {"demo": demo_controller(), **{f"PID {kp:g},{ki:g},{kd:g}": Controller.pid(kp, ki, kd) for kp, ki, kd in OLD_LAB_PIDS}}


def first_second_nrmse(t: np.ndarray, alpha: np.ndarray, reference: np.ndarray) -> float:
    """The angle's RMS difference over the first second after the poke, over the reference's range there (%)."""
    w = (t >= BIG_POKE.start) & (t <= BIG_POKE.start + 1.0)
    return float(100 * np.sqrt(np.mean((alpha[w] - reference[w]) ** 2)) / np.ptp(reference[w]))


def run_with(spec: RunSpec, **supervisor: float) -> dict[str, np.ndarray]:
    """``spec`` simulated with Supervisor.fmu parameters beyond the RunSpec's (the same loop as pendulab.simulate)."""
    lti = discretize(spec.controller.transfer_function, h=spec.timing.step, method=spec.timing.method)
    system = pendulum_system(spec.parameters(), lti.to_parameters(), step=spec.timing.step, delay=spec.timing.delay,
                             supervisor={**spec.supervisor_parameters(), **supervisor}, initial_state=spec.initial_state())
    with Master(system) as master:
        return master.run(spec.timing.stop_time, list(RECORD))


def _seconds(value: float | None) -> str:
    return "-" if value is None else f"{value:.3f} s"


def cut_of(log: dict[str, np.ndarray]) -> float | None:
    t = float(log["supervisor.trip_time"][-1])
    return None if t < 0 else t


# ---------------------------------------------------------------- must-show 1
def recentre_section() -> list[dict]:
    rows = []
    print("\n== re-centring: 220 rad/s^2 poke at 1 s, 60 s (pendulab.simulate) ==")
    print(f"{'controller':<16} {'N':>2} {'cut without':>11} {'cut with':>9} {'|x| without':>11} {'|x| with':>9} {'NRMSE %':>8} "
          f"{'settle w/o':>10} {'settle with':>11} {'acted s':>8} {'dx/dt m/s':>9}")
    for name, controller in controllers().items():
        for delay in (0, 2):
            spec = RunSpec(controller, poke=BIG_POKE, timing=Timing(stop_time=60.0, delay=delay))
            without = pendulab.simulate(spec)
            with_ = pendulab.simulate(spec.replace(supervisor=Supervisor(recentre=True)))
            row = {
                "controller": name, "delay": delay,
                "cut_without_s": without.metrics["safety_cut_time_s"], "cut_with_s": with_.metrics["safety_cut_time_s"],
                "max_x_without_m": float(np.abs(without.columns["x"]).max()), "max_x_with_m": float(np.abs(with_.columns["x"]).max()),
                "nrmse_pct": first_second_nrmse(with_.columns["t"], with_.columns["alpha"], without.columns["alpha"]),
                "settling_without_s": without.metrics["settling_time_s"], "settling_with_s": with_.metrics["settling_time_s"],
                "stable_with": with_.metrics["stable"], "recentre_time_s": with_.metrics["recentre_time_s"],
                "cart_speed_after_poke_m_s": without.metrics["cart_speed_change_m_s"],
                "verdict_with": with_.verdict.headline(),
            }
            rows.append(row)

            def f(v, fmt="{:.3f}"):
                return "-" if v is None else fmt.format(v)

            print(f"{name:<16} {delay:>2} {f(row['cut_without_s']):>11} {f(row['cut_with_s']):>9} {row['max_x_without_m']:>11.3f} "
                  f"{row['max_x_with_m']:>9.3f} {row['nrmse_pct']:>8.2f} {f(row['settling_without_s']):>10} "
                  f"{f(row['settling_with_s']):>11} {f(row['recentre_time_s'], '{:.1f}'):>8} {f(row['cart_speed_after_poke_m_s'], '{:+.2f}'):>9}")
    print("\nThe PIDs with re-centring far stronger than the default (r up to 5 mm at 0.05 m/s): the cut time in 10 s, delay 0")
    strong = [(0.005, 0.05), (0.02, 0.5), (0.05, 1.0), (0.2, 2.0)]
    for name, controller in list(controllers().items())[1:]:
        spec = RunSpec(controller, poke=BIG_POKE, timing=Timing(stop_time=10.0), supervisor=Supervisor(recentre=True))
        cuts = []
        for r_max, slew in strong:
            log = run_with(spec, recentre_r_max=r_max, recentre_slew=slew, recentre_x_on=0.03)
            ref = pendulab.simulate(spec.replace(supervisor=Supervisor())).columns["alpha"]
            cuts.append({"r_max_m": r_max, "slew_m_s": slew, "cut_s": cut_of(log),
                         "reason": TRIP_REASONS[int(log["supervisor.trip_reason"][-1])], "max_abs_r_m": float(np.abs(log["supervisor.r"]).max()),
                         "nrmse_pct": first_second_nrmse(log["time"], log["plant.alpha"], ref)})
        rows.append({"controller": name, "strong_recentring": cuts})
        print(f"  {name:<16} " + "  ".join(f"|r|<={c['r_max_m'] * 1e3:g} mm @{c['slew_m_s']:g} m/s: cut {_seconds(c['cut_s'])} ({c['reason']}), NRMSE {c['nrmse_pct']:.0f} %"
                                        for c in cuts))
    return rows


def law_section() -> list[dict]:
    print("\n== re-centring law: the reference's size against acting on the predicted position (demo; worse of delay 0 and 2) ==")
    print(f"{'r_max mm':>8} {'lead s':>6} {'slew':>6} {'largest |x| m':>13} {'NRMSE %':>8}")
    rows = []
    demo = demo_controller()
    refs = {d: pendulab.simulate(RunSpec(demo, poke=BIG_POKE, timing=Timing(stop_time=60.0, delay=d))).columns["alpha"] for d in (0, 2)}
    # (the default slew 0.05 m/s; then a smoother engagement: the default size reached more slowly)
    settings = [(r_max, lead, 0.05) for r_max in (0.004, 0.005, 0.006) for lead in (0.0, 0.2, 0.5)]
    settings += [(0.005, 0.0, slew) for slew in (0.02, 0.01, 0.005)]
    for r_max, lead, slew in settings:
        worst_x = worst_e = 0.0
        cut = None
        for d in (0, 2):
            spec = RunSpec(demo, poke=BIG_POKE, timing=Timing(stop_time=60.0, delay=d), supervisor=Supervisor(recentre=True))
            log = run_with(spec, recentre_r_max=r_max, recentre_lead=lead, recentre_slew=slew)
            worst_x = max(worst_x, float(np.abs(log["plant.x"]).max()))
            worst_e = max(worst_e, first_second_nrmse(log["time"], log["plant.alpha"], refs[d]))
            cut = cut or cut_of(log)
        rows.append({"r_max_m": r_max, "lead_s": lead, "slew_m_s": slew, "max_x_m": worst_x, "nrmse_pct": worst_e, "cut_s": cut})
        print(f"{r_max * 1e3:>8.0f} {lead:>6.1f} {slew:>6.3f} {worst_x:>13.3f} {worst_e:>8.2f}" + ("" if cut is None else f"  cut at {cut} s"))
    return rows


# ---------------------------------------------------------------- must-show 2
def _swing_events(log: dict[str, np.ndarray]) -> dict:
    t, state = log["time"], log["supervisor.state"]
    catches = t[1:][(state[:-1] == SWINGING) & (state[1:] == RUNNING)]
    out = {"catches_s": [float(c) for c in catches], "misses": int(log["supervisor.misses"][-1]),
           "max_x_m": float(np.abs(log["plant.x"]).max()),
           "ends": "tripped: " + TRIP_REASONS[int(log["supervisor.trip_reason"][-1])] if state[-1] == TRIPPED
           else {RUNNING: "held", SWINGING: "still swinging"}.get(int(state[-1]), str(state[-1]))}
    if catches.size:
        after = t >= catches[-1]
        wrapped = np.angle(np.exp(1j * log["plant.alpha"][after]))
        out["max_alpha_after_catch_deg"] = float(np.degrees(np.abs(wrapped).max()))
        out["held_s"] = float(t[-1] - catches[-1]) if state[-1] == RUNNING and np.all(state[after] == RUNNING) else 0.0
    return out


def catch_section() -> list[dict]:
    print("\n== swing-up hand-over window (demo + re-centring, 30 s): |x| < 0.20 m, |dalpha/dt| < 150 deg/s, and |alpha| below ==")
    rows = []
    demo = demo_controller()
    for degrees in (15, 12, 10, 8, 6):
        for delay in (0, 2, 4):
            spec = RunSpec(demo, plant=Plant(start="hanging"), supervisor=Supervisor(swing_up=True, recentre=True),
                           timing=Timing(stop_time=30.0, delay=delay))
            row = {"catch_alpha_deg": degrees, "delay": delay, **_swing_events(run_with(spec, catch_alpha=math.radians(degrees)))}
            rows.append(row)
            print(f"{degrees:>3} deg  N={delay}: catches at {[round(c, 3) for c in row['catches_s']]}, {row['misses']} missed, ends {row['ends']}, "
                  f"largest |x| {row['max_x_m']:.3f} m" + (f", largest |alpha| after the last catch {row['max_alpha_after_catch_deg']:.1f} deg"
                                                             if "max_alpha_after_catch_deg" in row else ""))
    return rows


def swing_section() -> list[dict]:
    print("\n== swing-up in simulation (pendulab.simulate; demo + re-centring, 26 s) ==")
    rows = []
    for delay in (0, 2):
        spec = RunSpec(demo_controller(), plant=Plant(start="hanging"), supervisor=Supervisor(swing_up=True, recentre=True),
                       timing=Timing(stop_time=26.0, delay=delay))
        result = pendulab.simulate(spec)
        m, t, state = result.metrics, result.columns["t"], result.columns["supervisor_state"]
        held = float(t[-1] - m["catch_time_s"]) if m["catch_time_s"] is not None and np.all(state[t >= m["catch_time_s"]] == RUNNING) else 0.0
        row = {"delay": delay, "catch_time_s": m["catch_time_s"], "max_x_m": m["max_abs_x_m"], "missed": m["missed_catches"], "held_s": held}
        rows.append(row)
        print(f"N={delay}: caught at {row['catch_time_s']} s, largest |x| {row['max_x_m']:.3f} m, {row['missed']} missed, held {held:.1f} s (to the end)")
    return rows


#: lab's endings that are the host's or the link's (a loaded machine), not the modes': such a session is run again.
LINK_ENDINGS = ("watchdog tripped", "link lost", "the link is too slow")


def lab_section(tries: int = 3) -> list[dict]:
    print("\n== lab --swing-up --recentre against the emulator and the firmware twin (real time) ==")
    rows = []
    for rig, args in (("emulator", []), ("firmware twin", ["--firmware"])):
        for attempt in range(1, tries + 1):
            row = _lab_session(rig, args)
            row["attempt"] = attempt
            rows.append(row)
            if row["status"] == 0 or not any(words in row["ending"] for words in LINK_ENDINGS):
                break
    return rows


def _lab_session(rig: str, args: list[str]) -> dict:
    env = {**os.environ, "MPLBACKEND": "Agg", "PYTHONUNBUFFERED": "1"}
    with tempfile.TemporaryDirectory() as folder:
        emu = subprocess.Popen([sys.executable, "-m", "pendulab", "rig-emulator", *args], stdout=subprocess.PIPE,
                               stderr=subprocess.DEVNULL, text=True, env=env)
        try:
            port = emu.stdout.readline().strip()  # type: ignore[union-attr]
            out = Path(folder) / "lab"
            started = os.times()
            lab = subprocess.run([sys.executable, "-m", "pendulab", "lab", "--port", port, "--demo", "--swing-up", "--recentre",
                                  "--delay", "4", "--stop-time", "17", "--out", str(out)], input="s\n", capture_output=True,
                                 text=True, env=env, timeout=120)
        finally:
            emu.terminate()
            emu.wait(10)
        ending = (lab.stdout.strip().splitlines() or ["?"])[-1]
        ended = os.times()  # (the children's CPU: lab and the rig)
        cpu = ended.children_user + ended.children_system - started.children_user - started.children_system
        row: dict = {"rig": rig, "status": lab.returncode, "ending": ending, "children_cpu_s": cpu}
        metrics_file = out / "metrics.json"
        if metrics_file.is_file():
            m = json.loads(metrics_file.read_text())
            log = np.genfromtxt(out / "rig_log.csv", delimiter=",", names=True)
            catch = m.get("catch_time_s")
            held = 0.0
            if catch is not None:
                after = log["t"] >= catch
                held = float(log["t"][-1] - catch) if np.all(log["supervisor_state"][after] == RUNNING) else 0.0
            row.update(catch_time_s=catch, max_x_m=m.get("max_abs_x_m"), missed=m.get("missed_catches"), held_s=held,
                       end_reason=m.get("end_reason"))
        print(f"{rig}: exit {lab.returncode}, caught at {row.get('catch_time_s')} s, largest |x| {row.get('max_x_m') or float('nan'):.3f} m, "
              f"{row.get('missed')} missed, held {row.get('held_s', 0):.1f} s; {ending.split('; ended: ')[-1]}; "
              f"load average {os.getloadavg()[0]:.1f}")
        return row


SECTIONS = {"recentre": recentre_section, "law": law_section, "catch": catch_section, "swing": swing_section}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, help="write every number as JSON here")
    parser.add_argument("--lab", action="store_true", help="also the real-time lab sessions (emulator, firmware twin)")
    parser.add_argument("--only", help="comma-separated sections: " + ", ".join([*SECTIONS, "lab"]))
    args = parser.parse_args()
    chosen = args.only.split(",") if args.only else [*SECTIONS, *(["lab"] if args.lab else [])]
    numbers = {}
    for name in chosen:
        started = time.process_time()
        numbers[name] = lab_section() if name == "lab" else SECTIONS[name]()
        print(f"({name}: {time.process_time() - started:.1f} s CPU)")
    if args.out:
        args.out.write_text(json.dumps(numbers, indent=1, default=float))
        print(f"numbers written to {args.out}")


if __name__ == "__main__":
    main()
