"""The GUI's local web server: the standard library's threaded HTTP server, a JSON API and static files.

The page (``static/``) and Plotly's ``plotly.min.js`` (shipped inside the ``plotly`` wheel) are served
from installed files, so the GUI needs no internet. Each simulation runs in its own process
(:mod:`pendulab.gui.worker`) and writes its own run folder; a run is known by an unguessable id and
listed only in the tab that started or opened it, so two tabs never mix their runs.

Only this module's standard-library imports happen at start-up: the first page is drawn before
numpy, python-control or CasADi are imported (the bar: the first page within 3 s, bench/gui.py).
"""

from __future__ import annotations

import importlib.util
import json
import multiprocessing
import queue as queue_module
import re
import secrets
import shutil
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any
from urllib.parse import unquote, urlsplit

from pendulab.errors import UserError

STATIC = Path(__file__).with_name("static")
#: Largest calibration file accepted (the lab's are well under 10 kB).
MAX_UPLOAD = 1_000_000
#: Largest JSON request body (a form is a few kB).
MAX_JSON = 1_000_000
#: Bodies above this are not even read: the connection is closed after the answer.
MAX_DRAIN = 256_000_000
CONTENT_TYPES = {
    ".html": "text/html; charset=utf-8",
    ".js": "text/javascript; charset=utf-8",
    ".css": "text/css; charset=utf-8",
    ".mat": "application/octet-stream",
    ".csv": "text/csv; charset=utf-8",
    ".json": "application/json",
    ".png": "image/png",
    ".gif": "image/gif",
}


def plotly_js() -> Path:
    """``plotly.min.js`` from the installed ``plotly`` package (found without importing plotly)."""
    spec = importlib.util.find_spec("plotly")
    locations = list(spec.submodule_search_locations or []) if spec else []
    for location in locations:
        path = Path(location) / "package_data" / "plotly.min.js"
        if path.is_file():
            return path
    raise UserError("the GUI needs the 'plotly' package (it ships plotly.min.js): pip install plotly")


@dataclass
class Run:
    """A run in a tab's list: simulated here (``kind="sim"``) or opened from a folder (``kind="open"``)."""

    id: str
    tab: str
    kind: str
    folder: Path
    label: str
    stop_time: float = 0.0
    state: str = "running"  # running, done, error
    progress: float = 0.0
    error: str | None = None
    process: Any = None
    started: float = field(default_factory=time.monotonic)

    def summary(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "kind": self.kind,
            "label": self.label,
            "folder": str(self.folder),
            "state": self.state,
            "progress": self.progress,
            "stop_time": self.stop_time,
            "error": self.error,
        }


class GuiState:
    """The server's runs, calibrations and uploads."""

    def __init__(self, out_dir: Path) -> None:
        self.out_dir = out_dir
        self.runs: dict[str, Run] = {}
        self.lock = threading.Lock()
        self.uploads = Path(tempfile.mkdtemp(prefix="pendulab-gui-"))
        self.calibrations: dict[str, tuple[str, Path | None]] = {"default": ("default (the lab's)", None)}
        folder = Path("calibration")
        if folder.is_dir():
            for path in sorted(folder.iterdir()):
                if path.suffix.lower() in (".json", ".mat") and path.name != "default.json":
                    self.calibrations[f"file:{path.name}"] = (f"calibration/{path.name}", path)
        self._context = multiprocessing.get_context("spawn")

    def calibration(self, key: str | None) -> tuple[str | None, str]:
        if not key or key == "default":
            return None, "default"
        if key not in self.calibrations:
            raise UserError(f"calibration {key!r} is not in the list; choose one from the list or upload the file again")
        label, path = self.calibrations[key]
        return str(path), label

    def new_folder(self, name: str) -> Path:
        stamp = time.strftime("%Y%m%d-%H%M%S")
        base = self.out_dir / f"{stamp}-gui-{name}"
        path, k = base, 1
        while True:
            try:
                path.mkdir(parents=True, exist_ok=False)
                return path
            except FileExistsError:
                k += 1
                path = Path(f"{base}-{k}")
            except OSError as exc:
                raise UserError(f"cannot create the run folder {path}: {exc.strerror or exc}; start the GUI with another --out") from None

    def start(self, tab: str, form: dict[str, Any]) -> Run:
        from pendulab.gui.app import run_spec
        from pendulab.gui.worker import run_simulation

        path, calibration_label = self.calibration(form.get("calibration"))
        spec = run_spec(form, path)
        if spec.plant.kind == "seesaw":
            folder = self.new_folder("seesaw")
            gains = ", ".join(f"{k:.4g}" for k in spec.controller.state_feedback.K)
            label = f"{folder.name}: state feedback K = [{gains}], seesaw, tap {spec.poke.magnitude:g}"
        else:
            pendulum = spec.plant.pendulum
            folder = self.new_folder(pendulum)
            label = f"{folder.name}: {spec.controller.transfer_function}, {pendulum}, poke {spec.poke.magnitude:g}"
        run = Run(secrets.token_hex(8), tab, "sim", folder, label, stop_time=spec.timing.stop_time)
        q = self._context.Queue()
        meta = {"calibration": calibration_label, "source": "simulation"}
        run.process = self._context.Process(target=run_simulation, args=(spec, meta, str(folder), q), daemon=True)
        run.process.start()
        with self.lock:
            self.runs[run.id] = run
        threading.Thread(target=self._watch, args=(run, q), daemon=True).start()
        return run

    def _watch(self, run: Run, q: Any) -> None:
        while True:
            try:
                kind, value = q.get(timeout=0.5)
            except queue_module.Empty:
                if not run.process.is_alive():
                    run.state, run.error = "error", f"the simulation process ended unexpectedly (exit code {run.process.exitcode})"
                    return
                continue
            if kind == "progress":
                run.progress = value
            elif kind == "done":
                run.progress, run.state = run.stop_time, "done"
                break
            else:
                run.state, run.error = "error", value
                break
        run.process.join(timeout=5)

    def open(self, tab: str, path_text: str) -> Run:
        from pendulab.gui.app import run_data

        text = (path_text or "").strip().strip('"')
        if not text:
            raise UserError("type the path of a run folder (from 'pendulab simulate' or 'pendulab lab') or of a folder of the old lab's logs")
        path = Path(text).expanduser()
        data = run_data(path)  # refuses what it cannot read, with a message
        folder = path if path.is_dir() else path.parent
        run = Run(secrets.token_hex(8), tab, "open", folder, data["label"], state="done")
        with self.lock:
            self.runs[run.id] = run
        return run

    def get(self, run_id: str) -> Run:
        run = self.runs.get(run_id)
        if run is None:
            raise LookupError(run_id)
        return run

    def close(self) -> None:
        for run in list(self.runs.values()):
            if run.process is not None and run.process.is_alive():
                run.process.terminate()
        shutil.rmtree(self.uploads, ignore_errors=True)

    def upload_calibration(self, name: str, body: bytes) -> tuple[str, str]:
        from pendulab.calibration.files import load_calibration

        name = Path(name.replace("\\", "/")).name or "upload"
        suffix = Path(name).suffix.lower()
        if suffix not in (".json", ".mat"):
            raise UserError(f"{name}: a calibration file is JSON (.json) or the old lab's MATLAB file (.mat)")
        if suffix == ".json" and (b"\0" in body[:4096]):
            raise UserError(f"{name} is not a JSON text file (it holds binary data); upload the calibration JSON that 'pendulab calibrate' or 'pendulab fit' wrote")
        if suffix == ".mat" and not body.startswith(b"MATLAB") and not body.startswith(b"\x89HDF"):
            raise UserError(f"{name} is not a MATLAB .mat file (it does not start with a MAT-file header); upload the old lab's calibration .mat")
        key = f"upload:{secrets.token_hex(4)}"
        path = self.uploads / key.replace(":", "-") / name
        path.parent.mkdir()
        path.write_bytes(body)
        try:
            load_calibration(path)
        except UserError as exc:
            shutil.rmtree(path.parent, ignore_errors=True)
            raise UserError(str(exc).replace(str(path), name)) from None
        except Exception as exc:  # noqa: BLE001 - a file that is not what it claims: say so, keep serving
            shutil.rmtree(path.parent, ignore_errors=True)
            raise UserError(f"{name} cannot be read as a calibration file ({type(exc).__name__}); is it the right file?") from None
        label = f"uploaded: {name}"
        self.calibrations[key] = (label, path)
        return key, label


class Handler(BaseHTTPRequestHandler):
    """Routes: ``/`` and ``/static/*`` (files), ``/api/*`` (JSON), ``/files/RUN/NAME`` (downloads)."""

    server: "GuiServer"
    protocol_version = "HTTP/1.1"

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 - quiet: the terminal shows the URL only
        pass

    # -------------------------------------------------------------------------------- plumbing
    def _send(self, status: int, body: bytes, content_type: str, headers: dict[str, str] | None = None) -> None:
        self.send_response(status)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("X-Content-Type-Options", "nosniff")
        for key, value in (headers or {}).items():
            self.send_header(key, value)
        self.end_headers()
        if self.command != "HEAD":
            self.wfile.write(body)

    def _json(self, data: Any, status: int = 200) -> None:
        self._send(status, json.dumps(data, allow_nan=False).encode(), "application/json", {"Cache-Control": "no-store"})

    def _error(self, message: str, status: int = 400) -> None:
        self._json({"ok": False, "error": message}, status)

    def _host_allowed(self) -> bool:
        # A web page elsewhere cannot reach this server through a name that points at 127.0.0.1
        # (DNS rebinding): only the names the server was opened with are answered.
        host = (self.headers.get("Host") or "").lower()
        return self.server.any_host or host in self.server.allowed_hosts

    def _read_body(self, limit: int) -> bytes | None:
        """The request body, or None (answer sent) when it is larger than ``limit``."""
        try:
            length = int(self.headers.get("Content-Length") or 0)
        except ValueError:
            length = -1
        if length < 0:
            self._error("the request has no valid Content-Length", 411)
            return None
        if length > limit:
            if length <= MAX_DRAIN:  # read and drop it, so that the browser reads the answer
                left = length
                while left > 0:
                    chunk = self.rfile.read(min(left, 1 << 20))
                    if not chunk:
                        break
                    left -= len(chunk)
            else:
                self.close_connection = True
            self._error(self._too_large(length, limit), HTTPStatus.REQUEST_ENTITY_TOO_LARGE)
            return None
        return self.rfile.read(length)

    def _too_large(self, length: int, limit: int) -> str:
        name = unquote(self.headers.get("X-Filename") or "the file")
        return f"{name} is {length / 1e6:.1f} MB; a calibration file is at most {limit / 1e6:.0f} MB (the lab's are a few kB): is it the right file?"

    def _guarded(self, handle: Any) -> None:
        try:
            handle()
        except (BrokenPipeError, ConnectionResetError):
            pass  # the tab was closed while it waited
        except Exception as exc:  # noqa: BLE001 - one bad request must not take the page down
            self.close_connection = True
            self._error(f"internal error in the GUI server ({type(exc).__name__}: {exc}); please report it", 500)

    def do_GET(self) -> None:  # noqa: N802 - http.server's name
        self._guarded(self._get)

    def do_POST(self) -> None:  # noqa: N802 - http.server's name
        self._guarded(self._post)

    # -------------------------------------------------------------------------------- GET
    def _get(self) -> None:
        if not self._host_allowed():
            return self._error("unknown host name; open the address that 'pendulab gui' printed", 403)
        path = urlsplit(self.path).path
        try:
            if path in ("/", "/index.html"):
                return self._file(STATIC / "index.html")
            if path == "/static/plotly.min.js":
                return self._file(plotly_js(), cache=True)
            if path.startswith("/static/"):
                name = path[len("/static/") :]
                if re.fullmatch(r"[\w.-]+", name) and (STATIC / name).is_file():
                    return self._file(STATIC / name)
                return self._error("no such file", 404)
            if path.startswith("/files/"):
                return self._download(path)
            if path == "/api/calibrations":
                return self._json({"ok": True, "calibrations": [{"key": k, "label": v[0]} for k, v in self.server.state.calibrations.items()]})
            if path == "/api/runs":
                tab = self.headers.get("X-Pendulab-Tab", "")
                runs = [r.summary() for r in self.server.state.runs.values() if r.tab == tab]
                return self._json({"ok": True, "runs": runs})
            match = re.fullmatch(r"/api/runs/([0-9a-f]{16})(/data|/plots)?", path)
            if match:
                return self._run(match.group(1), match.group(2))
            return self._error("no such page", 404)
        except UserError as exc:
            return self._error(str(exc))

    def _file(self, path: Path, cache: bool = False) -> None:
        self._send(200, path.read_bytes(), CONTENT_TYPES.get(path.suffix, "application/octet-stream"),
                   {"Cache-Control": "max-age=86400" if cache else "no-cache"})

    def _run(self, run_id: str, what: str | None) -> None:
        from pendulab.gui.app import run_data

        try:
            run = self.server.state.get(run_id)
        except LookupError:
            return self._error(f"no run {run_id} on this server (it may have been restarted)", 404)
        if not what:
            return self._json({"ok": True, "run": run.summary()})
        if run.state != "done":
            return self._error(f"run {run.label} is not finished ({run.state})", 409)
        if what == "/data":
            data = run_data(run.folder, run.label)
            return self._json({"ok": True, "id": run.id, **data})
        # /plots: the command line's PNG plots of this run, written into its folder on request.
        if run.kind != "sim":
            return self._error("plots are made for the runs simulated here; an opened folder keeps its own files", 409)
        from pendulab.analysis.plots import plot_run
        from pendulab.analysis.results import read_run

        if not (run.folder / "run.png").is_file():
            columns, meta = read_run(run.folder)
            params = meta.get("parameters") if isinstance(meta.get("parameters"), dict) else None
            # The seesaw's disturbance is its tap.
            poke = float(params.get("poke_start", params.get("tap_start", 1.0))) if params else None
            plot_run(columns, run.folder, title=run.label, poke_start=poke)
        return self._json({"ok": True, "files": sorted(p.name for p in run.folder.glob("*.png"))})

    def _download(self, path: str) -> None:
        from pendulab.gui.app import DOWNLOADABLE

        match = re.fullmatch(r"/files/([0-9a-f]{16})/([\w.-]+)", path)
        if not match:
            return self._error("no such file", 404)
        try:
            run = self.server.state.get(match.group(1))
        except LookupError:
            return self._error("no such run", 404)
        target = run.folder / match.group(2)
        if target.suffix.lower() not in DOWNLOADABLE or not target.is_file() or target.parent != run.folder:
            return self._error(f"{match.group(2)} is not a file of this run", 404)
        self._send(200, target.read_bytes(), CONTENT_TYPES.get(target.suffix.lower(), "application/octet-stream"),
                   {"Content-Disposition": f'attachment; filename="{target.name}"', "Cache-Control": "no-store"})

    # -------------------------------------------------------------------------------- POST
    def _post(self) -> None:
        if not self._host_allowed():
            return self._error("unknown host name; open the address that 'pendulab gui' printed", 403)
        tab = self.headers.get("X-Pendulab-Tab", "")
        if not re.fullmatch(r"[0-9a-zA-Z-]{8,64}", tab):
            # Custom header: a page of another site cannot send it without the server's consent (CORS).
            self._read_body(MAX_JSON)
            return self._error("requests come from the GUI's page only (missing tab id)", 403)
        path = urlsplit(self.path).path
        if path == "/api/calibration":
            body = self._read_body(MAX_UPLOAD)
            if body is None:
                return
            try:
                key, label = self.server.state.upload_calibration(unquote(self.headers.get("X-Filename") or "upload"), body)
            except UserError as exc:
                return self._error(str(exc))
            return self._json({"ok": True, "key": key, "label": label})
        raw = self._read_body(MAX_JSON)
        if raw is None:
            return
        try:
            form = json.loads(raw or b"{}")
            if not isinstance(form, dict):
                raise ValueError("not an object")
        except ValueError:
            return self._error("the request is not a JSON object", 400)
        from pendulab.gui import app

        try:
            if path == "/api/controller":
                return self._json(app.check_controller(form))
            if path == "/api/linear":
                calibration, _ = self.server.state.calibration(form.get("calibration"))
                return self._json({"ok": True, **app.linear_view(form, calibration)})
            if path == "/api/run":
                run = self.server.state.start(tab, form)
                return self._json({"ok": True, "run": run.summary()})
            if path == "/api/open":
                run = self.server.state.open(tab, str(form.get("path", "")))
                return self._json({"ok": True, "run": run.summary()})
        except UserError as exc:
            return self._error(str(exc))
        return self._error("no such request", 404)


class GuiServer(ThreadingHTTPServer):
    """The threaded server with the GUI's state attached."""

    daemon_threads = True
    # On Windows SO_REUSEADDR lets a second server take a port in use: there, a busy port must fail.
    allow_reuse_address = sys.platform != "win32"

    def __init__(self, host: str, port: int, out_dir: Path) -> None:
        try:
            super().__init__((host, port), Handler)
        except OSError as exc:
            raise UserError(f"cannot listen on {host}:{port}: {exc.strerror or exc}; choose another --port, or leave it out for a free one") from None
        self.state = GuiState(out_dir)
        self.port = self.server_address[1]
        names = {host, "127.0.0.1", "localhost", "[::1]"}
        self.allowed_hosts = {f"{name}:{self.port}" for name in names}
        self.any_host = host not in ("127.0.0.1", "localhost", "::1")

    @property
    def url(self) -> str:
        host = self.server_address[0]
        return f"http://{host if ':' not in host else f'[{host}]'}:{self.port}/"

    def server_close(self) -> None:
        state = getattr(self, "state", None)  # absent when the port could not be opened
        if state is not None:
            state.close()
        super().server_close()
