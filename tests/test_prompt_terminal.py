"""The interactive prompt of `pendulab simulate`, driven through a real pseudo-terminal (pexpect)."""

from __future__ import annotations

import sys

import pexpect
import scipy.io


def spawn(args: list[str], cwd) -> pexpect.spawn:
    child = pexpect.spawn(sys.executable, ["-m", "pendulab", *args], cwd=str(cwd), encoding="utf-8", timeout=60)
    child.setecho(False)
    return child


def answer(child: pexpect.spawn, prompt: str, text: str) -> None:
    child.expect_exact(prompt)
    child.sendline(text)


def test_prompt_to_a_finished_run(tmp_path, plant_fmu):
    out = tmp_path / "run"
    child = spawn(["simulate", "--out", str(out), "--stop-time", "3"], tmp_path)
    answer(child, "Kernel zeros: ", "-6")
    answer(child, "Kernel poles: ", "0")  # forbidden: a pure integrator; the prompt explains and asks again
    child.expect("0")
    answer(child, "Kernel poles: ", "6.4")
    answer(child, "Kernel gain: ", "lots")  # not a number: asked again
    answer(child, "Kernel gain: ", "45000")
    answer(child, "(default f): ", "a")
    answer(child, "Compensator 1 zeros: ", "-16")
    answer(child, "Compensator 1 poles: ", "-80")
    answer(child, "Compensator 1 gain [1]: ", "")
    answer(child, "(default f): ", "a")
    answer(child, "Compensator 2 zeros: ", "")
    answer(child, "Compensator 2 poles: ", "-80")
    answer(child, "Compensator 2 gain [1]: ", "")
    answer(child, "(default f): ", "f")
    answer(child, "Pendulum length, long or short [long]: ", "medium")  # re-asked
    answer(child, "Pendulum length, long or short [long]: ", "long")
    answer(child, "Calibration file [default]: ", "")
    answer(child, "Poke magnitude in rad/s^2 [50]: ", "")
    answer(child, "Poke duration in s [0.005]: ", "")
    answer(child, "Poke start time in s [1]: ", "")
    child.expect("BALANCED for 3 s")
    child.expect(pexpect.EOF)
    child.close()
    assert child.exitstatus == 0
    data = scipy.io.loadmat(out / "run.mat")
    assert data["alpha"].shape == (3001, 1)
    assert abs(data["alpha"]).max() < 0.1


def test_prompt_end_of_input_is_a_clean_error(tmp_path):
    child = spawn(["simulate", "--out", str(tmp_path / "run")], tmp_path)
    answer(child, "Kernel zeros: ", "-6")
    child.expect_exact("Kernel poles: ")
    child.sendeof()
    child.expect(pexpect.EOF)
    child.close()
    output = child.before or ""
    assert child.exitstatus == 2
    assert "Traceback" not in output
    assert not (tmp_path / "run").exists()

