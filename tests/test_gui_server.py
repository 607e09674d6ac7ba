"""The GUI's server without a browser: where it listens, what it refuses, the same messages as the command line."""

from __future__ import annotations

import http.client
import json
import signal
import socket
import subprocess
import sys
import threading

import pytest

from pendulab.cli.main import main
from pendulab.errors import UserError
from pendulab.gui.app import check_controller, run_spec
from pendulab.gui.server import GuiServer

TAB = {"X-Pendulab-Tab": "testtab-0001"}


@pytest.fixture()
def server(tmp_path):
    srv = GuiServer("127.0.0.1", 0, tmp_path / "runs")
    thread = threading.Thread(target=srv.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
    thread.start()
    yield srv
    srv.shutdown()
    srv.server_close()


def request(srv, method, path, body=None, headers=None):
    conn = http.client.HTTPConnection("127.0.0.1", srv.port, timeout=30)
    conn.request(method, path, body=body, headers={**TAB, **(headers or {})})
    response = conn.getresponse()
    data = response.read()
    conn.close()
    return response.status, json.loads(data) if data[:1] == b"{" else data


def test_listens_on_loopback_by_default(tmp_path):
    process = subprocess.Popen([sys.executable, "-m", "pendulab", "gui", "--no-browser", "--out", str(tmp_path)],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = process.stdout.readline()
        assert line.startswith("pendulab GUI at http://127.0.0.1:")
        port = int(line.split("127.0.0.1:")[1].split("/")[0])
        listening = [c for c in _listening_sockets() if c[1] == port]
        assert listening and all(host == "127.0.0.1" for host, _ in listening)
        process.send_signal(signal.SIGINT)  # Ctrl-C: a clean stop, no traceback
        _, err = process.communicate(timeout=10)
        assert process.returncode == 0 and err.strip() == "pendulab GUI stopped"
    finally:
        if process.poll() is None:
            process.kill()
            process.wait(timeout=10)


def _listening_sockets():
    """(address, port) of the TCP sockets listening on this machine, from /proc (Linux)."""
    out = []
    for line in open("/proc/net/tcp").read().splitlines()[1:]:
        local, state = line.split()[1], line.split()[3]
        if state == "0A":  # LISTEN
            address, port = local.split(":")
            out.append((socket.inet_ntoa(bytes.fromhex(address)[::-1]), int(port, 16)))
    return out


def test_port_in_use_is_one_clear_line(tmp_path, capsys):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        status = main(["gui", "--no-browser", "--port", str(busy.getsockname()[1]), "--out", str(tmp_path)])
    err = capsys.readouterr().err.strip()
    assert status == 2 and len(err.splitlines()) == 1
    assert "choose another --port" in err


@pytest.mark.parametrize(
    "form, argv",
    [
        ({"zeros": "-5", "poles": "0", "gain": "40000"}, ["--zeros=-5", "--poles", "0", "--gain", "40000"]),
        ({"zeros": "-5,-6,-7", "poles": "7", "gain": "1"}, ["--zeros=-5,-6,-7", "--poles", "7", "--gain", "1"]),
        ({"zeros": "-1+2j", "poles": "-3", "gain": "1"}, ["--zeros=-1+2j", "--poles=-3", "--gain", "1"]),
        ({"zeros": "", "poles": "-3", "gain": "abc"}, ["--zeros", "", "--poles=-3", "--gain", "abc"]),
        ({"zeros": "-5", "poles": "7", "gain": "1", "compensators": [{"zeros": "-17", "poles": "x"}]},
         ["--zeros=-5", "--poles", "7", "--gain", "1", "--compensator=-17;x;"]),
        ({"mode": "pid", "pid": {"kp": "0", "ki": "0", "kd": "0"}}, ["--pid", "0,0,0"]),
    ],
)
def test_controller_messages_are_the_command_lines(form, argv, capsys, tmp_path):
    answer = check_controller({"mode": "kernel", **form})
    assert answer["ok"] is False
    assert main(["simulate", *argv, "--out", str(tmp_path / "never")]) == 2
    assert capsys.readouterr().err.strip() == f"pendulab: error: {answer['error']}"
    assert not (tmp_path / "never").exists()


def test_settings_messages_are_the_command_lines_in_the_forms_words(capsys, tmp_path):
    form = {"controller": {"mode": "kernel", "zeros": "-5", "poles": "7", "gain": "40000"}, "stop_time": "2", "delay": "9",
            "poke": {"magnitude": "50", "duration": "0.005", "start": "1"}}
    with pytest.raises(UserError) as exc:
        run_spec(form, None)
    assert main(["simulate", "--demo", "--stop-time", "2", "--delay", "9", "--out", str(tmp_path / "x")]) == 2
    cli = capsys.readouterr().err.strip().removeprefix("pendulab: error: ")
    # The same check and message, with the form's words for the command line's options (issue 24).
    assert cli.startswith("--delay 9 ") and str(exc.value) == cli.replace("--delay", "transport delay")
    with pytest.raises(UserError) as exc:
        run_spec({**form, "delay": "0", "poke": {"magnitude": "abc", "duration": "0.005", "start": "1"}}, None)
    assert str(exc.value).startswith("poke magnitude 'abc' is not a number") and "--" not in str(exc.value)
    with pytest.raises(UserError, match="^poke magnitude is 0: a poke of size 0 disturbs nothing"):
        run_spec({**form, "delay": "0", "poke": {"magnitude": "0", "duration": "0.005", "start": "1"}}, None)
    with pytest.raises(UserError, match="poke starts at t=3"):
        run_spec({**form, "delay": "0", "poke": {"magnitude": "50", "duration": "0.005", "start": "3"}}, None)


def test_pages_and_refusals(server):
    status, page = request(server, "GET", "/")
    assert status == 200 and b"pendulab" in page
    status, js = request(server, "GET", "/static/plotly.min.js")
    assert status == 200 and len(js) > 1_000_000  # the real library, served from the installed wheel
    # A request from another site (no tab header) or through another host name (DNS rebinding): refused.
    conn = http.client.HTTPConnection("127.0.0.1", server.port, timeout=10)
    conn.request("POST", "/api/run", body=b"{}", headers={"Content-Type": "text/plain"})
    assert conn.getresponse().status == 403
    conn.close()
    status, answer = request(server, "GET", "/api/runs", headers={"Host": f"evil.example:{server.port}"})
    assert status == 403
    assert request(server, "GET", "/files/0123456789abcdef/..%2F..%2Fetc%2Fpasswd")[0] == 404
    assert request(server, "GET", "/static/../server.py")[0] == 404
    status, answer = request(server, "POST", "/api/run", body=b"not json")
    assert status == 400 and "JSON" in answer["error"]


def test_upload_of_100_mb_gets_a_message_and_the_server_goes_on(server, tmp_path):
    big = tmp_path / "calibration.json"
    with open(big, "wb") as f:
        f.truncate(100_000_000)
    conn = http.client.HTTPConnection("127.0.0.1", server.port, timeout=60)
    with open(big, "rb") as body:
        conn.request("POST", "/api/calibration", body=body, headers={**TAB, "X-Filename": "calibration.json",
                                                                      "Content-Length": str(big.stat().st_size)})
        response = conn.getresponse()
        answer = json.loads(response.read())
    conn.close()
    assert response.status == 413 and "calibration.json is 100.0 MB" in answer["error"]
    status, answer = request(server, "GET", "/api/calibrations")
    assert status == 200 and [c["key"] for c in answer["calibrations"]] == ["default"]


@pytest.mark.parametrize(
    "name, body, message",
    [
        ("cal.json", b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR" + bytes(300), "not a JSON text file"),
        ("cal.mat", b"PK\x03\x04" + bytes(300), "not a MATLAB .mat file"),
        ("cal.json", b'{"friction": "lots"}', "cal.json"),
        ("cal.exe", b"MZ" + bytes(10), "JSON (.json) or the old lab's MATLAB file"),
        ("cal.mat", b"MATLAB 5.0 MAT-file" + bytes(200), "cal.mat"),
    ],
)
def test_uploads_that_are_not_calibrations(server, name, body, message):
    status, answer = request(server, "POST", "/api/calibration", body=body, headers={"X-Filename": name})
    assert status == 400 and message in answer["error"]
    assert str(server.state.uploads) not in answer["error"]  # the message names the user's file, not ours
    assert request(server, "GET", "/api/calibrations")[1]["calibrations"] == [{"key": "default", "label": "default (the lab's)"}]


def test_linear_view_matches_the_python_api(server):
    import numpy as np

    from pendulab.control.controller import demo_controller
    from pendulab.model.linear import linearize
    from pendulab.model.parameters import PlantParameters

    form = {"controller": {"mode": "kernel", "zeros": "-5", "poles": "7", "gain": "40000",
                           "compensators": [{"zeros": "-17", "poles": "-80"}, {"zeros": "", "poles": "-80"}]}, "pendulum": "short"}
    status, answer = request(server, "POST", "/api/linear", body=json.dumps(form).encode())
    assert status == 200 and answer["ok"], answer
    # The closed-loop poles are the roots of 1 + Lp C(s) G(s), computed here independently.
    loop = demo_controller().transfer_function() * linearize(PlantParameters.preset("short")).tf("tip")
    expected = np.sort_complex(np.roots(np.polyadd(loop.den[0][0], loop.num[0][0])))
    got = np.sort_complex(np.array(answer["closed_poles"]["re"]) + 1j * np.array(answer["closed_poles"]["im"]))
    np.testing.assert_allclose(got, expected, rtol=1e-6)
    assert answer["stable"] is bool(np.all(expected.real < 0)) is True
    mag = np.abs(np.polyval(loop.num[0][0], 10j) / np.polyval(loop.den[0][0], 10j))
    np.testing.assert_allclose(np.interp(1.0, np.log10(answer["bode"]["omega"]), answer["bode"]["mag_db"]), 20 * np.log10(mag), atol=0.05)


def test_a_run_with_bad_settings_is_refused_with_the_command_lines_message(server, capsys, tmp_path):
    form = {"controller": {"mode": "kernel", "zeros": "-5", "poles": "7", "gain": "40000"}, "stop_time": "1",
            "poke": {"magnitude": "50", "duration": "0.005", "start": "1"}}
    status, answer = request(server, "POST", "/api/run", body=json.dumps(form).encode())
    assert status == 400
    assert main(["simulate", "--demo", "--stop-time", "1", "--poke", "50,0.005,1", "--out", str(tmp_path / "x")]) == 2
    cli = capsys.readouterr().err.strip().removeprefix("pendulab: error: ")
    assert answer["error"] == cli.replace("--stop-time", "the stop time")
    assert not list((tmp_path / "runs").glob("*")) if (tmp_path / "runs").exists() else True


def test_calibrations_from_the_calibration_folder(tmp_path, monkeypatch):
    from pendulab.calibration.files import default_calibration, save_calibration
    from pendulab.gui.app import plant_parameters

    calibration = default_calibration()
    save_calibration(calibration, tmp_path / "calibration" / "fitted.json")
    monkeypatch.chdir(tmp_path)
    srv = GuiServer("127.0.0.1", 0, tmp_path / "runs")
    try:
        assert "file:fitted.json" in srv.state.calibrations
        path, label = srv.state.calibration("file:fitted.json")
        assert label == "calibration/fitted.json"
        params = plant_parameters({"pendulum": "short"}, path)
        assert params.Lp == pytest.approx(0.3365)
        with pytest.raises(UserError, match="not in the list"):
            srv.state.calibration("file:../../etc/passwd")
    finally:
        srv.server_close()


def test_upload_of_the_old_labs_mat_calibration(server, tmp_path):
    import io

    import scipy.io

    from pendulab.calibration.files import load_calibration

    buffer = io.BytesIO()
    scipy.io.savemat(buffer, {"measuredData": [[0.5, 0.05, 3.0, 0.0]]})
    status, answer = request(server, "POST", "/api/calibration", body=buffer.getvalue(), headers={"X-Filename": "measured.mat"})
    assert status == 200 and answer["ok"] and answer["label"] == "uploaded: measured.mat"
    path, label = server.state.calibration(answer["key"])
    friction = load_calibration(path).friction
    assert friction[0] == 0.5 and friction[2] == 2.0  # [F1 v1 B unused] as the old lab read it: F2 = 4 F1
    form = {"controller": {"mode": "kernel", "zeros": "-5", "poles": "7", "gain": "40000"}, "calibration": answer["key"]}
    status, linear = request(server, "POST", "/api/linear", body=json.dumps(form).encode())
    assert status == 200 and linear["ok"]


def test_a_failed_simulation_reaches_the_page_as_one_message(tmp_path, monkeypatch):
    import queue

    import pendulab.simulation as simulation
    from pendulab.cosim.master import SimulationError
    from pendulab.gui.worker import run_simulation

    form = {"controller": {"mode": "kernel", "zeros": "-5", "poles": "7", "gain": "40000"}, "stop_time": "2",
            "poke": {"magnitude": "50", "duration": "0.005", "start": "1"}}
    spec = run_spec(form, None)

    def fail(*args, **kwargs):
        raise SimulationError("plant.fmu: fmi2DoStep returned fmi2Error at t=1.2")

    monkeypatch.setattr(simulation, "simulate", fail)
    q = queue.Queue()
    run_simulation(spec, {}, str(tmp_path / "run"), q)
    kind, message = q.get_nowait()
    assert kind == "error" and message.startswith("the simulation failed: plant.fmu: fmi2DoStep returned fmi2Error at t=1.2")
    assert not (tmp_path / "run").exists()  # nothing half-written

    monkeypatch.setattr(simulation, "simulate", lambda *a, **k: 1 / 0)
    run_simulation(spec, {}, str(tmp_path / "run"), q)
    kind, message = q.get_nowait()
    assert kind == "error" and "internal error (ZeroDivisionError" in message


def test_opens_the_browser_at_its_address(tmp_path):
    import os
    import time

    seen = tmp_path / "opened.txt"
    script = tmp_path / "browser.py"
    script.write_text(f"import sys\nopen({str(seen)!r}, 'w').write(sys.argv[1])\n")
    env = {**os.environ, "BROWSER": f"{sys.executable} {script} %s"}  # webbrowser's own way to name the browser
    process = subprocess.Popen([sys.executable, "-m", "pendulab", "gui", "--out", str(tmp_path / "runs")],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        url = process.stdout.readline().split(" at ")[1].split()[0]
        deadline = time.monotonic() + 20
        while not (seen.is_file() and seen.read_text()) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert seen.read_text() == url
    finally:
        process.terminate()
        process.wait(timeout=10)


def test_the_supervisor_mode_switches_reach_the_run(tmp_path):
    """Issue 21: the page's re-centring and swing-up switches run the same modes as simulate --recentre --swing-up."""
    import queue

    import scipy.io

    from pendulab.gui.worker import run_simulation

    form = {"controller": {"mode": "kernel", "zeros": "-5", "poles": "7", "gain": "40000"}, "stop_time": "8",
            "poke": {"magnitude": "50", "duration": "0.005", "start": "1"}, "recentre": True, "swing_up": True}
    spec = run_spec(form, None)
    assert spec.supervisor_parameters() == {"recentre": True, "swing_up": True} and spec.plant.start == "hanging"
    assert run_spec({**form, "recentre": False, "swing_up": False}, None).supervisor_parameters() == {}
    q = queue.Queue()
    run_simulation(spec, {}, str(tmp_path / "run"), q)
    messages = [q.get_nowait() for _ in range(q.qsize())]
    assert messages[-1] == ("done", None), messages
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert metrics["swing_start_s"] == 0.0 and 0 < metrics["catch_time_s"] < 8
    meta = scipy.io.loadmat(tmp_path / "run" / "run.mat", squeeze_me=True, struct_as_record=False)["meta"]
    assert meta.recentre and meta.swing_up and meta.start == "hanging"


def test_the_seesaw_s_controller_entry_linear_view_and_run(tmp_path, capsys):
    """Issue 20: the page's seesaw. Q and R give Quanser's K (the SEESAW Laboratory Guide's); a file that
    'pendulab lqr --out' wrote gives the K and poles 'lqr --json' prints; wrong files and weights get one
    line in the form's words; a run is the seesaw's, drawn from its own columns."""
    import queue

    import numpy as np

    from pendulab.gui.app import linear_view, run_data
    from pendulab.gui.worker import run_simulation

    lqr = {"plant": "seesaw", "mode": "lqr", "q": "1000,5000,0,0,2000", "r": "0.5", "integral": True}
    answer = check_controller(lqr)
    assert answer["states"] == ["x", "theta", "xdot", "thetadot", "theta_integral"]
    np.testing.assert_allclose(answer["K"], [180.797, -224.3485, 16.6684, -66.9969, -63.2456], rtol=2e-5)  # the Guide's K

    def poles(pairs):
        return np.sort_complex(np.array([complex(re, im) for re, im in pairs]))

    path = tmp_path / "k.toml"
    assert main(["lqr", "--plant", "seesaw", "--q", "500,5000,0,0,1000", "--r", "1", "--json", "--out", str(path)]) == 0
    printed = json.loads(capsys.readouterr().out)
    from_file = check_controller({"plant": "seesaw", "mode": "file", "file": {"name": "k.toml", "text": path.read_text()}})
    assert from_file["K"] == printed["K"]
    np.testing.assert_allclose(poles(from_file["closed_loop_poles"]), poles(printed["closed_loop_poles"]), rtol=1e-9)

    assert main(["lqr", "--plant", "pendulum", "--out", str(tmp_path / "p.toml")]) == 0
    capsys.readouterr()
    wrong = [
        ({"mode": "file", "file": {"name": "p.toml", "text": (tmp_path / "p.toml").read_text()}}, "is a state feedback for the pendulum"),
        ({"mode": "file", "file": {"name": "g.toml", "text": "[kernel]\nzeros = [-6]\npoles = [6.4]\ngain = 45000\n"}},
         "no [state_feedback] table"),
        ({"mode": "file", "file": {"name": "", "text": ""}}, "choose the controller file"),
        ({"q": "1000,5000,0,0"}, "Q has 4 weights but the state has 5"),
        ({"r": "-0.5"}, "R must be a finite number > 0"),
    ]
    for change, words in wrong:
        error = check_controller({**lqr, **change})["error"]
        assert words in error and "--q" not in error and "--r" not in error and "\n" not in error, error

    view = linear_view({"plant": "seesaw", "controller": lqr}, None)
    got = np.sort_complex(np.array(view["closed_poles"]["re"]) + 1j * np.array(view["closed_poles"]["im"]))
    np.testing.assert_allclose(got, poles(answer["closed_loop_poles"]), rtol=1e-9)
    assert view["stable"] and view["unstable_open_loop_poles"] == 1

    # The pendulum's fields (hidden on the page) do not reach a seesaw run.
    form = {"plant": "seesaw", "controller": lqr, "poke": {"magnitude": "3.3", "duration": "0.1", "start": "0.5"},
            "stop_time": "2.5", "pendulum": "short", "recentre": True}
    spec = run_spec(form, None)
    assert spec.plant.kind == "seesaw" and spec.supervisor_parameters() == {} and spec.controller.state_feedback.K == tuple(answer["K"])
    with pytest.raises(UserError, match="^tap magnitude is 0: a tap of size 0"):
        run_spec({**form, "poke": {"magnitude": "0", "duration": "0.1", "start": "0.5"}}, None)
    q = queue.Queue()
    run_simulation(spec, {}, str(tmp_path / "run"), q)
    assert [q.get_nowait() for _ in range(q.qsize())][-1] == ("done", None)
    data = run_data(tmp_path / "run")
    assert data["plant"] == "seesaw" and set(data["columns"]) == {"t", "theta", "x", "voltage"} and data["poke_start"] == 0.5
    verdict = data["metrics"]["verdict"]
    assert verdict["plant"] == "seesaw" and verdict["headline"].startswith("HELD LEVEL for 2.5 s")
    # 2.5 s ends 1.4 s after the tilt settled: the cart is still returning from the tap, not judged as a drift.
    assert "drift" not in [w["kind"] for w in verdict["warnings"]] and "tap's response" in verdict["measures"]["drift_not_judged"]
