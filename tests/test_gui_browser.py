"""The GUI in a real browser: Debian's Chromium, headless, driven by Selenium through Debian's chromium-driver.

One server and one browser for the module (start-up is most of the cost). Screenshots of each state
of the page go to ``$PENDULAB_GUI_SCREENSHOTS`` (default: a temporary folder).
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.io

selenium = pytest.importorskip("selenium")
from selenium import webdriver  # noqa: E402
from selenium.webdriver.chrome.service import Service  # noqa: E402
from selenium.webdriver.common.by import By  # noqa: E402
from selenium.webdriver.support.ui import WebDriverWait  # noqa: E402

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
DRIVER = shutil.which("chromedriver") or "/usr/bin/chromedriver"
pytestmark = pytest.mark.skipif(not (Path(CHROMIUM).exists() and Path(DRIVER).exists()),
                                reason="needs Debian's chromium and chromium-driver (apt-get install chromium chromium-driver)")

DEMO = ("-5", "7", "40000", [("-17", "-80", ""), ("", "-80", "")])


def chromium_options(profile: Path, downloads: Path) -> webdriver.ChromeOptions:
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--disable-dev-shm-usage", "--window-size=1500,1900",
                 f"--user-data-dir={profile}"):
        options.add_argument(flag)
    options.add_experimental_option("prefs", {"download.default_directory": str(downloads), "download.prompt_for_download": False})
    return options


def start_gui(out: Path, cwd: Path) -> tuple[subprocess.Popen, str]:
    """``pendulab gui --no-browser`` on a free port; returns the process and the URL it printed."""
    process = subprocess.Popen([sys.executable, "-m", "pendulab", "gui", "--no-browser", "--out", str(out)], cwd=cwd,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = process.stdout.readline()
    match = re.search(r"(http://\S+/)", line)
    assert match, f"no URL in {line!r}: {process.stderr.read() if process.poll() is not None else ''}"
    return process, match.group(1)


@pytest.fixture(scope="module")
def gui(tmp_path_factory):
    root = tmp_path_factory.mktemp("gui")
    process, url = start_gui(root / "runs", root)
    downloads = root / "downloads"
    downloads.mkdir()
    driver = webdriver.Chrome(service=Service(DRIVER), options=chromium_options(root / "profile", downloads))
    driver.execute_cdp_cmd("Page.setDownloadBehavior", {"behavior": "allow", "downloadPath": str(downloads)})
    shots = Path(os.environ.get("PENDULAB_GUI_SCREENSHOTS") or root / "screenshots")
    shots.mkdir(parents=True, exist_ok=True)
    yield {"driver": driver, "url": url, "root": root, "downloads": downloads, "shots": shots, "process": process}
    driver.quit()
    process.terminate()
    process.wait(timeout=10)


def wait(driver, condition, timeout=60.0):
    return WebDriverWait(driver, timeout, poll_frequency=0.1).until(lambda d: condition(d))


def shot(gui, name: str) -> None:
    gui["driver"].save_screenshot(str(gui["shots"] / f"{name}.png"))


def type_into(driver, element_id: str, text: str) -> None:
    element = driver.find_element(By.ID, element_id)
    element.clear()
    element.send_keys(text)


def enter_kernel(driver, zeros, poles, gain, compensators=()):
    type_into(driver, "k-zeros", zeros)
    type_into(driver, "k-poles", poles)
    type_into(driver, "k-gain", gain)
    for z, p, k in compensators:
        driver.find_element(By.ID, "add-comp").click()
        row = driver.find_elements(By.CSS_SELECTOR, "tr.comp")[-1]
        for cls, value in (("c-zeros", z), ("c-poles", p), ("c-gain", k)):
            row.find_element(By.CLASS_NAME, cls).send_keys(value)


def status(driver, element_id: str) -> tuple[str, str]:
    element = driver.find_element(By.ID, element_id)
    return element.get_attribute("class"), element.text


def run_and_wait(driver) -> Path:
    """Click Run, wait for the run to finish; the run folder the page names."""
    before = len(driver.find_elements(By.CSS_SELECTOR, "#runs tbody tr"))
    driver.find_element(By.ID, "run").click()
    wait(driver, lambda d: len(d.find_elements(By.CSS_SELECTOR, "#runs tbody tr")) > before, 10)
    wait(driver, lambda d: "results in" in status(d, "run-status")[1] or "error" in status(d, "run-status")[0], 60)
    cls, text = status(driver, "run-status")
    assert "results in" in text, text
    return Path(text.split("results in ", 1)[1].strip())


def cli_error(*argv: str) -> str:
    """The command line's one-line error for the same input."""
    done = subprocess.run([sys.executable, "-m", "pendulab", "simulate", *argv, "--out", os.devnull], capture_output=True, text=True, timeout=60)
    assert done.returncode == 2, done.stderr
    return done.stderr.strip().removeprefix("pendulab: error: ")


def page_metrics(driver, run_id: str) -> dict[str, tuple[str, object]]:
    cells = driver.find_elements(By.CSS_SELECTOR, f'#metrics td[data-run="{run_id}"]')
    return {c.get_attribute("data-key"): (c.text, json.loads(c.get_attribute("data-value") or "null")) for c in cells}


def current_run_id(driver) -> str:
    return driver.find_element(By.CSS_SELECTOR, "#runs tr.current").get_attribute("data-run")


def test_controller_mistake_fix_run_metrics_overlay_download(gui):
    d = gui["driver"]
    d.get(gui["url"])
    wait(d, lambda d: d.find_element(By.TAG_NAME, "body").get_attribute("data-drawn") == "1", 10)
    shot(gui, "01-first-page")

    # A mistake: a kernel pole exactly at s = 0. The page says what the command line says.
    enter_kernel(d, "-5", "0", "40000")
    wait(d, lambda d: "error" in status(d, "controller-status")[0], 10)
    assert status(d, "controller-status")[1] == cli_error("--zeros", "-5", "--poles", "0", "--gain", "40000")
    shot(gui, "02-controller-error")

    # Fixed: the demo controller typed by hand; G(s) shown formatted, the linear view drawn.
    type_into(d, "k-poles", "7")
    for z, p, k in DEMO[3]:
        d.find_element(By.ID, "add-comp").click()
        row = d.find_elements(By.CSS_SELECTOR, "tr.comp")[-1]
        row.find_element(By.CLASS_NAME, "c-zeros").send_keys(z)
        row.find_element(By.CLASS_NAME, "c-poles").send_keys(p)
    expected = "Gc(s) = 40000 (s + 5)(s + 17) / ((s - 7)(s + 80)^2)"  # as 'pendulab simulate' prints it
    wait(d, lambda d: status(d, "controller-status")[1].startswith(expected), 10)
    assert "ok" in status(d, "controller-status")[0]
    wait(d, lambda d: "closed loop stable" in d.find_element(By.ID, "linear-verdict").text, 30)
    assert d.execute_script("return document.getElementById('rootlocus').data.length") >= 4
    assert "phase margin" in d.find_element(By.ID, "margins").text
    shot(gui, "03-controller-ok-linear-view")

    type_into(d, "stop-time", "3")
    d.find_element(By.ID, "run").click()
    wait(d, lambda d: d.find_element(By.ID, "progress-box").is_displayed(), 10)  # progress while it runs
    shot(gui, "04-running")
    wait(d, lambda d: "results in" in status(d, "run-status")[1], 60)
    folder = Path(status(d, "run-status")[1].split("results in ", 1)[1].strip())
    assert not d.find_element(By.ID, "progress-box").is_displayed()
    shot(gui, "05-first-run")
    first = current_run_id(d)
    metrics = json.loads((folder / "metrics.json").read_text())
    shown = page_metrics(d, first)
    checked = 0
    for key, value in metrics.items():
        if key not in shown:
            continue
        text, raw = shown[key]
        assert raw == value, key  # the page holds the run's own numbers ...
        if isinstance(value, bool):
            assert text == ("yes" if value else "no")
        elif value is None:  # with a * and the reason beside it when the metric is not reported
            assert text == ("n/a *" if key in metrics["not_reported"] else "n/a"), (key, text)
        elif key == "verdict":
            assert text.startswith(value["outcome"])
        elif isinstance(value, str):
            assert text == value
        else:  # ... and shows them to 4 significant digits
            assert math.isclose(float(text), value, rel_tol=6e-4, abs_tol=1e-12), (key, text, value)
        checked += 1
    assert checked >= 8 and metrics["stable"] is True
    # The verdict box: this demo run is balanced with no warning, the only verdict shown in green.
    cls, text = status(d, "run-status")
    assert metrics["verdict"]["clean"] and "ok" in cls and text.startswith(metrics["verdict"]["headline"])

    # A second run with a harder poke: both overlaid, aligned at the poke, side by side in the table.
    type_into(d, "poke-mag", "150")
    second_folder = run_and_wait(d)
    assert second_folder != folder
    second = current_run_id(d)
    assert second != first
    names = d.execute_script("return document.getElementById('response').data.map(t => t.name)")
    assert len(names) == 8 and len(set(names)) == 2
    m2 = json.loads((second_folder / "metrics.json").read_text())
    assert page_metrics(d, second)["peak_time_s"][1] == m2["peak_time_s"]
    assert page_metrics(d, first)["peak_time_s"][1] == metrics["peak_time_s"]
    shot(gui, "06-two-runs-overlaid")

    # Download run.mat of the second run and read it with SciPy.
    d.find_element(By.CSS_SELECTOR, '#downloads a[download="run.mat"]').click()
    target = gui["downloads"] / "run.mat"
    wait(d, lambda d: target.is_file() and not list(gui["downloads"].glob("*.crdownload")), 20)
    mat = scipy.io.loadmat(target)
    csv = np.genfromtxt(second_folder / "run.csv", delimiter=",", names=True)
    assert mat["alpha"].shape == (csv["alpha"].size, 1)
    np.testing.assert_allclose(mat["alpha"].ravel(), csv["alpha"], rtol=1e-6, atol=1e-12)
    assert float(mat["meta"]["parameters"][0, 0]["poke_magnitude"][0, 0].ravel()[0]) == 150.0

    # The command line's PNG plots, made on request and offered for download.
    d.find_element(By.ID, "make-plots").click()
    wait(d, lambda d: d.find_elements(By.CSS_SELECTOR, '#downloads a[download="run.png"]'), 60)
    assert (second_folder / "run.png").is_file()

    # The animation of the rig draws the current run.
    d.find_element(By.ID, "play").click()
    wait(d, lambda d: d.find_element(By.ID, "anim-time").text.startswith("t = "), 5)

    # Opening the first run's folder (as a rig run folder would be) adds it to the list.
    type_into(d, "open-path", str(folder))
    d.find_element(By.ID, "open-btn").click()
    wait(d, lambda d: "opened" in status(d, "open-status")[1], 20)
    assert page_metrics(d, current_run_id(d))["peak_time_s"][1] == metrics["peak_time_s"]


def _old_lab_folder(folder: Path) -> Path:
    """The old lab's logs: one [t, value] .mat per signal, the pendulum upright and poked at 1 s."""
    folder.mkdir()
    t = np.arange(0, 3.0, 1e-3)
    after = np.clip(t - 1.0, 0, None)
    # 0.8 rad/s at the onset: a poke of 160 rad/s^2 for 5 ms, above the poke detector's 3 encoder steps per 10 ms.
    alpha = np.where(t > 1.0, 0.1 * np.exp(-3 * after) * np.sin(8 * after), 0.0)
    for name, values in (("angle", alpha), ("position", 0.1 * alpha), ("voltage", 5 * alpha)):
        scipy.io.savemat(folder / f"{name}.mat", {f"{name}Data": np.column_stack([t, values])})
    return folder


def test_old_lab_folder_and_bad_path(gui):
    d = gui["driver"]
    type_into(d, "open-path", str(gui["root"] / "no-such-folder"))
    d.find_element(By.ID, "open-btn").click()
    wait(d, lambda d: "error" in status(d, "open-status")[0], 10)
    assert "does not exist" in status(d, "open-status")[1]
    type_into(d, "open-path", str(_old_lab_folder(gui["root"] / "oldlab")))
    d.find_element(By.ID, "open-btn").click()
    wait(d, lambda d: "opened" in status(d, "open-status")[1], 20)
    run_id = current_run_id(d)
    assert "old lab" in d.find_element(By.CSS_SELECTOR, f'#runs tr[data-run="{run_id}"]').text
    natural = page_metrics(d, run_id)["natural_frequency_rad_s"][1]
    assert natural == pytest.approx(8.0, rel=0.02)  # the synthetic log's own oscillation, 8 rad/s
    shot(gui, "07-old-lab-folder")


def test_uploads_that_are_not_what_they_claim(gui):
    d = gui["driver"]
    fake = gui["root"] / "calibration.json"
    fake.write_bytes(b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR" + bytes(range(256)) * 4)
    d.find_element(By.ID, "cal-file").send_keys(str(fake))
    wait(d, lambda d: "error" in status(d, "cal-status")[0], 10)
    assert "not a JSON text file" in status(d, "cal-status")[1]
    shot(gui, "08-upload-renamed-binary")

    huge = gui["root"] / "big.mat"
    with open(huge, "wb") as f:
        f.truncate(100_000_000)
    d.find_element(By.ID, "cal-file").send_keys(str(huge))
    wait(d, lambda d: "100.0 MB" in status(d, "cal-status")[1], 10)
    assert "at most 1 MB" in status(d, "cal-status")[1]

    good = gui["root"] / "my_rig.json"
    from pendulab.calibration.files import default_calibration, save_calibration

    save_calibration(default_calibration(), good)
    d.find_element(By.ID, "cal-file").send_keys(str(good))
    wait(d, lambda d: "ok" in status(d, "cal-status")[0], 10)
    assert d.find_element(By.ID, "calibration").get_attribute("value").startswith("upload:")
    assert gui["process"].poll() is None  # the server kept running through all of it


def test_two_tabs_do_not_mix(gui):
    d = gui["driver"]
    first_tab = d.current_window_handle
    d.switch_to.new_window("tab")
    d.get(gui["url"])
    wait(d, lambda d: d.find_element(By.TAG_NAME, "body").get_attribute("data-drawn") == "1", 10)
    assert d.find_elements(By.CSS_SELECTOR, "#runs tbody tr") == []  # the other tab's runs are not listed here
    d.find_element(By.ID, "mode-pid").click()
    assert not d.find_element(By.ID, "kernel-entry").is_displayed()
    wait(d, lambda d: "Gc(s) =" in status(d, "controller-status")[1], 10)
    from pendulab.control import Controller, parse_compensator

    # The prefilled PID is one that balances: in series with 1/(s - 4) (the form says why a PID needs it).
    prefilled = Controller([*Controller.pid(300, 100, 100).factors, parse_compensator("none;4")])
    assert status(d, "controller-status")[1].startswith(f"Gc(s) = {prefilled}")
    assert "can never" in d.find_element(By.ID, "pid-note").text
    wait(d, lambda d: "closed loop stable" in d.find_element(By.ID, "linear-verdict").text, 30)
    # The PID alone: the linear view says, before any run, that no gain can balance it, and why.
    d.execute_script("const e = document.getElementById('pid-pole'); e.value = ''; e.dispatchEvent(new Event('input'));")
    wait(d, lambda d: "closed loop UNSTABLE" in d.find_element(By.ID, "linear-verdict").text, 30)
    wait(d, lambda d: "no gain can balance the pendulum" in d.find_element(By.ID, "linear-never").text, 30)
    assert "den_G(0)" in d.find_element(By.ID, "linear-never").text
    shot(gui, "09-pid-entry")
    d.find_element(By.ID, "demo").click()
    wait(d, lambda d: "(s + 80)^2" in status(d, "controller-status")[1], 10)
    wait(d, lambda d: "closed loop stable" in d.find_element(By.ID, "linear-verdict").text, 30)
    type_into(d, "stop-time", "2.5")
    type_into(d, "poke-mag", "80")
    type_into(d, "delay", "2")  # the transport delay reaches the simulation (run.mat's meta says so)
    second_tab = d.current_window_handle

    # Start both, then wait for both: they run at the same time.
    d.find_element(By.ID, "run").click()
    d.switch_to.window(first_tab)
    type_into(d, "poke-mag", "30")
    before = len(d.find_elements(By.CSS_SELECTOR, "#runs tbody tr"))
    d.find_element(By.ID, "run").click()
    folders = {}
    for handle, magnitude, delay in ((first_tab, 30.0, 0), (second_tab, 80.0, 2)):
        d.switch_to.window(handle)
        wait(d, lambda d: "results in" in status(d, "run-status")[1] and not d.find_element(By.ID, "run").get_attribute("disabled"), 60)
        folder = Path(status(d, "run-status")[1].split("results in ", 1)[1].strip())
        folders[handle] = folder
        mat = scipy.io.loadmat(folder / "run.mat")
        assert float(mat["meta"]["parameters"][0, 0]["poke_magnitude"][0, 0].ravel()[0]) == magnitude
        assert float(mat["meta"]["delay"][0, 0].ravel()[0]) == delay
        metrics = json.loads((folder / "metrics.json").read_text())
        run_id = current_run_id(d)
        assert page_metrics(d, run_id)["peak_time_s"][1] == metrics["peak_time_s"]
    assert folders[first_tab] != folders[second_tab]
    d.switch_to.window(second_tab)
    assert len(d.find_elements(By.CSS_SELECTOR, "#runs tbody tr")) == 1
    shot(gui, "10-second-tab")
    d.switch_to.window(first_tab)
    assert len(d.find_elements(By.CSS_SELECTOR, "#runs tbody tr")) == before + 1


def test_fresh_form_lead_verdict_form_words_and_reload(gui):
    """Issue 24: empty fields are empty, errors use the form's words, a zero poke is refused, the lead
    controller's verdict names its warnings in amber, and the runs survive a reload."""
    d = gui["driver"]
    d.switch_to.new_window("tab")
    d.get(gui["url"])
    wait(d, lambda d: d.find_element(By.TAG_NAME, "body").get_attribute("data-drawn") == "1", 10)
    for element_id in ("k-zeros", "k-poles", "k-gain"):  # no grey values that look like a controller
        field = d.find_element(By.ID, element_id)
        assert field.get_attribute("value") == "" and not field.get_attribute("placeholder"), element_id
    d.find_element(By.ID, "add-comp").click()
    assert not d.find_elements(By.CSS_SELECTOR, "tr.comp")[-1].find_element(By.CLASS_NAME, "c-gain").get_attribute("placeholder")
    d.find_element(By.CSS_SELECTOR, "tr.comp .remove").click()

    enter_kernel(d, "-6,-12", "6.4,-90", "40000")  # the lead controller
    wait(d, lambda d: "ok" in status(d, "controller-status")[0], 10)
    # Form errors in the form's words, not the command line's.
    type_into(d, "poke-mag", "abc")
    d.find_element(By.ID, "run").click()
    wait(d, lambda d: "error" in status(d, "run-status")[0], 10)
    text = status(d, "run-status")[1]
    assert text.startswith("poke magnitude 'abc' is not a number") and "--" not in text, text
    type_into(d, "poke-mag", "0")  # no disturbance: refused, it would test nothing
    d.find_element(By.ID, "run").click()
    wait(d, lambda d: "poke magnitude is 0" in status(d, "run-status")[1], 10)
    assert "error" in status(d, "run-status")[0] and "--" not in status(d, "run-status")[1]
    type_into(d, "stop-time", "-1")
    type_into(d, "poke-mag", "50")
    d.find_element(By.ID, "run").click()
    wait(d, lambda d: status(d, "run-status")[1].startswith("the stop time -1"), 10)
    type_into(d, "stop-time", "5")

    folder = run_and_wait(d)
    metrics = json.loads((folder / "metrics.json").read_text())
    cls, text = status(d, "run-status")
    headline = metrics["verdict"]["headline"]
    assert text.startswith(headline) and headline.startswith("BALANCED for 5 s, but the voltage chatters")
    assert "warn" in cls and "ok" not in cls.split()  # amber: balanced, with warnings
    for kind in ("saturation", "chattering", "drift"):
        assert f"warning: {kind}:" in text
    colour = d.execute_script("return getComputedStyle(document.getElementById('run-status')).borderLeftColor")
    assert colour == "rgb(221, 136, 0)", colour  # #d80, not the green of a clean verdict
    run_id = current_run_id(d)
    cell = d.find_element(By.CSS_SELECTOR, f'#metrics td[data-run="{run_id}"][data-key="verdict"]')
    assert cell.get_attribute("class") == "warn" and cell.text.startswith("balanced (chattering, saturation, drift")
    peak = d.find_element(By.CSS_SELECTOR, f'#metrics td[data-run="{run_id}"][data-key="peak_time_s"]')
    assert peak.text == "n/a *" and "chatters" in peak.get_attribute("title")
    assert "chatters" in d.find_element(By.ID, "metrics-notes").text
    shot(gui, "11-lead-controller-warnings")

    # A reload keeps the tab's runs (and their data).
    d.refresh()
    wait(d, lambda d: d.find_elements(By.CSS_SELECTOR, f'#runs tr[data-run="{run_id}"]'), 20)
    wait(d, lambda d: d.find_elements(By.CSS_SELECTOR, f'#metrics td[data-run="{run_id}"]'), 20)
    assert page_metrics(d, run_id)["verdict"][1]["headline"] == headline
    shot(gui, "12-after-reload")


def test_the_seesaw_chosen_its_controller_entry_run_and_drawing(gui):
    """Issue 20: choosing the seesaw turns the controller entry into the state feedback's (K shown as
    'pendulab lqr' prints it), the poke into the tap, and a run draws the tilt, the seesaw's verdict in
    green, its metrics in degrees and the seesaw animated."""
    d = gui["driver"]
    d.switch_to.new_window("tab")
    d.get(gui["url"])
    wait(d, lambda d: d.find_element(By.TAG_NAME, "body").get_attribute("data-drawn") == "1", 10)
    d.find_element(By.ID, "plant-seesaw").click()
    assert not d.find_element(By.ID, "k-zeros").is_displayed() and not d.find_element(By.ID, "pendulum").is_displayed()
    assert d.find_element(By.ID, "sf-q").get_attribute("value") == "1000,5000,0,0,2000"
    assert [d.find_element(By.ID, i).get_attribute("value") for i in ("poke-mag", "poke-dur")] == ["3.3", "0.1"]
    assert not d.find_element(By.ID, "recentre").is_displayed()
    wait(d, lambda d: "K_theta = -224.349" in status(d, "controller-status")[1], 20)  # the Guide: -224.3485
    wait(d, lambda d: "closed loop stable" in d.find_element(By.ID, "linear-verdict").text, 20)
    type_into(d, "sf-r", "-1")  # a wrong weight: the command line's rule in the form's words
    wait(d, lambda d: status(d, "controller-status")[1].startswith("R must be a finite number > 0"), 10)
    d.find_element(By.ID, "sf-demo").click()
    wait(d, lambda d: "ok" in status(d, "controller-status")[0], 10)
    type_into(d, "stop-time", "4")

    folder = run_and_wait(d)
    metrics = json.loads((folder / "metrics.json").read_text())
    cls, text = status(d, "run-status")
    assert metrics["verdict"]["plant"] == "seesaw" and text.startswith(metrics["verdict"]["headline"])
    assert text.startswith("HELD LEVEL for 4 s") and "ok" in cls.split()  # green: held level, no warning
    run_id = current_run_id(d)
    layout = d.execute_script("const l = document.getElementById('response').layout; return [l.yaxis.title.text, l.yaxis3.title.text, !!l.yaxis4]")
    assert layout == ["tilt (°)", "voltage (V)", False]
    tilt = d.execute_script("return document.getElementById('response').data[0].y")
    run = scipy.io.loadmat(folder / "run.mat")
    assert max(map(abs, tilt)) == pytest.approx(np.degrees(np.abs(run["theta"]).max()), rel=1e-9)
    shown = page_metrics(d, run_id)
    assert shown["verdict"][0] == "held" and "final_value_rad" not in shown  # the seesaw's rows, not the pendulum's
    assert "natural_frequency_rad_s" in shown and "tip" not in d.execute_script("return Object.keys(runs.get(current).data.columns)")
    assert shown["peak_tilt_rad"][1] == metrics["peak_tilt_rad"]
    assert math.isclose(float(shown["peak_tilt_rad"][0]), math.degrees(metrics["peak_tilt_rad"]), rel_tol=6e-4)
    assert float(shown["tilt_settling_time_s"][0]) == pytest.approx(metrics["tilt_settling_time_s"], rel=6e-4)
    d.find_element(By.ID, "play").click()
    wait(d, lambda d: ", tilt " in d.find_element(By.ID, "anim-time").text, 5)
    shot(gui, "13-seesaw-run")
