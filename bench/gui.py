#!/usr/bin/env python3
"""``pendulab gui``: from the command to the first page drawn in the browser (issue 10).

Bar: < 3 s.

Each repeat starts ``pendulab gui --no-browser`` as a user would (the console script, a fresh process),
reads the address it prints and opens it in a headless Chromium that is already open (Debian's
``chromium`` through ``chromium-driver``; the browser's own start is the browser's, not ours), until
the page marks itself drawn (``body[data-drawn]``, set in the first animation frame after the form is
built); then until Plotly (4.6 MB, loaded after the first draw) is ready. Baselines in the same run:

* ``python -c pass``: the interpreter's own start;
* ``python -c "import pendulab"``: the package's top level;
* a trivial ``data:`` page drawn in the same browser: the browser's own cost of drawing a page.

Usage::

    python bench/gui.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from cli import pendulab_script  # noqa: E402 - the same console script the CLI bench starts

BAR_S = 3.0


def python_start(code: str) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", code], check=True)
    return time.perf_counter() - t0


def browser(profile: Path):
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.page_load_strategy = "none"  # get() returns at once: the page is watched, not its load event
    options.binary_location = shutil.which("chromium") or "/usr/bin/chromium"
    for flag in ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--disable-dev-shm-usage", "--window-size=1500,1200",
                 f"--user-data-dir={profile}"):
        options.add_argument(flag)
    return webdriver.Chrome(service=Service(shutil.which("chromedriver") or "/usr/bin/chromedriver"), options=options)


def wait_for(driver, script: str, timeout: float = 30.0) -> None:
    end = time.perf_counter() + timeout
    while not driver.execute_script(script):
        if time.perf_counter() > end:
            raise SystemExit(f"the page did not reach {script!r} within {timeout} s")
        time.sleep(0.005)


def gui_start(driver, out: Path) -> tuple[float, float, float]:
    """Seconds from the command to: the address printed, the page drawn, Plotly ready."""
    t0 = time.perf_counter()
    process = subprocess.Popen([*pendulab_script(), "gui", "--no-browser", "--out", str(out)], stdout=subprocess.PIPE, text=True)
    try:
        line = process.stdout.readline()
        printed = time.perf_counter() - t0
        match = re.search(r"(http://\S+/)", line)
        if not match:
            raise SystemExit(f"pendulab gui printed no address: {line!r}")
        driver.get(match.group(1))
        wait_for(driver, "return document.body.dataset.drawn === '1'")
        drawn = time.perf_counter() - t0
        wait_for(driver, "return document.body.dataset.plotly === '1'")
        plotly = time.perf_counter() - t0
    finally:
        process.terminate()
        process.wait(timeout=10)
    return printed, drawn, plotly


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        driver = browser(Path(tmp) / "profile")
        try:
            driver.get("data:text/html,<p>warm-up</p>")
            rows: dict[str, list[float]] = {k: [] for k in ("pass", "import", "trivial", "printed", "drawn", "plotly")}
            for i in range(args.repeats):
                rows["pass"].append(python_start("pass"))
                rows["import"].append(python_start("import pendulab"))
                t0 = time.perf_counter()
                driver.get(f"data:text/html,<p id=x>{i}</p><script>requestAnimationFrame(()=>document.body.dataset.drawn='1')</script>")
                wait_for(driver, "return document.body.dataset.drawn === '1'")
                rows["trivial"].append(time.perf_counter() - t0)
                printed, drawn, plotly = gui_start(driver, Path(tmp) / "runs")
                rows["printed"].append(printed)
                rows["drawn"].append(drawn)
                rows["plotly"].append(plotly)
        finally:
            driver.quit()
    med = {k: statistics.median(v) for k, v in rows.items()}
    base = med["pass"]
    labels = {
        "pass": "python -c pass",
        "import": "python -c 'import pendulab'",
        "trivial": "trivial page drawn (browser only)",
        "printed": "pendulab gui: address printed",
        "drawn": "pendulab gui: first page drawn",
        "plotly": "pendulab gui: plots library ready",
    }
    print(f"median of {args.repeats} runs (wall clock)")
    for key, label in labels.items():
        print(f"  {label:38s} {med[key] * 1e3:8.0f} ms   {med[key] / base:5.1f}x python -c pass")
    verdict = "PASS" if med["drawn"] < BAR_S else "FAIL"
    print(f"first page drawn {med['drawn']:.2f} s (max {max(rows['drawn']):.2f} s) against the bar {BAR_S:.0f} s: {verdict}")
    return 0 if verdict == "PASS" else 1


if __name__ == "__main__":
    raise SystemExit(main())
