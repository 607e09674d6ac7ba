"""The interactive prompt of ``pendulab simulate``: controller, pendulum, calibration file, poke.

The questions go through two callables, ``ask(prompt) -> str`` and ``say(text)``, so the prompt runs
the same on a terminal (``input`` / ``print``), in a test (scripted answers) or behind another UI.
A bad answer is never fatal: the one-line error is shown and the question asked again. The end of
the input (``EOFError``) raises a :class:`~pendulab.errors.UserError`.

Examples
--------
>>> from pendulab.control.prompt import prompt_simulation
>>> answers = iter(["-5", "7", "40000", "a", "-17", "-80", "", "a", "", "-80", "", "f", "", "", "", "", ""])
>>> spec = prompt_simulation(ask=lambda q: next(answers), say=lambda text: None)
>>> print(spec.controller.transfer_function)
40000 (s + 5)(s + 17) / ((s - 7)(s + 80)^2)
>>> spec.plant.pendulum, spec.plant.calibration, spec.poke
('long', None, Poke(magnitude=50.0, duration=0.005, start=1.0))
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Callable, TypeVar

from pendulab.control.controller import MAX_FACTORS, Controller, Factor, Number, parse_numbers, to_number
from pendulab.errors import ControllerError, UserError
from pendulab.spec import Poke, RunSpec

T = TypeVar("T")

#: Poke defaults (SPEC §2): magnitude rad/s², duration s, start s (the spec's).
DEFAULT_POKE = (Poke().magnitude, Poke().duration, Poke().start)
PENDULUMS = ("long", "short")

INTRO = (
    "Enter the controller G(s) = G1(s)·G2(s)·…·Gn(s), n <= 6: the kernel G1 and then compensators,\n"
    "each as zeros, poles and gain. Separate numbers with commas, write complex ones as -3+4j (in\n"
    "conjugate pairs); leave blank for none. No pole or zero exactly at 0: use 1/(s+0.1) for an\n"
    "integrator. The controller acts on the tip error e = -Lp*alpha; a positive gain pushes the cart\n"
    "under a falling pendulum."
)


class _Dialogue:
    def __init__(self, ask: Callable[[str], str], say: Callable[[str], None]) -> None:
        self._ask, self.say = ask, say
        self.eof_message = "input ended before the controller was complete"

    def question(self, prompt: str, parse: Callable[[str], T]) -> T:
        """Ask until ``parse`` accepts the answer."""
        while True:
            try:
                answer = self._ask(prompt)
            except EOFError:
                raise UserError(self.eof_message) from None
            if answer is None:
                raise UserError(self.eof_message)
            try:
                return parse(str(answer).strip())
            except UserError as exc:
                self.say(f"  error: {exc}")


def _roots(kind: str, label: str) -> Callable[[str], list[Number]]:
    def parse(text: str) -> list[Number]:
        values = parse_numbers(text, f"{label} {kind}s")
        # Check them now (nothing at 0, conjugate pairs) so that only this answer is asked again.
        factor = Factor(values, (), label=label) if kind == "zero" else Factor((), values, label=label)
        return list(factor.zeros if kind == "zero" else factor.poles)

    return parse


def _gain(label: str, default: float | None) -> Callable[[str], float]:
    def parse(text: str) -> float:
        if not text:
            if default is None:
                raise ControllerError(f"the {label} needs a gain; type a non-zero number, e.g. 40000")
            return default
        return Factor((), (), to_number(text, f"{label} gain"), label=label).gain

    return parse


def _choice(text: str) -> str:
    word = text.lower() or "f"
    for option in ("add", "start", "finish"):
        if option.startswith(word) or (option == "start" and "start over".startswith(word)):
            return option
    raise UserError(f"unknown choice {text!r}; type a (add a compensator), s (start over) or f (finish)")


def _pendulum(text: str) -> str:
    word = text.lower() or "long"
    for name in PENDULUMS:
        if name.startswith(word):
            return name
    raise UserError(f"unknown pendulum {text!r}; type long or short (blank for long)")


def _calibration(text: str) -> str | None:
    if not text:
        return None
    path = Path(text).expanduser()
    if not path.is_file():
        raise UserError(f"calibration file {text!r} does not exist; give the path of a calibration file or leave blank for the default")
    return text


def _poke_value(name: str, default: float, *, minimum: float | None) -> Callable[[str], float]:
    def parse(text: str) -> float:
        if not text:
            return default
        value = to_number(text, f"poke {name}")
        if isinstance(value, complex):
            raise UserError(f"poke {name} {text!r} is complex; give a real number")
        if minimum is not None and value < minimum:
            raise UserError(f"poke {name} {value:g} is negative; give a value >= {minimum:g}")
        return float(value)

    return parse


def _enter_factor(d: _Dialogue, label: str, title: str, gain_default: float | None) -> Factor:
    zeros = d.question(f"{title} zeros: ", _roots("zero", label))
    poles = d.question(f"{title} poles: ", _roots("pole", label))
    suffix = " [1]" if gain_default is not None else ""
    gain = d.question(f"{title} gain{suffix}: ", _gain(label, gain_default))
    return Factor(zeros, poles, gain, label=label)


def _enter_controller(d: _Dialogue) -> Controller:
    while True:  # one pass per "start over"
        factors = [_enter_factor(d, "kernel", "Kernel", None)]
        d.say(f"  G1(s) = {factors[0].describe()}")
        while True:
            choice = d.question("[a]dd compensator / [s]tart over / [f]inish (default f): ", _choice)
            if choice == "start":
                d.say("Starting over.")
                break
            if choice == "add":
                if len(factors) >= MAX_FACTORS:
                    d.say(f"  error: already {MAX_FACTORS} factors (a kernel and {MAX_FACTORS - 1} compensators); finish or start over")
                    continue
                i = len(factors)
                factors.append(_enter_factor(d, f"compensator {i}", f"Compensator {i}", 1.0))
                d.say(f"  G{i + 1}(s) = {factors[-1].describe()}")
                continue
            try:
                controller = Controller(factors)
            except UserError as exc:
                d.say(f"  error: {exc}")
                continue
            d.say(controller.describe())
            return controller


def prompt_simulation(
    ask: Callable[[str], str] = input,
    say: Callable[[str], None] = print,
    *,
    base: RunSpec | None = None,
) -> RunSpec:
    """Ask for the controller, pendulum, calibration file and poke: the run they describe.

    Parameters
    ----------
    ask : callable
        ``ask(prompt) -> answer``; raises ``EOFError`` at the end of the input (as :func:`input`).
    say : callable
        Shows a line of text (explanations, errors, the controller entered).
    base : RunSpec, optional
        The run's other settings (timing, cart, ...); the answers replace its controller, pendulum,
        calibration and poke.

    Returns
    -------
    RunSpec

    Raises
    ------
    UserError
        The input ended before all answers were given.
    """
    base = base or RunSpec()
    d = _Dialogue(ask, say)
    say(INTRO)
    controller = _enter_controller(d)
    d.eof_message = "input ended before the simulation settings were complete"
    pendulum = d.question("Pendulum length, long or short [long]: ", _pendulum)
    calibration = d.question("Calibration file [default]: ", _calibration)
    magnitude = d.question(f"Poke magnitude in rad/s^2 [{DEFAULT_POKE[0]:g}]: ", _poke_value("magnitude", DEFAULT_POKE[0], minimum=None))
    duration = d.question(f"Poke duration in s [{DEFAULT_POKE[1]:g}]: ", _poke_value("duration", DEFAULT_POKE[1], minimum=0.0))
    start = d.question(f"Poke start time in s [{DEFAULT_POKE[2]:g}]: ", _poke_value("start time", DEFAULT_POKE[2], minimum=0.0))
    plant = dataclasses.replace(base.plant, pendulum=pendulum, calibration=calibration)
    return base.replace(controller=controller, plant=plant, poke=Poke(magnitude, duration, start))


def prompt_controller(
    ask: Callable[[str], str] = input,
    say: Callable[[str], None] = print,
) -> Controller:
    """Ask for the controller alone (``pendulab lab``: the rig is the plant, a person pokes it)."""
    d = _Dialogue(ask, say)
    say(INTRO)
    return _enter_controller(d)
