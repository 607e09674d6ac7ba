"""Plant parameters: presets, validation, and bad input on the command line (issue 2, must-show 8)."""

from __future__ import annotations

import importlib.util
import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from pendulab.cli.main import main
from pendulab.errors import ParameterError, UserError
from pendulab.model.parameters import CARTS, PENDULUMS, PlantParameters

CONSOLE_SCRIPT = Path(sys.executable).with_name("pendulab")
HAS_CALIBRATION_FILES = importlib.util.find_spec("pendulab.calibration.files") is not None
needs_calibration_files = pytest.mark.skipif(
    not HAS_CALIBRATION_FILES, reason="pendulab.calibration.files (the calibration file reader) is not written yet"
)


# ---------------------------------------------------------------- presets
def test_lumped_cart_mass_of_the_ip02_presets() -> None:
    """SPEC §2: IP02 no-load cart, M_cart 0.57 kg, lumped Mc 0.7031 kg (rotor inertia lumped in)."""
    for pendulum in PENDULUMS:
        p = PlantParameters.preset(pendulum, "ip02")
        assert p.lumped_cart_mass == pytest.approx(0.7031, abs=5e-5)
        assert p.lumped_cart_mass == pytest.approx(p.M_cart + p.eta_g * p.Kg**2 * p.Jm / p.r_mp**2, rel=1e-15)
    rotor = 0.7031 - 0.57
    assert PlantParameters.preset(cart="ip02-weight").lumped_cart_mass == pytest.approx(0.94 + rotor, abs=5e-5)
    assert PlantParameters.preset(cart="ip01").lumped_cart_mass == pytest.approx(0.52 + rotor, abs=5e-5)


@pytest.mark.parametrize(
    "pendulum, Mp, Lp, lp, Ip",
    [("long", 0.230, 0.6413, 0.3302, 7.884e-3), ("short", 0.127, 0.3365, 0.1778, 1.199e-3)],
)
def test_pendulum_presets_follow_the_spec_table(pendulum: str, Mp: float, Lp: float, lp: float, Ip: float) -> None:
    p = PlantParameters.preset(pendulum)
    assert (p.Mp, p.Lp, p.lp) == (Mp, Lp, lp)
    assert p.Ip == pytest.approx(Ip, rel=1e-3)  # the table rounds Ip = Mp Lp^2 / 12 to 4 digits
    assert p.Ip == pytest.approx(p.Mp * p.Lp**2 / 12, rel=1e-12)
    assert p.Bp == 0.0024


@pytest.mark.parametrize("cart, M_cart, Beq", [("ip02", 0.57, 4.3), ("ip02-weight", 0.94, 5.4), ("ip01", 0.52, 0.9)])
def test_cart_presets_follow_the_spec_table(cart: str, M_cart: float, Beq: float) -> None:
    p = PlantParameters.preset("short", cart)
    assert (p.M_cart, p.Beq) == (M_cart, Beq)
    assert p.Mp == 0.127, "the cart preset must not change the pendulum"


def test_default_friction_vector_and_motor() -> None:
    p = PlantParameters()
    assert p.friction == (1.5, 0.005, 3.0, 0.05, 20.0)
    assert (p.Rm, p.Kt, p.Km, p.Kg, p.Jm, p.r_mp, p.V_max, p.g) == (2.6, 0.007683, 0.007678, 3.71, 3.90e-7, 6.35e-3, 10.0, 9.81)
    assert p == PlantParameters.preset("long", "ip02")


def test_preset_overrides_and_with_values() -> None:
    p = PlantParameters.preset("short", "ip01", Beq=2.5)
    assert p.Beq == 2.5 and p.M_cart == 0.52
    q = p.with_values(F1=0.0, F2=0.0)
    assert q.friction[0] == 0.0 and p.F1 == 1.5, "with_values returns a copy"


def test_without_nonlinearities() -> None:
    p = PlantParameters().without_nonlinearities()
    assert (p.F1, p.F2, p.q_alpha, p.q_x, p.I_max, p.poke_magnitude) == (0, 0, 0, 0, 0, 0)


# ---------------------------------------------------------------- validation
@pytest.mark.parametrize(
    "values, words",
    [
        ({"Mp": -0.1}, ["Mp", "negative"]),
        ({"M_cart": -0.57}, ["M_cart"]),
        ({"M_cart": 0.0}, ["M_cart", "outside its range 0.01 to 100 kg"]),
        ({"V_max": -5.0}, ["V_max", "negative", "0.01 to 1000 V"]),
        ({"Lp": 0.0}, ["lp <= Lp"]),
        ({"Rm": 0.0}, ["Rm"]),
        ({"Beq": math.nan}, ["Beq", "not finite"]),
        ({"g": math.inf}, ["g", "not finite"]),
        ({"F1": -math.inf}, ["F1"]),
        ({"Kt": "fast"}, ["Kt", "not a number"]),
        ({"V_max": True}, ["V_max", "not a number"]),
        ({"Ip": 0.0, "lp": 0.0}, ["inertia"]),
    ],
)
def test_bad_values_raise_one_line_parameter_errors(values: dict, words: list[str]) -> None:
    with pytest.raises(ParameterError) as info:
        PlantParameters.preset("long", **values)
    message = str(info.value)
    assert "\n" not in message
    for word in words:
        assert word in message
    # The same check applies to copies.
    with pytest.raises(ParameterError):
        PlantParameters().with_values(**values)


def test_negative_poke_is_allowed() -> None:
    """A poke may push either way; every other parameter is >= 0."""
    assert PlantParameters(poke_magnitude=-220.0).poke_magnitude == -220.0


@pytest.mark.parametrize("kwargs, word", [({"pendulum": "medium"}, "medium"), ({"cart": "ip03"}, "ip03")])
def test_unknown_preset(kwargs: dict, word: str) -> None:
    with pytest.raises(ParameterError, match=word):
        PlantParameters.preset(**kwargs)


def test_unknown_parameter_name() -> None:
    with pytest.raises(ParameterError, match="'mass'"):
        PlantParameters.preset(mass=1.0)
    with pytest.raises(ParameterError, match="'Mc'"):
        PlantParameters().with_values(Mc=0.7)


def test_parameter_error_is_a_user_error() -> None:
    assert issubclass(ParameterError, UserError) and ParameterError.exit_status == 2


# ---------------------------------------------------------------- the command line
def _assert_one_error_line(status: int, out: str, err: str, *words: str) -> None:
    assert status == 2
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, f"expected one stderr line, got {err!r}"
    assert lines[0].startswith("pendulab: error: ")
    for word in words:
        assert word in lines[0]
    assert out == ""


@pytest.mark.parametrize(
    "argv, words",
    [
        (["tf", "--pendulum", "medium"], ["medium"]),
        (["tf", "--cart", "foo"], ["foo"]),
        (["tf", "--output", "theta"], ["theta"]),
        (["tf", "--bogus"], ["--bogus"]),
        (["frobnicate"], ["frobnicate"]),
    ],
)
def test_cli_bad_choices(argv: list[str], words: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    status = main(argv)
    out, err = capsys.readouterr()
    _assert_one_error_line(status, out, err, *words)


def test_cli_console_script_bad_preset_has_no_traceback() -> None:
    result = subprocess.run([str(CONSOLE_SCRIPT), "tf", "--pendulum", "medium"], capture_output=True, text=True, timeout=120)
    _assert_one_error_line(result.returncode, result.stdout, result.stderr, "medium")


@needs_calibration_files
def test_cli_console_script_missing_calibration_file() -> None:
    result = subprocess.run(
        [str(CONSOLE_SCRIPT), "tf", "--calibration", "/nonexistent.json"], capture_output=True, text=True, timeout=120
    )
    _assert_one_error_line(result.returncode, result.stdout, result.stderr, "/nonexistent.json")


def _calibration(**entries: object) -> dict:
    data: dict = {"format": "pendulab-calibration", "version": 1,
                  "friction": {"F1": 1.5, "v1": 0.005, "F2": 3.0, "v2": 0.05, "B": 20.0}}
    data.update(entries)
    return data


@needs_calibration_files
@pytest.mark.parametrize(
    "name, content",
    [
        ("directory", None),
        ("garbage.json", b"\x00\xff not json {"),
        ("truncated.json", b'{"format": "pendulab-calibration", "friction": {"F1": 1.5,'),
        ("negative.json", json.dumps(_calibration(M_cart=-0.5)).encode()),
        ("nan.json", json.dumps(_calibration(Beq=math.nan)).encode()),
        ("short-vector.json", json.dumps(_calibration(friction=[1.5, 0.005, 3.0])).encode()),
    ],
)
def test_cli_unusable_calibration_file(name: str, content: bytes | None, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / name
    if content is None:
        path.mkdir()
    else:
        path.write_bytes(content)
    before = sorted(tmp_path.rglob("*"))
    status = main(["tf", "--calibration", str(path)])
    out, err = capsys.readouterr()
    _assert_one_error_line(status, out, err, name)
    assert sorted(tmp_path.rglob("*")) == before, "nothing written beside the bad file"


@needs_calibration_files
def test_cli_good_calibration_file_changes_the_transfer_function(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The calibrated Beq and force gain reach the linearization (SPEC §3: a calibrated transfer function)."""
    path = tmp_path / "cal.json"
    path.write_text(json.dumps(_calibration(Beq=6.0, force_gain=0.9)))
    assert main(["tf", "--json"]) == 0
    nominal = json.loads(capsys.readouterr().out)
    assert main(["tf", "--json", "--calibration", str(path)]) == 0
    calibrated = json.loads(capsys.readouterr().out)
    from pendulab.model.linear import linearize

    _, poles, gain = linearize(PlantParameters.preset(Beq=6.0, force_gain=0.9)).zpk()
    assert calibrated["gain"] == pytest.approx(gain, rel=1e-9) and calibrated["gain"] != pytest.approx(nominal["gain"])
    assert sorted(calibrated["poles"]) == [pytest.approx(p, rel=1e-9) for p in sorted(poles)]


@pytest.mark.parametrize("cart", CARTS)
def test_cli_accepts_every_cart(cart: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["tf", "--cart", cart]) == 0
    assert capsys.readouterr().out.startswith("alpha/V = ")
