"""The interactive prompt of ``pendulab simulate``, driven by scripted answers."""

from __future__ import annotations

import pytest

from pendulab.control.controller import Controller, Factor, demo_controller
from pendulab.control.prompt import DEFAULT_POKE, prompt_simulation
from pendulab.errors import UserError
from pendulab.spec import Poke, RunSpec


class Script:
    """``ask``/``say`` for a list of answers; records every question and line shown."""

    def __init__(self, answers: list[str]) -> None:
        self.answers = list(answers)
        self.questions: list[str] = []
        self.said: list[str] = []

    def ask(self, question: str) -> str:
        self.questions.append(question)
        if not self.answers:
            raise EOFError
        return self.answers.pop(0)

    def say(self, text: str) -> None:
        self.said.append(text)

    def run(self) -> RunSpec:
        result = prompt_simulation(ask=self.ask, say=self.say)
        assert not self.answers, f"answers left over: {self.answers}"
        return result

    @property
    def errors(self) -> list[str]:
        return [line for line in self.said if line.strip().startswith("error:")]


DEFAULTS = ["", "", "", "", ""]  # pendulum, calibration, poke magnitude, duration, start
DEMO = ["-5", "7", "40000", "a", "-17", "-80", "", "a", "none", "-80", "", "f"]


def test_demo_controller_with_defaults():
    script = Script(DEMO + DEFAULTS)
    result = script.run()
    assert result == RunSpec(demo_controller(), poke=Poke(*DEFAULT_POKE))
    assert script.errors == []
    assert any("G(s) = G1(s)·G2(s)·G3(s)" in line for line in script.said)


def test_all_settings(tmp_path):
    calibration = tmp_path / "cal.json"
    calibration.write_text("{}")
    script = Script(["-1+2j, -1-2j", "-10, -20, 3", "-2.5", "F", "s", str(calibration), "220", "0.01", "0.5"])
    result = script.run()
    assert result.controller.transfer_function == Controller([Factor([complex(-1, 2), complex(-1, -2)], [-10, -20, 3], -2.5)])
    assert (result.plant.pendulum, result.plant.calibration, result.poke) == ("short", str(calibration), Poke(220.0, 0.01, 0.5))


def test_bad_answers_are_asked_again_with_the_error():
    script = Script(
        [
            "-3+-4j",  # kernel zeros: malformed
            "0",  # at the origin
            "-3+4j",  # no conjugate
            "-1",  # ok
            "1 2",  # kernel poles: missing comma
            "-2",  # ok
            "",  # kernel gain: required
            "abc",
            "0",  # zero gain
            "1+1j",  # complex gain
            "12",  # ok
            "x",  # menu: unknown
            "f",  # finish: fine, one zero one pole
            "medium",  # pendulum
            "l",
            str("/no/such/calibration.json"),
            "",
            "nan",  # magnitude
            "-50",  # negative magnitude is a poke the other way: accepted
            "-1",  # duration negative
            "0.002",
            "1e999",  # start
            "2",
        ]
    )
    result = script.run()
    assert result.controller.transfer_function == Controller.from_zpk([-1], [-2], 12)
    assert result.plant.pendulum == "long" and result.plant.calibration is None and result.poke == Poke(-50.0, 0.002, 2.0)
    errors = script.errors
    assert len(errors) == 14
    for fragment in ("'-3+-4j' is not a number", "exactly at s = 0", "no conjugate", "separate numbers with commas", "needs a gain",
                     "'abc' is not a number", "gain is 0", "complex", "unknown choice", "unknown pendulum", "does not exist",
                     "not finite", "negative"):
        assert any(fragment in e for e in errors), fragment
    assert all("\n" not in e for e in errors)


def test_improper_controller_is_refused_at_finish_then_fixed():
    script = Script(["-1, -2", "-3", "5", "f", "a", "none", "-50", "2", "f"] + DEFAULTS)
    result = script.run()
    assert any("improper" in e for e in script.errors)
    assert result.controller.transfer_function == Controller([Factor([-1, -2], [-3], 5), Factor([], [-50], 2)])


def test_start_over_discards_the_factors():
    script = Script(["-1", "-2", "3", "a", "-5", "-6", "", "s", "", "-9", "4", "finish"] + DEFAULTS)
    result = script.run()
    assert any("Starting over" in line for line in script.said)
    assert result.controller.transfer_function == Controller.from_zpk([], [-9], 4)


def test_at_most_five_compensators():
    answers = ["", "-1", "1"] + ["a", "", "-2", ""] * 5 + ["a", "f"] + DEFAULTS
    script = Script(answers)
    result = script.run()
    assert len(result.controller.transfer_function.factors) == 6
    assert any("already 6 factors" in e for e in script.errors)


@pytest.mark.parametrize("cut", [0, 2, 5, 11])
def test_end_of_input_during_the_controller(cut):
    script = Script(DEMO[:cut])
    with pytest.raises(UserError) as excinfo:
        script.run()
    assert str(excinfo.value) == "input ended before the controller was complete"


@pytest.mark.parametrize("cut", [0, 3])
def test_end_of_input_after_the_controller(cut):
    script = Script(DEMO + DEFAULTS[:cut])
    with pytest.raises(UserError, match="input ended before the simulation settings were complete"):
        script.run()


def test_an_ask_returning_none_counts_as_end_of_input():
    with pytest.raises(UserError, match="input ended"):
        prompt_simulation(ask=lambda q: None, say=lambda t: None)  # type: ignore[arg-type,return-value]
