"""Controller entry: the rules of SPEC §4, text forms, dict/file forms, PID, transfer functions."""

from __future__ import annotations

import json
import os

import control
import numpy as np
import pytest

from pendulab.control.controller import (
    Controller,
    Factor,
    demo_controller,
    format_number,
    format_numbers,
    parse_compensator,
    parse_controller,
    parse_numbers,
    to_number,
    unstable_example,
)
from pendulab.control.files import controller_toml, load_controller_file, save_controller_file
from pendulab.errors import ControllerError, UserError


def same_tf(a: control.TransferFunction, b: control.TransferFunction, rtol: float = 1e-9) -> bool:
    """Equal as rational functions: num_a * den_b == num_b * den_a (coefficient-wise, relative)."""
    lhs = np.polymul(a.num[0][0], b.den[0][0])
    rhs = np.polymul(b.num[0][0], a.den[0][0])
    n = max(len(lhs), len(rhs))
    lhs, rhs = np.pad(lhs, (n - len(lhs), 0)), np.pad(rhs, (n - len(rhs), 0))
    return bool(np.allclose(lhs, rhs, rtol=rtol, atol=rtol * np.max(np.abs(rhs))))


def one_line_error(excinfo: pytest.ExceptionInfo) -> str:
    message = str(excinfo.value)
    assert "\n" not in message and message.strip() == message and message
    assert isinstance(excinfo.value, UserError)
    return message


# ------------------------------------------------------------------------------ numbers and text
def test_parse_numbers_forms():
    assert parse_numbers("1, -2.5, -3+4j") == [1.0, -2.5, complex(-3, 4)]
    assert parse_numbers("  -3 + 4j , -3 - 4j ") == [complex(-3, 4), complex(-3, -4)]
    assert parse_numbers("-3+4i,-3-4i") == [complex(-3, 4), complex(-3, -4)]  # MATLAB style
    assert parse_numbers("[1e3, (2)]") == [1000.0, 2.0]
    for empty in ("", "  ", "none", "None", "[]", "-"):
        assert parse_numbers(empty) == []
    assert all(isinstance(v, float) for v in parse_numbers("1, 2+0j"))


@pytest.mark.parametrize(
    "text, fragment",
    [
        ("-3+-4j", "'-3+-4j' is not a number"),
        ("1 2", "separate numbers with commas"),
        ("1,,2", "empty entry"),
        ("1,", "empty entry"),
        ("nan", "not finite"),
        ("-inf", "not finite"),
        ("1e999", "not finite"),
        ("abc", "'abc' is not a number"),
        ("1+2k", "is not a number"),
    ],
)
def test_parse_numbers_errors(text, fragment):
    with pytest.raises(ControllerError) as excinfo:
        parse_numbers(text, "kernel poles")
    message = one_line_error(excinfo)
    assert fragment in message and message.startswith("kernel poles")


def test_numbers_round_trip_exactly_through_text():
    values = [0.1, -1 / 3, 1e-300, -2.5e17, complex(-3, 4), complex(-1 / 7, -2 / 3)]
    assert parse_numbers(format_numbers(values)) == values
    assert format_numbers([]) == "none"
    assert format_number(-3.0) == "-3" and format_number(complex(-3, -4)) == "-3-4j"


def test_to_number_forms_and_errors():
    assert to_number([-3, 4]) == complex(-3, 4)
    assert to_number(np.float32(2.5)) == 2.5 and to_number("7") == 7.0
    for bad in (True, None, [1, 2, 3], {"re": 1}, 10**400, [1, "2"], float("nan"), object()):
        with pytest.raises(ControllerError) as excinfo:
            to_number(bad, "gain")
        one_line_error(excinfo)


def test_parse_compensator():
    f = parse_compensator("-16;-80")
    assert f.zeros == (-16.0,) and f.poles == (-80.0,) and f.gain == 1.0
    assert parse_compensator("none;-1+2j,-1-2j;2.5") == Factor([], [complex(-1, 2), complex(-1, -2)], 2.5)
    assert parse_compensator(";-80;").gain == 1.0  # blank gain = 1
    for text, fragment in [("-1", "1 part"), ("1;2;3;4", "4 part"), ("-1;-2;0", "gain is 0"), ("-1;-2;1+1j", "complex"), ("0;-1", "s = 0")]:
        with pytest.raises(ControllerError) as excinfo:
            parse_compensator(text, "compensator 2")
        message = one_line_error(excinfo)
        assert fragment in message and "compensator 2" in message


def test_parse_controller_is_the_inverse_of_to_strings():
    c = Controller([Factor([-1, complex(-3, 4), complex(-3, -4)], [2.5], -7.25), Factor([], [-80, -90]), Factor([-0.5], [-3], 0.3)])
    strings = c.to_strings()
    assert strings["compensators"][0] == "none;-80, -90;1"
    back = parse_controller(**strings)
    assert back == c
    with pytest.raises(ControllerError, match="no gain"):
        parse_controller("-1", "-2", " ")
    with pytest.raises(ControllerError, match="at most 5"):
        parse_controller("-1", "-2", "1", ["none;-1"] * 6)


# ------------------------------------------------------------------------------ the rules
@pytest.mark.parametrize("where", ["zeros", "poles"])
def test_rule_1_nothing_at_the_origin(where):
    kwargs = {"zeros": [-1.0], "poles": [-2.0, -3.0], "gain": 1.0}
    kwargs[where] = [kwargs[where][0], 0.0] if where == "poles" else [0.0]
    with pytest.raises(ControllerError) as excinfo:
        Controller.from_zpk(**kwargs)
    message = one_line_error(excinfo)
    assert "exactly at s = 0" in message
    assert ("1/(s+0.1)" in message) if where == "poles" else ("s/(s+62.8)" in message and "-0.1" in message)
    # just off the origin is fine
    kwargs[where] = [-1e-9] if where == "zeros" else [-1e-9, -3.0]
    Controller.from_zpk(**kwargs)


def test_rule_2_proper_overall_but_factors_may_be_improper():
    # The kernel alone is improper; the product is proper.
    c = Controller([Factor([-1, -2], [5], 3.0), Factor([], [-80])])
    assert c.order == 2
    with pytest.raises(ControllerError) as excinfo:
        Controller([Factor([-1, -2], [5], 3.0), Factor([-7], [-80])])
    message = one_line_error(excinfo)
    assert "improper" in message and "3 zeros" in message and "2 pole" in message


def test_rule_3_at_most_six_factors():
    factors = [Factor([], [-float(i)]) for i in range(1, 7)]
    assert len(Controller(factors).compensators) == 5
    with pytest.raises(ControllerError) as excinfo:
        Controller(factors + [Factor([], [-9.0])])
    assert "7 factors" in one_line_error(excinfo)


def test_rule_3_conjugate_pairs_finite_gain():
    with pytest.raises(ControllerError, match=r"-3\+4j has no conjugate.*add -3-4j"):
        Factor([complex(-3, 4)], [-1, -2], label="kernel")
    with pytest.raises(ControllerError, match="no conjugate"):  # pair split across zeros and poles
        Factor([complex(-3, 4)], [complex(-3, -4), -1])
    with pytest.raises(ControllerError, match="no conjugate"):  # two of the same sign are no pair
        Factor([], [complex(-3, 4), complex(-3, 4)])
    with pytest.raises(ControllerError, match="not finite"):
        Factor([], [float("inf")])
    with pytest.raises(ControllerError, match="gain is 0"):
        Factor([], [-1], 0.0)
    with pytest.raises(ControllerError, match="gain"):
        Factor([], [-1], float("nan"))
    # pairs in any order; a near-exact partner is made exact
    f = Factor([complex(-3, -4), -1, complex(-3, 4 + 1e-14)], [-1, -2, -3])
    assert f.zeros[2] == complex(-3, -4).conjugate()
    assert np.all(np.isreal(f.numerator()))


def test_controller_needs_factors():
    with pytest.raises(ControllerError, match="no kernel"):
        Controller([])
    with pytest.raises(ControllerError, match="not a Factor"):
        Controller([([-1], [-2], 1.0)])  # type: ignore[list-item]


# ------------------------------------------------------------------------------ views
def test_zpk_and_transfer_function_agree():
    c = Controller([Factor([-6], [6.4], 45000.0), Factor([complex(-3, 4), complex(-3, -4)], [-80, -90]), Factor([], [-100], 0.5)])
    zeros, poles, gain = c.zpk()
    assert gain == 45000.0 * 0.5
    assert sorted(np.round(poles.real, 9)) == [-100, -90, -80, 6.4]
    g = c.transfer_function()
    for s in (1j, 3.0 + 2j, 100j):
        direct = gain * np.prod(s - zeros) / np.prod(s - poles)
        assert np.isclose(g(s), direct, rtol=1e-12)
    # the TF equals the product of the factors' TFs
    product = c.factors[0].transfer_function() * c.factors[1].transfer_function() * c.factors[2].transfer_function()
    assert same_tf(g, product)


def test_describe_and_str():
    c = demo_controller()
    assert str(c) == "40000 (s + 5)(s + 17) / ((s - 7)(s + 80)^2)"
    text = c.describe()
    assert "(kernel)" in text and "(compensator 2)" in text and text.count("\n") == 4
    assert "G3(s) = 1 / (s + 80)" in text
    pair = Controller([Factor([], [complex(-3, 4), complex(-3, -4)], -2.0)])
    assert str(pair) == "-2 / (s^2 + 6s + 25)"


def test_dict_round_trip_and_json_shape():
    c = Controller([Factor([complex(-1, 2), complex(-1, -2)], [3.0], 7.0), Factor([-5], [-50, -60])])
    d = c.to_dict()
    assert d["kernel"]["zeros"] == [[-1.0, 2.0], [-1.0, -2.0]]
    assert json.loads(json.dumps(d)) == d
    assert Controller.from_dict(json.loads(json.dumps(d))) == c
    # strings and a comma-separated list are accepted too; compensator gain defaults to 1
    loose = {"kernel": {"zeros": "-1+2j, -1-2j", "poles": ["3"], "gain": "7"}, "compensators": [{"zeros": [-5], "poles": [-50, -60]}]}
    assert Controller.from_dict(loose) == c


@pytest.mark.parametrize(
    "data, fragment",
    [
        ([], "a controller is a table"),
        ({}, "no 'kernel'"),
        ({"kernel": {"poles": [-1]}}, "kernel has no gain"),
        ({"kernel": {"poles": [-1], "gain": 1}, "extra": 1}, "unknown key 'extra'"),
        ({"kernel": {"poles": [-1], "gain": 1, "pole": [-2]}}, "unknown key 'pole' in kernel"),
        ({"kernel": [1, 2]}, "kernel must be a table"),
        ({"kernel": {"poles": [-1], "gain": 1}, "compensators": {"poles": [-1]}}, "must be a list"),
        ({"kernel": {"poles": [-1], "gain": 1}, "compensators": [{"poles": [-1]}] * 6}, "6 compensators"),
        ({"kernel": {"poles": [-1], "gain": 1}, "compensators": [{"poles": [0]}]}, "compensator 1 pole 0"),
        ({"kernel": {"poles": [-1], "gain": 1}, "compensators": [{"poles": [-1], "gain": [1, 1]}]}, "compensator 1 gain"),
        ({"kernel": {"poles": {"a": 1}, "gain": 1}}, "kernel poles"),
        ({"kernel": {"poles": [-1], "gain": True}}, "kernel gain"),
        ({"kernel": {"zeros": [-1, -2], "poles": [-1], "gain": 1}}, "improper"),
    ],
)
def test_from_dict_errors(data, fragment):
    with pytest.raises(ControllerError) as excinfo:
        Controller.from_dict(data)
    assert fragment in one_line_error(excinfo)


def test_from_transfer_function_and_zpk():
    c = demo_controller()
    back = Controller.from_transfer_function(c.transfer_function())
    assert len(back.factors) == 1 and back.order == 3
    assert same_tf(back.transfer_function(), c.transfer_function(), rtol=1e-9)
    assert same_tf(Controller.from_transfer_function(control.ss(c.transfer_function())).transfer_function(), c.transfer_function(), rtol=1e-7)
    # complex roots come back as exact conjugate pairs
    g = control.tf([2.0, 4.0, 10.0], [1.0, 30.0, 300.0, 1000.0])
    k = Controller.from_transfer_function(g).kernel
    assert sum(isinstance(z, complex) for z in k.zeros) == 2 and k.gain == 2.0
    with pytest.raises(ControllerError, match="exactly at s = 0"):
        Controller.from_transfer_function(control.tf([1.0], [1.0, 5.0, 0.0]))
    with pytest.raises(ControllerError, match="discrete-time"):
        Controller.from_transfer_function(control.tf([1.0], [1.0, 0.5], 0.01))
    with pytest.raises(ControllerError, match="improper"):
        Controller.from_transfer_function(control.tf([1.0, 1.0, 1.0], [1.0, 5.0]))
    with pytest.raises(ControllerError, match="SISO"):
        Controller.from_transfer_function(control.tf([[[1.0], [2.0]]], [[[1.0, 1.0], [1.0, 2.0]]]))
    with pytest.raises(ControllerError, match="TransferFunction"):
        Controller.from_transfer_function("1/(s+1)")
    with pytest.raises(ControllerError, match="numerator is 0"):
        Controller.from_transfer_function(control.tf([0.0], [1.0, 1.0]))
    assert Controller.from_zpk(np.array([-1.0]), np.array([-2.0, -3.0]), np.float64(4.0)).kernel.gain == 4.0


@pytest.mark.parametrize("kp, ki, kd", [(3.0, 2.0, 0.5), (3.0, 0.0, 0.5), (3.0, 2.0, 0.0), (0.0, 2.0, 0.0), (0.0, 2.0, 0.5), (4.0, 0.0, 0.0), (-62.8 * 0.5, 1.0, 0.5)])
def test_pid_matches_its_formula(kp, ki, kd):
    wf, Ti = 62.8, 0.628
    c = Controller.pid(kp, ki, kd)
    s = control.tf("s")
    reference = kp + ki / (s + 1 / Ti) + kd * wf * s / (s + wf)
    for point in (0.5j, 2.0 + 1j, 40j, 300j):
        assert np.isclose(c.transfer_function()(point), reference(point), rtol=1e-10)
    # dropped terms drop their poles
    assert c.order == (ki != 0) + (kd != 0)


def test_pid_other_filters_and_errors():
    c = Controller.pid(1.0, 1.0, 1.0, wf=100.0, Ti=2.0)
    assert sorted(c.kernel.poles) == [-100.0, -0.5]
    for args, fragment in [
        ((0.0, 0.0, 0.0), "all gains are 0"),
        ((0.0, 0.0, 1.0), "zero exactly at s = 0"),
        ((1.0, -1 / 0.628, 0.0), "zero exactly at s = 0"),
        ((1.0, 1.0, 1.0, -1.0), "wf and Ti must be > 0"),
        ((1.0, 1.0, 1.0, 62.8, 0.0), "wf and Ti must be > 0"),
        ((float("nan"), 1.0, 1.0), "not finite"),
        ((1j, 1.0, 1.0), "complex"),
    ]:
        with pytest.raises(ControllerError) as excinfo:
            Controller.pid(*args)
        assert fragment in one_line_error(excinfo)


# ------------------------------------------------------------------------------ files
def test_controller_files_round_trip(tmp_path):
    c = Controller([Factor([complex(-3, 4), complex(-3, -4)], [2.0], 1e-5), Factor([-0.1], [-62.8, -1 / 3])])
    for name in ("c.toml", "c.json"):
        save_controller_file(c, tmp_path / name)
        assert load_controller_file(tmp_path / name) == c
    assert sorted(os.listdir(tmp_path)) == ["c.json", "c.toml"]  # no temporary files left
    assert "[[compensators]]" in controller_toml(c)


def test_handwritten_toml_file(tmp_path):
    path = tmp_path / "mine.TOML"
    path.write_text(
        '# my controller\n[kernel]\nzeros = [-5]\npoles = [7]\ngain = 40000\n\n'
        '[[compensators]]\nzeros = ["-17"]\npoles = [-80]\n\n[[compensators]]\npoles = [-80]\n'
    )
    assert load_controller_file(path) == demo_controller()
    path2 = tmp_path / "pair.toml"
    path2.write_text("[kernel]\nzeros = [[-3, 4], [-3, -4]]\npoles = [-1, -2, -50]\ngain = 2\n")
    assert load_controller_file(path2).kernel.zeros == (complex(-3, 4), complex(-3, -4))


@pytest.mark.parametrize(
    "name, content, fragment",
    [
        ("c.toml", "[kernel\nzeros = [1]", "not valid TOML"),
        ("c.json", '{"kernel": ', "not valid JSON"),
        ("c.json", '{"kernel": {"poles": [NaN], "gain": 1}}', "not finite"),
        ("c.json", '{"kernel": {"poles": [-1], "gain": 1e999}}', "not finite"),
        ("c.json", '{"kernel": {"poles": [-1], "gain": ' + "9" * 5000 + "}}", "cannot be read"),
        ("c.json", "[" * 100000, "c.json"),
        ("c.toml", "[kernel]\npoles = [-1]\ngain = 1\ncolour = 'red'\n", "unknown key 'colour' in kernel"),
        ("c.toml", "[kernel]\npoles = [-1]\n", "kernel has no gain"),
        ("c.toml", "", "no 'kernel'"),
        ("c.txt", "[kernel]", "name it *.toml or *.json"),
        ("c", "[kernel]", "(no suffix)"),
    ],
)
def test_bad_controller_files(tmp_path, name, content, fragment):
    path = tmp_path / name
    path.write_text(content)
    with pytest.raises(ControllerError) as excinfo:
        load_controller_file(path)
    message = one_line_error(excinfo)
    assert fragment in message and str(path) in message


def test_unreadable_controller_files(tmp_path):
    with pytest.raises(ControllerError, match="does not exist"):
        load_controller_file(tmp_path / "missing.toml")
    (tmp_path / "dir.toml").mkdir()
    with pytest.raises(ControllerError, match="is a directory"):
        load_controller_file(tmp_path / "dir.toml")
    (tmp_path / "bin.json").write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(ControllerError, match="not UTF-8"):
        load_controller_file(tmp_path / "bin.json")
    with pytest.raises(ControllerError, match="cannot write"):
        save_controller_file(demo_controller(), tmp_path / "no" / "such" / "c.toml")
    assert not (tmp_path / "no").exists()


# ------------------------------------------------------------------------------ demo
def test_demo_and_unstable_example_shapes():
    c = demo_controller("short")
    assert c == demo_controller("long") and len(c.factors) == 3 and c.kernel.gain > 0
    assert unstable_example().kernel.gain == -c.kernel.gain
    with pytest.raises(ControllerError, match="unknown pendulum"):
        demo_controller("medium")
