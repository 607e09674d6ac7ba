"""``pendulab simulate``: enter a controller, simulate a poke, write the results."""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pendulab.cli.options import (
    add_controller_options,
    add_mode_options,
    add_overwrite_option,
    add_plant_options,
    controller_from_args,
    plant_from_args,
)
from pendulab.errors import UserError
from pendulab.outputs import run_folder

if TYPE_CHECKING:
    from pendulab.spec import RunSpec


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "simulate",
        help="simulate a poke of the pendulum with your controller",
        description=(
            "Simulate the lab: plant, controller and supervisor FMUs in co-simulation, poke the pendulum, and write "
            "run.mat, run.csv and metrics.json. With no controller given on a terminal, asks for one."
        ),
        epilog=(
            "examples (the first four balance both pendulums with no warning):\n"
            "  pendulab simulate --demo\n"
            "  pendulab simulate --zeros=-6 --poles=6.4 --gain 45000 --compensator '-16;-80' --compensator ';-80' --plot\n"
            "  pendulab simulate --controller my_controller.toml --pendulum short --animate\n"
            "  pendulab simulate --pid 300,100,100 --compensator 'none;4'   (a PID alone cannot balance: see README)\n"
            "  pendulab simulate --demo --poke 220,0.005,1 --stop-time 60 --delay 2 --recentre\n"
            "  pendulab simulate --demo --start hanging --swing-up --stop-time 20 --plot\n"
            "  pendulab simulate --plant seesaw --demo --plot"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_controller_options(parser)
    parser.add_argument("--plant", choices=("pendulum", "seesaw"), default="pendulum",
                        help="plant (default pendulum); the seesaw runs a state feedback: --demo (Quanser's LQR) or "
                             "--controller FILE from 'pendulab lqr --plant seesaw --out FILE'")
    add_plant_options(parser)
    parser.add_argument("--poke", metavar="MAG,DUR,START",
                        help="poke magnitude (rad/s^2), duration (s), start (s); default 50,0.005,1 (the seesaw's tap: 3.3,0.1,1)")
    parser.add_argument("--stop-time", type=float, default=5.0, metavar="T", help="simulated time in s (default 5)")
    parser.add_argument("--step", type=float, default=1e-3, metavar="H", help="control period in s (default 0.001)")
    parser.add_argument("--method", choices=("tustin", "zoh"), default="tustin", help="discretization (default tustin)")
    parser.add_argument("--delay", type=int, default=0, metavar="N",
                        help="transport delay of N control periods before the plant, as on the rig (default 0; compare with a rig run at its N)")
    parser.add_argument("--no-quantization", action="store_true", help="ideal encoders (no quantization)")
    add_mode_options(parser)
    parser.add_argument("--out", type=Path, metavar="DIR", help="output folder (default: a new folder under runs/)")
    add_overwrite_option(parser)
    parser.add_argument("--plot", action="store_true", help="also write PNG plots")
    parser.add_argument("--animate", action="store_true", help="also write an animation (GIF) of the rig")
    parser.add_argument("--ssp", nargs="?", const="Plant", choices=("Plant", "Plant3"), metavar="PLANT",
                        help="also write the loop as an SSP file (loop.ssp), with the FMI 2.0 plant (Plant, default) "
                             "or the FMI 3.0 one (--ssp Plant3)")
    parser.add_argument("--robust", type=int, metavar="N",
                        help="also run the controller on N plausible rigs (the calibration's spread or the documented defaults) "
                             "and say on how many it balances, with a 95 %% confidence interval; the worst rig's run is saved "
                             "in DIR/worst/, the rigs' table in DIR/robust/")
    parser.add_argument("--robust-seed", type=int, default=1, metavar="S", help="seed of the --robust rigs (default 1)")
    parser.set_defaults(func=run)


def parse_poke(text: str) -> tuple[float, float, float]:
    """``MAG,DUR,START`` as three numbers, checked (:meth:`pendulab.spec.Poke.parse`)."""
    from pendulab.spec import Poke

    return dataclasses.astuple(Poke.parse(text))  # type: ignore[return-value]


def spec_from_args(args: argparse.Namespace) -> RunSpec:
    """The run the options describe (asking on a terminal when no controller is given), validated."""
    from pendulab.spec import Poke, Quantization, RunSpec, Supervisor, Timing

    timing = Timing(stop_time=args.stop_time, step=args.step, method=args.method, delay=args.delay)
    timing.validate()
    poke = Poke.parse(args.poke) if args.poke else None
    if args.plant == "seesaw":
        return seesaw_spec_from_args(args, timing, poke)
    if args.pendulum == "none":
        raise UserError("simulate needs a pendulum: --pendulum none is the cart alone, which has nothing to balance "
                        "(for the cart alone use 'pendulab calibrate --virtual'); choose --pendulum long or short")
    controller = controller_from_args(args)
    spec = RunSpec(controller, plant=plant_from_args(args, start=args.start), poke=poke or Poke(), timing=timing,
                   quantization=Quantization(enabled=not args.no_quantization),
                   supervisor=Supervisor(recentre=args.recentre, swing_up=args.swing_up))
    if controller is None:
        if not sys.stdin.isatty():
            raise UserError("no controller given: use --demo, --zeros/--poles/--gain, --pid or --controller FILE (or run on a terminal to be asked)")
        from pendulab.control.prompt import prompt_simulation

        asked = prompt_simulation(base=spec)
        # Flags given on the command line win over the answers' defaults.
        plant = dataclasses.replace(asked.plant, calibration=asked.plant.calibration or spec.plant.calibration)
        spec = asked.replace(plant=plant, poke=poke or asked.poke)
    spec.poke.check_disturbs()  # with no disturbance the run would test nothing
    return spec.validate()


def seesaw_spec_from_args(args: argparse.Namespace, timing: Any, poke: Any) -> RunSpec:
    """The seesaw's run: a state feedback (--demo: Quanser's LQR, or --controller FILE), the tap (``simulate``, ``lab``)."""
    from pendulab.control.state_feedback import design_state_feedback, load_state_feedback_file
    from pendulab.cosim.seesaw import TAP_DEFAULT
    from pendulab.spec import ControllerSpec, Plant, Poke, Quantization, RunSpec, Supervisor

    others = [flag for flag, given in (("--zeros/--poles/--gain", args.zeros is not None or args.poles is not None or args.gain is not None),
                                       ("--pid", args.pid is not None), ("--compensator", bool(args.compensator))) if given]
    if others:
        raise UserError(f"the seesaw runs a state feedback, not {others[0]}: use --demo (Quanser's LQR) or "
                        "--controller FILE from 'pendulab lqr --plant seesaw --out FILE'")
    if args.demo == bool(args.controller):
        raise UserError("--plant seesaw needs one controller: --demo (Quanser's LQR) or --controller FILE from 'pendulab lqr --plant seesaw --out FILE'")
    if args.recentre or args.swing_up or getattr(args, "start", "upright") != "upright" or args.pendulum != "long":
        raise UserError("--recentre, --swing-up, --start and --pendulum are the pendulum's; the seesaw has none of them")
    design = design_state_feedback("seesaw") if args.demo else load_state_feedback_file(args.controller)
    if poke is not None:
        poke.check_disturbs(what="tap")  # with no tap the run would test nothing
    spec = RunSpec(
        ControllerSpec(state_feedback=design),
        plant=Plant(kind="seesaw", cart=args.cart, calibration=str(args.calibration) if args.calibration else None),
        poke=poke or Poke(*TAP_DEFAULT),
        timing=timing,
        quantization=Quantization(enabled=not getattr(args, "no_quantization", False)),
        supervisor=Supervisor(),
    )
    return spec.validate()


def run(args: argparse.Namespace) -> int:
    started = time.perf_counter()
    if args.robust is not None and args.robust < 1:
        raise UserError(f"--robust {args.robust}: give the number of plausible rigs, at least 1 (e.g. --robust 200)")
    spec = spec_from_args(args)
    params = spec.parameters()
    seesaw = spec.plant.kind == "seesaw"
    if seesaw and args.ssp not in (None, "Plant"):
        raise UserError(f"--ssp {args.ssp}: the seesaw's loop has one plant FMU, Seesaw.fmu; give --ssp alone")
    folder = run_folder(args.out, "seesaw" if seesaw else spec.plant.pendulum, overwrite=args.overwrite)
    out_dir = folder.path

    from pendulab.cosim.master import SimulationError
    from pendulab.simulation import simulate

    prediction = None
    if not seesaw and spec.controller.transfer_function is not None:
        # The linear check comes before the simulation: a controller that can never balance is named now.
        from pendulab.control.loop import linear_prediction

        timing = spec.timing
        prediction = linear_prediction(spec.controller.transfer_function, params, h=timing.step, method=timing.method, delay=timing.delay)
        if prediction.never:
            print(f"before simulating: {prediction.never}", file=sys.stderr)

    def progress(t: float) -> None:
        if sys.stderr.isatty():
            print(f"\r  simulated {t:5.1f} / {spec.timing.stop_time:g} s", end="", file=sys.stderr, flush=True)

    try:
        result = simulate(spec, progress=progress)
    except SimulationError as exc:
        # An FMU refused the inputs (e.g. a poke so large that the state overflows): nothing is written.
        raise UserError(f"the simulation failed: {exc}; check the controller, the poke and the parameters") from None
    if sys.stderr.isatty():
        print("\r" + " " * 40 + "\r", end="", file=sys.stderr)
    folder.prepare(announce=lambda line: print(line, file=sys.stderr))  # stdout starts with the verdict
    written = list(result.write(out_dir).values())
    if args.plot:
        from pendulab.analysis.plots import plot_run

        written += plot_run(
            result.columns, out_dir, title=f"{'seesaw' if seesaw else spec.plant.pendulum + ' pendulum'}: {result.meta['controller']}",
            poke_start=None if spec.supervisor.swing_up else spec.poke.start,
            safety_cut_time=result.metrics.get("safety_cut_time_s"), voltage_limit=params.V_max,
        )
    if args.animate and seesaw:
        from pendulab.analysis.animation import animate_seesaw

        written.append(animate_seesaw(result.columns, out_dir / "rig.gif", tap_start=spec.poke.start))
    elif args.animate:
        from pendulab.analysis.animation import animate_run

        written.append(animate_run(result.columns, out_dir / "rig.gif", Lp=params.Lp, poke_start=params.poke_start) or out_dir / "rig.gif")
    if args.ssp and seesaw:
        from pendulab.cosim.ssp import export_ssp
        from pendulab.simulation import build_system

        written.append(export_ssp(build_system(spec, params), out_dir / "loop.ssp", stop_time=spec.timing.stop_time))
    elif args.ssp:
        from pendulab.control.realization import discretize
        from pendulab.cosim.pendulum import pendulum_system
        from pendulab.cosim.ssp import export_ssp

        timing = spec.timing
        system = pendulum_system(params, discretize(spec.controller.transfer_function, h=timing.step, method=timing.method).to_parameters(),
                                 step=timing.step, delay=timing.delay, plant=args.ssp)
        written.append(export_ssp(system, out_dir / "loop.ssp", stop_time=timing.stop_time))
    _print_summary(result, prediction, out_dir, written, time.perf_counter() - started)
    if args.robust:
        _robust(args, spec, out_dir)
    return 0


def _robust(args: argparse.Namespace, spec: Any, out_dir: Path) -> None:
    """``--robust N``: the controller on N plausible rigs, one line, the worst rig's run saved in DIR/worst/."""
    from pendulab.cli.sweep import ProgressBar
    from pendulab.simulation import simulate
    from pendulab.sweep.robust import robustness

    bar = ProgressBar()
    answer = robustness(spec, args.robust, out_dir / "robust", seed=args.robust_seed, progress=bar)
    bar.end()
    print(answer.line())
    worst = answer.worst
    if worst is None:
        return
    inputs = {name: worst[name] for name in answer.sweep_spec.input_names}
    result = simulate(answer.sweep_spec.run_spec(inputs), meta={"robust_rig": {"sample": worst["sample"], **inputs}})
    result.write(out_dir / "worst")
    drawn = ", ".join(f"{k}={v:.4g}" for k, v in inputs.items())
    print(f"worst rig ({worst['status']}): rig {worst['sample']} ({drawn}); its run is in {out_dir / 'worst'}/")


def _fmt(value: Any, unit: str = "", digits: int = 4) -> str:
    if value is None:
        return "n/a"
    if isinstance(value, bool):
        return "yes" if value else "no"
    return f"{value:.{digits}g}{unit}"


def _metric_line(label: str, m: dict[str, Any], key: str, unit: str) -> str:
    """``  label   value`` or ``  label   n/a (why it is not reported)``."""
    value = m.get(key)
    why = (m.get("not_reported") or {}).get(key) if value is None else None
    return f"  {label:<19} {_fmt(value, unit)}" + (f" ({why})" if why else "")


def _print_summary(result: Any, prediction: Any, out_dir: Path, written: list[Path], elapsed: float) -> None:
    m = result.metrics
    verdict = result.verdict
    # The first line is the verdict: the outcome and the worst warnings; the warnings follow, one a line.
    print("\n".join(verdict.lines()))
    if verdict.plant == "seesaw":
        _print_seesaw(result)
        print(f"results in {out_dir}/ ({', '.join(p.name for p in written)}) after {elapsed:.1f} s")
        return
    if prediction is not None:
        agrees = prediction.agrees_with(verdict.outcome)
        print(f"  {prediction.describe()}: {'agrees with' if agrees else 'DISAGREES with'} the simulation"
              + ("" if agrees else _disagreement(prediction, verdict)))
        if prediction.never:
            print(f"  {prediction.never}")
    print(f"  controller          {result.meta['controller']}")
    print(_metric_line("natural frequency", m, "natural_frequency_rad_s", " rad/s"))
    print(_metric_line("peak time", m, "peak_time_s", " s"))
    amplitude, frequency = m.get("limit_cycle_amplitude_rad"), m.get("limit_cycle_frequency_rad_s")
    if amplitude is not None and frequency is not None:
        # A sustained oscillation: name it rather than print an overshoot and a settling time that
        # describe it badly. Its cause is read from the voltage: friction and quantization at small
        # voltages, or a loop that chatters at the voltage limit.
        chatters = verdict is not None and any(w.kind == "chattering" for w in verdict.warnings)
        cause = "the loop chatters at the voltage limit" if chatters else "friction and quantization"
        print(f"  limit cycle         ±{math.degrees(amplitude):.2f}° ({amplitude * 1e3:.3g} mrad) at {frequency:.3g} rad/s "
              f"(sustained oscillation: {cause})")
        if m.get("overshoot_percent") is not None:
            print(_metric_line("overshoot", m, "overshoot_percent", " %"))
    else:
        print(_metric_line("overshoot", m, "overshoot_percent", " %"))
        print(_metric_line("settling time", m, "settling_time_s", " s"))
    print(f"  final angle         {_fmt(m.get('final_value_rad'), ' rad')}")
    print(f"  cart speed change   {_fmt(m.get('cart_speed_change_m_s'), ' m/s')} (mean speed over the last second minus before the poke)")
    if "max_abs_x_m" in m:
        print(f"  largest |x|         {_fmt(m.get('max_abs_x_m'), ' m')}")
    if result.meta.get("swing_up"):
        print(f"  swing-up            started {_fmt(m.get('swing_start_s'), ' s')}, caught {_fmt(m.get('catch_time_s'), ' s')}"
              f" ({m.get('missed_catches', 0)} missed; the response above is measured from the catch)")
    if result.meta.get("recentre"):
        print(f"  re-centring         acted for {_fmt(m.get('recentre_time_s'), ' s')} in {len(m.get('recentre_intervals_s', []))} interval(s)")
    for line in result.meta.get("mode_events", []):
        print(f"  {line}")
    print(f"results in {out_dir}/ ({', '.join(p.name for p in written)}) after {elapsed:.1f} s")


def _print_seesaw(result: Any) -> None:
    """The seesaw's tap response under its verdict: the peak, the settling within 2°, what is left, the cart."""
    from pendulab.analysis.verdict import TILT_BAND

    m = result.metrics
    params = result.spec.parameters()
    why = m.get("not_reported") or {}

    def deg(value: float | None) -> str:
        return "n/a" if value is None else f"{math.degrees(value):.2f}°"

    print(f"  controller          {result.meta['controller']}")
    print(f"  tap                 {params.tap_magnitude:g} rad/s² for {params.tap_duration:g} s at {params.tap_start:g} s")
    peak_time = result.verdict.measures.get("peak_tilt_time_s")
    print(f"  peak tilt           {deg(m.get('peak_tilt_rad'))}" + (f" at {peak_time:.3f} s after the tap" if peak_time is not None else ""))
    band = f"{math.degrees(TILT_BAND):.0f}°"
    settled = m.get("tilt_settling_time_s")
    print(f"  settled within {band}   " + (f"{settled:.3f} s after the tap" if settled is not None else f"n/a ({why.get('tilt_settling_time_s', '')})"))
    if m.get("residual_tilt_rad") is not None:
        print(f"  last second         within {deg(m['residual_tilt_rad'])} of level")
    amplitude, frequency = m.get("limit_cycle_amplitude_rad"), m.get("limit_cycle_frequency_rad_s")
    if amplitude is not None and frequency is not None:
        cause = "friction and quantization" if params.q_theta > 0 else "friction (the encoders are ideal in this run)"
        print(f"  limit cycle         ±{math.degrees(amplitude):.2f}° at {frequency:.3g} rad/s (sustained oscillation: {cause})")
    elif "limit_cycle_amplitude_rad" in why:
        print(f"  limit cycle         n/a ({why['limit_cycle_amplitude_rad']})")
    print(_metric_line("natural frequency", m, "natural_frequency_rad_s", " rad/s"))
    print(_metric_line("overshoot", m, "overshoot_percent", " %"))
    x_max = result.verdict.measures.get("x_max")
    if m.get("max_abs_x_m") is not None:
        print(f"  largest |x|         {m['max_abs_x_m']:.3f} m" + (f" (the supervisor cuts at {x_max:.2f} m)" if x_max else ""))


def _disagreement(prediction: Any, verdict: Any) -> str:
    """Why the linear loop and the simulation can disagree, in this case's terms."""
    if not prediction.stable and verdict.outcome == "balanced":
        return (" (the linear loop is unstable; saturation and friction hold it in a bounded oscillation"
                + (" that chatters" if any(w.kind == "chattering" for w in verdict.warnings) else "")
                + ": do not expect the rig to behave like the linear design)")
    if prediction.stable and verdict.outcome == "cut":
        return " (the linear loop is stable, but it does not hold the cart: the cut is the track limit)"
    return " (the nonlinear plant (saturation, friction, the poke's size) leaves the linear model's range)"
