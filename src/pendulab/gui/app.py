"""What the GUI's page asks the server, answered with pendulab's own API (no logic of its own).

Every function takes the page's form as plain JSON data and returns plain JSON data; a mistake in
the form raises :class:`~pendulab.errors.UserError` with the same message as the command line gives,
because the form is read by the same functions: :func:`pendulab.control.entry.controller_from_options`
for the controller, and a :class:`pendulab.spec.RunSpec` (its ``validate``) for the run.

The plant is the form's ``plant`` ("pendulum" or "seesaw"). The seesaw's controller is a state feedback:
an LQR designed from the typed Q and R (:func:`pendulab.control.state_feedback.design_from_text`, as
``pendulab lqr``), Quanser's by default, or a controller file that ``pendulab lqr --out`` wrote.

Heavy imports (numpy, python-control, CasADi) happen inside the functions: the server starts and draws
the first page before any of them is needed.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any, Mapping

from pendulab.errors import UserError

#: Most compensators besides the kernel (the lab's G2..G6).
MAX_COMPENSATORS = 5
#: Most samples of one signal sent to the page (a long run is thinned for drawing; files keep all).
MAX_POINTS = 20_000


def _text(form: Mapping[str, Any], key: str) -> str:
    value = form.get(key, "")
    return "" if value is None else str(value)


def _number(value: Any, what: str) -> float:
    try:
        number = float(str(value).strip())
    except ValueError:
        raise UserError(f"{what} {str(value)!r} is not a number; type a number such as 5 or 0.001") from None
    if not math.isfinite(number):
        raise UserError(f"{what} {value!r} must be a finite number")
    return number


def plant_kind(form: Mapping[str, Any]) -> str:
    """The form's plant: ``"pendulum"`` (default) or ``"seesaw"``."""
    kind = _text(form, "plant") or "pendulum"
    if kind not in ("pendulum", "seesaw"):
        raise UserError(f"plant {kind!r}: choose the pendulum or the seesaw")
    return kind


def parse_state_feedback_form(form: Mapping[str, Any]) -> Any:
    """The seesaw's controller: an LQR from the typed Q and R (``mode`` "lqr"), or a controller file's text
    (``mode`` "file", ``file`` = {"name", "text"}); ``pendulab lqr``'s rules and messages."""
    from pendulab.control.state_feedback import design_from_text, state_feedback_from_text

    if form.get("mode") == "file":
        upload = form.get("file") or {}
        name = Path(_text(upload, "name").replace("\\", "/")).name
        if not name:
            raise UserError("choose the controller file that 'pendulab lqr --plant seesaw --out FILE' wrote")
        design = state_feedback_from_text(_text(upload, "text"), name)
        if design.plant != "seesaw":
            raise UserError(f"controller file {name} is a state feedback for the {design.plant}; design one for the seesaw "
                            "with 'pendulab lqr --plant seesaw --out FILE' or type Q and R")
        return design
    return design_from_text("seesaw", _text(form, "q"), _text(form, "r"), bool(form.get("integral", True)))


def parse_controller_form(form: Mapping[str, Any]) -> Any:
    """The controller of the form: kernel plus compensators, or PID (the seesaw's: a state feedback); the
    command line's rules and messages."""
    from pendulab.control.entry import controller_from_options

    if plant_kind(form) == "seesaw":
        return parse_state_feedback_form(form)
    if form.get("mode") == "pid":
        pid = form.get("pid") or {}
        values = [_text(pid, k).strip() for k in ("kp", "ki", "kd")]
        for value, label in zip(values, ("Kp", "Ki", "Kd")):
            _number(value, f"PID {label}")  # the form's words, before the command line's
        # The PID in series with 1/(s - p): the unstable pole a PID needs to balance (README); empty: the PID alone.
        pole = _text(pid, "pole").strip()
        if pole:
            _number(pole, "the PID's unstable pole p")
        controller = controller_from_options(pid=",".join(values), compensators=[f"none;{pole}"] if pole else [])
    else:
        rows = [row for row in (form.get("compensators") or []) if any(_text(row, k).strip() for k in ("zeros", "poles", "gain"))]
        # As typed on the command line: --compensator "ZEROS;POLES;GAIN", read by the same parser.
        controller = controller_from_options(
            zeros=_text(form, "zeros"), poles=_text(form, "poles"), gain=_text(form, "gain").strip() or None,
            compensators=[f"{_text(row, 'zeros')};{_text(row, 'poles')};{_text(row, 'gain')}" for row in rows],
        )
    if controller is None:
        raise UserError("no controller given: type the kernel's zeros, poles and gain, or choose PID")
    return controller


def check_controller(form: Mapping[str, Any]) -> dict[str, Any]:
    """``{"ok": True, "describe": G(s) formatted, "factors": [...]}`` or ``{"ok": False, "error": message}``.

    The seesaw's: ``describe`` the law and K, ``states``, ``K``, ``closed_loop_poles`` (as ``pendulab lqr`` prints).
    """
    try:
        controller = parse_controller_form(form)
    except UserError as exc:
        return {"ok": False, "error": in_form_words(str(exc))}
    if plant_kind(form) == "seesaw":
        from pendulab.control.state_feedback import closed_loop_poles

        # A - B K of the seesaw's linear model (a controller file holds K only).
        poles = [complex(p) for p in closed_loop_poles(controller)]
        return {"ok": True, "describe": controller.describe(), "states": list(controller.states), "K": list(controller.K),
                "closed_loop_poles": [[p.real, p.imag] for p in poles], "q": list(controller.q),
                "r": controller.r if math.isfinite(controller.r) else None}
    labels = ["kernel"] + [f"compensator {i}" for i in range(1, len(controller.factors))]
    factors = [{"label": label, "text": f.describe()} for label, f in zip(labels, controller.factors)]
    return {"ok": True, "describe": str(controller), "factors": factors, "order": controller.order}


def plant_section(form: Mapping[str, Any], calibration_path: str | None) -> Any:
    """The run's :class:`~pendulab.spec.Plant`: the chosen pendulum and cart (the seesaw: its IP02 cart), the
    chosen calibration."""
    from pendulab.spec import Plant

    if plant_kind(form) == "seesaw":
        return Plant(kind="seesaw", calibration=str(calibration_path) if calibration_path else None)
    return Plant(pendulum=_text(form, "pendulum") or "long", cart=_text(form, "cart") or "ip02",
                 calibration=str(calibration_path) if calibration_path else None)


def plant_parameters(form: Mapping[str, Any], calibration_path: str | None) -> Any:
    """Plant parameters of the chosen pendulum and cart with the chosen calibration applied."""
    return plant_section(form, calibration_path).parameters()


#: The command line's option names -> the form's words, for messages of the checks both share.
FORM_WORDS = (("--stop-time", "the stop time"), ("--step", "control period"), ("--delay", "transport delay"),
              ("--poke magnitude", "poke magnitude"), ("--poke duration", "poke duration"), ("--poke", "poke"),
              ("--pid", "PID"), ("--gain K", "the kernel's gain"), ("--compensator", "compensator"),
              ("--q", "Q"), ("--r ", "R "), ("--integral", "the integral"))


def in_form_words(message: str) -> str:
    """A message of the command line's checks with the form's words for its options.

    Examples
    --------
    >>> in_form_words("--stop-time -1 must be a positive number of seconds")
    'the stop time -1 must be a positive number of seconds'
    """
    for option, words in FORM_WORDS:
        message = message.replace(option, words)
    return message


def run_spec(form: Mapping[str, Any], calibration_path: str | None) -> Any:
    """The run the whole form describes, validated; the first mistake raises UserError in the form's words."""
    try:
        return _run_spec(form, calibration_path)
    except UserError as exc:
        raise UserError(in_form_words(str(exc))) from None


def _run_spec(form: Mapping[str, Any], calibration_path: str | None) -> Any:
    from pendulab.spec import ControllerSpec, Poke, Quantization, RunSpec, Supervisor, Timing

    seesaw = plant_kind(form) == "seesaw"
    controller = parse_controller_form({**(form.get("controller") or {}), "plant": plant_kind(form)})
    stop_time = _number(form.get("stop_time", 5), "stop time")
    step = _number(form.get("step", 0.001), "control period")
    delay_value = _number(form.get("delay", 0), "transport delay")
    if delay_value != int(delay_value):
        raise UserError(f"transport delay {delay_value:g} must be a whole number of control periods")
    method = _text(form, "method") or "tustin"
    if method not in ("tustin", "zoh"):
        raise UserError(f"discretization {method!r}: choose tustin or zoh")
    timing = Timing(stop_time=stop_time, step=step, method=method, delay=int(delay_value))
    timing.validate()
    poke_form = form.get("poke") or {}
    word = "tap" if seesaw else "poke"  # the seesaw's disturbance is a tap on its track
    poke = Poke(*(_number(_text(poke_form, key), f"{word} {key}") for key in ("magnitude", "duration", "start")))
    poke.validate()
    poke.check_disturbs(f"{word} magnitude", f"{word} duration", word)
    if seesaw:  # the seesaw has no supervisor modes: the form hides them
        spec = RunSpec(ControllerSpec(state_feedback=controller), plant=plant_section(form, calibration_path), poke=poke, timing=timing,
                       quantization=Quantization(enabled=bool(form.get("quantization", True))))
        return spec.validate()
    # The supervisor's modes (issue 21); a swing-up starts hanging.
    swing_up = bool(form.get("swing_up"))
    plant = dataclasses.replace(plant_section(form, calibration_path), start="hanging" if swing_up else "upright")
    spec = RunSpec(controller, plant=plant, poke=poke, timing=timing,
                   quantization=Quantization(enabled=bool(form.get("quantization", True))),
                   supervisor=Supervisor(recentre=bool(form.get("recentre")), swing_up=swing_up))
    return spec.validate()


def linear_view(form: Mapping[str, Any], calibration_path: str | None) -> dict[str, Any]:
    """Root locus of ``Lp·C(s)·G(s)`` with the closed-loop poles, Bode plot and margins, sampled-loop verdict.

    The loop is the one ``pendulab tf --root-locus`` draws: the controller acts on ``e = -Lp·alpha``.
    The seesaw's state feedback has no single loop: :func:`seesaw_linear_view`.
    """
    import numpy as np

    from pendulab.analysis.plots import root_locus
    from pendulab.model.linear import linearize

    if plant_kind(form) == "seesaw":
        return seesaw_linear_view(form, calibration_path)
    controller = parse_controller_form(form.get("controller") or {})
    params = plant_parameters(form, calibration_path)
    if params.Mp == 0:
        raise UserError("the cart without a pendulum has no angle to linearize; choose the long or short pendulum")
    loop = controller.transfer_function() * linearize(params).tf("tip")
    rl = root_locus(loop)

    def points(values: Any) -> dict[str, list[float]]:
        values = np.asarray(values, dtype=complex)
        return {"re": values.real.tolist(), "im": values.imag.tolist()}

    # Branches with NaN breaks between them: one trace on the page.
    branches = [points(rl.loci[:, j]) for j in range(rl.loci.shape[1])]
    bode = _bode(loop)
    step, method = 0.001, "tustin"
    try:
        step = _number((form.get("step") or 0.001), "control period")
        method = _text(form, "method") or "tustin"
        delay = int(_number(form.get("delay", 0), "transport delay"))
    except UserError:
        delay = 0
    from pendulab.control.loop import linear_prediction

    # The sampled loop as simulated (one sample of computation plus the transport delay), and whether any
    # gain could balance: the same prediction 'pendulab simulate' prints.
    prediction = linear_prediction(controller, params, h=step, method=method if method in ("tustin", "zoh") else "tustin",
                                   delay=max(delay, 0))
    return {
        "branches": branches,
        "open_poles": points(rl.poles),
        "open_zeros": points(rl.zeros),
        "closed_poles": points(rl.closed),
        "stable": rl.stable,
        "view": list(rl.view),
        "bode": bode,
        "sampled_stable": prediction.stable,
        "sampled_max_abs_z": prediction.max_abs_z,
        "prediction": prediction.describe(),
        "never": prediction.never,
        "unstable_open_loop_poles": int(np.sum(np.asarray(rl.poles).real > 0)),
    }


def seesaw_linear_view(form: Mapping[str, Any], calibration_path: str | None) -> dict[str, Any]:
    """The seesaw's poles: open loop (its linear model) and closed by the state feedback (``A - B K`` of the
    continuous model, as ``pendulab lqr`` prints them; a controller file's K is placed on the same model).

    ``{"seesaw": True, "open_poles", "closed_poles", "stable", "view"}`` (poles as ``{"re": [...], "im": [...]}``).
    """
    import numpy as np

    from pendulab.control.state_feedback import closed_loop_poles
    from pendulab.model.seesaw import linearize_seesaw

    design = parse_controller_form({**(form.get("controller") or {}), "plant": "seesaw"})
    params = plant_section(form, calibration_path).parameters()
    open_poles = np.linalg.eigvals(linearize_seesaw(params).ss.A)
    closed = closed_loop_poles(design, params)
    both = np.concatenate([open_poles, closed])
    reach = float(np.max(np.abs(both))) * 1.15 + 1.0
    return {
        "seesaw": True,
        "open_poles": {"re": open_poles.real.tolist(), "im": open_poles.imag.tolist()},
        "closed_poles": {"re": closed.real.tolist(), "im": closed.imag.tolist()},
        "stable": bool(np.all(closed.real < 0)),
        "unstable_open_loop_poles": int(np.sum(open_poles.real > 0)),
        "view": [-reach, max(reach * 0.25, float(np.max(both.real)) * 1.2 + 1.0), reach * 0.6],
    }


def _bode(loop: Any) -> dict[str, Any]:
    import control
    import numpy as np

    omega = np.logspace(-1, 4, 400)
    response = control.frequency_response(loop, omega)
    mag = np.abs(np.asarray(response.complex).ravel())
    phase = np.degrees(np.unwrap(np.angle(np.asarray(response.complex).ravel())))
    gm, pm, _, wpc, wgc, _ = control.stability_margins(loop)

    def finite(x: float) -> float | None:
        return float(x) if x is not None and math.isfinite(x) else None

    return {
        "omega": omega.tolist(),
        "mag_db": (20 * np.log10(np.maximum(mag, 1e-300))).tolist(),
        "phase_deg": phase.tolist(),
        "gain_margin_db": finite(20 * math.log10(gm)) if gm and math.isfinite(gm) and gm > 0 else None,
        "phase_margin_deg": finite(pm),
        "phase_crossover_rad_s": finite(wpc),
        "gain_crossover_rad_s": finite(wgc),
    }


def run_data(folder: Path, label: str | None = None) -> dict[str, Any]:
    """Columns (thinned to :data:`MAX_POINTS`), poke start, metrics and files of a run folder or old-lab folder."""
    import numpy as np

    from pendulab.analysis.compare import load_compared
    from pendulab.analysis.results import json_safe

    run = load_compared(folder)
    n = run.columns["t"].size
    stride = max(1, math.ceil(n / MAX_POINTS))
    seesaw = "theta" in run.columns and "alpha" not in run.columns
    names = ("t", "theta", "x", "voltage") if seesaw else ("t", "alpha", "tip", "x", "voltage")
    columns = {k: np.asarray(run.columns[k], dtype=float)[::stride].tolist() for k in names if k in run.columns}
    meta_lp = None
    if "tip" in run.columns and "alpha" in run.columns:
        alpha, tip = np.asarray(run.columns["alpha"]), np.asarray(run.columns["tip"])
        big = np.abs(alpha) > 1e-6
        meta_lp = float(np.median(tip[big] / alpha[big])) if big.any() else None
    files = sorted(p.name for p in folder.iterdir() if p.is_file() and p.suffix.lower() in DOWNLOADABLE) if folder.is_dir() else []
    return {
        "label": label or run.label,
        "plant": "seesaw" if seesaw else "pendulum",
        "source": run.source,
        "poke_start": run.poke_start,
        "columns": columns,
        "metrics": json_safe(run.metrics),
        "files": files,
        "Lp": meta_lp,
    }


#: Files of a run folder the page may download.
DOWNLOADABLE = (".mat", ".csv", ".json", ".png", ".gif")


