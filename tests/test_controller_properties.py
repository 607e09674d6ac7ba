"""Property tests: malformed or forbidden controllers give a ControllerError and nothing else; valid ones round-trip."""

from __future__ import annotations

import json
import math
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from pendulab.control.controller import (
    MAX_FACTORS,
    Controller,
    Factor,
    parse_compensator,
    parse_controller,
    parse_numbers,
    to_number,
)
from pendulab.control.files import load_controller_file
from pendulab.control.prompt import prompt_simulation
from pendulab.control.realization import discretize
from pendulab.errors import ControllerError, UserError

#: Cheap inputs (text, scalars): many examples; whole controllers cost more to generate: fewer.
SETTINGS = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
FEWER = settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])

# ------------------------------------------------------------------------------ strategies
#: Text that looks like numbers often enough to reach the deep branches of the parser.
number_chars = st.text(alphabet="0123456789.+-eEjJi ,()[]nafINF_;\t", max_size=30)
any_text = st.one_of(number_chars, st.text(max_size=30))

magnitudes = st.floats(min_value=1e-3, max_value=1e4, allow_nan=False, allow_infinity=False)
signs = st.sampled_from([-1.0, 1.0])
real_roots = st.builds(lambda m, s: [m * s], magnitudes, signs)
pair_roots = st.builds(
    lambda re, im: [complex(re, im), complex(re, -im)],
    st.floats(min_value=-1e3, max_value=1e3, allow_nan=False).filter(lambda v: v != 0 or True),
    magnitudes,
)
root_lists = st.lists(st.one_of(real_roots, pair_roots), max_size=3).map(lambda groups: [r for g in groups for r in g])
gains = st.builds(lambda m, s: m * s, st.floats(min_value=1e-6, max_value=1e6, allow_nan=False), signs)
factors = st.builds(lambda z, p, k: Factor(z, p, k), root_lists, root_lists, gains)


@st.composite
def valid_controllers(draw) -> Controller:
    chosen = draw(st.lists(factors, min_size=1, max_size=MAX_FACTORS))
    n_zeros = sum(len(f.zeros) for f in chosen)
    n_poles = sum(len(f.poles) for f in chosen)
    assume(n_zeros <= n_poles)
    return Controller(chosen)


json_scalars = st.one_of(
    st.none(), st.booleans(), st.integers(min_value=-(10**30), max_value=10**30), st.floats(), number_chars, st.text(max_size=10)
)
json_values = st.recursive(
    json_scalars,
    lambda children: st.lists(children, max_size=4) | st.dictionaries(st.sampled_from(["zeros", "poles", "gain", "kernel", "x"]), children, max_size=4),
    max_leaves=12,
)
factor_dicts = st.dictionaries(st.sampled_from(["zeros", "poles", "gain", "extra"]), json_values, max_size=4)
controller_dicts = st.one_of(
    json_values,
    st.fixed_dictionaries({"kernel": factor_dicts}, optional={"compensators": st.lists(factor_dicts, max_size=7) | json_values}),
)


def assert_clean(error: Exception) -> None:
    assert isinstance(error, ControllerError) and isinstance(error, UserError)
    message = str(error)
    assert message and "\n" not in message and len(message) < 400


# ------------------------------------------------------------------------------ malformed input
@SETTINGS
@given(any_text)
def test_parse_numbers_never_fails_otherwise(text):
    try:
        values = parse_numbers(text)
    except ControllerError as exc:
        assert_clean(exc)
    else:
        assert all(isinstance(v, (float, complex)) and abs(v) <= 2e100 for v in values)


@SETTINGS
@given(any_text)
def test_parse_compensator_never_fails_otherwise(text):
    try:
        factor = parse_compensator(text)
    except ControllerError as exc:
        assert_clean(exc)
    else:
        assert isinstance(factor, Factor) and factor.gain != 0


@SETTINGS
@given(st.one_of(json_values, st.complex_numbers(allow_nan=True), st.tuples(st.floats(), st.floats()), st.integers()))
def test_to_number_never_fails_otherwise(value):
    try:
        number = to_number(value)
    except ControllerError as exc:
        assert_clean(exc)
    else:
        assert math.isfinite(complex(number).real) and math.isfinite(complex(number).imag)


@SETTINGS
@given(controller_dicts)
def test_from_dict_never_fails_otherwise(data):
    try:
        controller = Controller.from_dict(data)
    except ControllerError as exc:
        assert_clean(exc)
    else:
        assert 1 <= len(controller.factors) <= MAX_FACTORS


@settings(max_examples=100, deadline=None)
@given(st.binary(max_size=200), st.sampled_from([".toml", ".json"]))
def test_controller_files_never_fail_otherwise(content, suffix):
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / f"c{suffix}"
        path.write_bytes(content)
        try:
            load_controller_file(path)
        except ControllerError as exc:
            assert_clean(exc)
            assert str(path) in str(exc)


@settings(max_examples=100, deadline=None)
@given(st.lists(any_text, max_size=25))
def test_prompt_never_crashes(answers):
    queue = list(answers)

    def ask(question: str) -> str:
        if not queue:
            raise EOFError
        return queue.pop(0)

    try:
        result = prompt_simulation(ask=ask, say=lambda text: None)
    except UserError as exc:
        assert str(exc).startswith("input ended before the")
    else:
        assert result.plant.pendulum in ("long", "short")


@SETTINGS
@given(st.floats(), st.floats(), st.floats(), st.floats(min_value=-100, max_value=1e4), st.floats(min_value=-1, max_value=10))
def test_pid_never_fails_otherwise(kp, ki, kd, wf, Ti):
    try:
        c = Controller.pid(kp, ki, kd, wf=wf, Ti=Ti)
    except ControllerError as exc:
        assert_clean(exc)
    else:
        assert c.order <= 2


# ------------------------------------------------------------------------------ forbidden controllers
@FEWER
@given(valid_controllers(), st.integers(min_value=0, max_value=MAX_FACTORS - 1), st.sampled_from(["zeros", "poles"]))
def test_a_root_at_the_origin_is_refused(controller, index, where):
    index %= len(controller.factors)
    data = controller.to_dict()
    target = data["kernel"] if index == 0 else data["compensators"][index - 1]
    target[where] = target[where] + [0.0]
    if where == "zeros":
        target["poles"] = target["poles"] + [-1.0]  # stay proper: only the origin is wrong
    try:
        Controller.from_dict(data)
    except ControllerError as exc:
        assert_clean(exc)
        assert "exactly at s = 0" in str(exc)
    else:
        raise AssertionError("a root at 0 was accepted")


@FEWER
@given(valid_controllers())
def test_improper_controllers_are_refused(controller):
    extra = sum(len(f.poles) for f in controller.factors) - sum(len(f.zeros) for f in controller.factors) + 1
    kernel = controller.kernel
    improper = Factor(list(kernel.zeros) + [-1.0 - i for i in range(extra)], kernel.poles, kernel.gain)
    try:
        Controller([improper, *controller.compensators])
    except ControllerError as exc:
        assert_clean(exc)
        assert "improper" in str(exc)
    else:
        raise AssertionError("an improper controller was accepted")


@FEWER
@given(valid_controllers(), st.sampled_from([math.nan, math.inf, -math.inf]), st.sampled_from(["zeros", "poles", "gain"]))
def test_non_finite_numbers_are_refused(controller, bad, where):
    data = controller.to_dict()
    if where == "gain":
        data["kernel"]["gain"] = bad
    else:
        data["kernel"][where] = data["kernel"][where] + [bad, bad]
        data["kernel"]["poles"] = data["kernel"]["poles"] + [-1.0, -2.0]
    try:
        Controller.from_dict(data)
    except ControllerError as exc:
        assert_clean(exc)
        assert "not finite" in str(exc)
    else:
        raise AssertionError("a non-finite number was accepted")


@FEWER
@given(st.lists(factors, min_size=MAX_FACTORS + 1, max_size=MAX_FACTORS + 4))
def test_more_than_six_factors_are_refused(chosen):
    try:
        Controller(chosen)
    except ControllerError as exc:
        assert_clean(exc)
    else:
        raise AssertionError("more than six factors were accepted")


@FEWER
@given(valid_controllers(), st.floats(min_value=-1e3, max_value=1e3, allow_nan=False), magnitudes)
def test_unpaired_complex_values_are_refused(controller, re, im):
    data = controller.to_dict()
    data["kernel"]["poles"] = data["kernel"]["poles"] + [[re, im]]
    try:
        Controller.from_dict(data)
    except ControllerError as exc:
        assert_clean(exc)
        assert "conjugate" in str(exc)
    else:
        raise AssertionError("an unpaired complex pole was accepted")


# ------------------------------------------------------------------------------ valid controllers round-trip
def same_polynomials(a: Controller, b: Controller) -> bool:
    ga, gb = a.transfer_function(), b.transfer_function()
    return np.array_equal(ga.num[0][0], gb.num[0][0]) and np.array_equal(ga.den[0][0], gb.den[0][0])


@FEWER
@given(valid_controllers())
def test_dict_and_json_round_trip(controller):
    back = Controller.from_dict(json.loads(json.dumps(controller.to_dict())))
    assert back == controller and same_polynomials(back, controller)


@FEWER
@given(valid_controllers())
def test_flag_strings_round_trip(controller):
    back = parse_controller(**controller.to_strings())
    assert back == controller and same_polynomials(back, controller)


@FEWER
@given(valid_controllers(), st.sampled_from(["tustin", "zoh"]))
def test_valid_controllers_discretize_to_finite_matrices(controller, method):
    try:
        lti = discretize(controller, h=1e-3, method=method)
    except ControllerError as exc:  # a pole exactly at 2/h, or the order limit
        assert_clean(exc)
        return
    assert lti.order == controller.order
    assert all(np.all(np.isfinite(m)) for m in (lti.A, lti.B, lti.C, lti.D))
