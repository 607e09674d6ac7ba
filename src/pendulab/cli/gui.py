"""``pendulab gui``: the student's GUI in the browser, served from this machine."""

from __future__ import annotations

import argparse
import sys
import threading
from pathlib import Path

from pendulab.errors import UserError


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "gui",
        help="the lab in your browser: controller, simulation, plots, root locus, runs side by side",
        description=(
            "Start a local web server (127.0.0.1, a free port) and open the GUI in the browser. Works with no "
            "internet. Runs are written under --out like 'pendulab simulate' writes them. Ctrl-C stops it."
        ),
    )
    parser.add_argument("--port", type=int, default=0, metavar="N", help="port to listen on (default: a free one)")
    parser.add_argument("--host", default="127.0.0.1", metavar="ADDR",
                        help="address to listen on (default 127.0.0.1: this machine only; others can reach any other address)")
    parser.add_argument("--no-browser", action="store_true", help="do not open the browser; only print the address")
    parser.add_argument("--out", type=Path, default=Path("runs"), metavar="DIR", help="folder for the runs (default runs/)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if not 0 <= args.port <= 65535:
        raise UserError(f"--port {args.port} must be from 1 to 65535 (or leave it out for a free one)")
    if args.out.exists() and not args.out.is_dir():
        raise UserError(f"--out {args.out} is a file; give a folder for the runs")
    from pendulab.gui.server import GuiServer, plotly_js

    plotly_js()  # refuse now, not in the browser, when plotly is missing
    server = GuiServer(args.host, args.port, args.out)
    if args.host not in ("127.0.0.1", "localhost", "::1"):
        print(f"warning: listening on {args.host}: other machines on the network can use this GUI", file=sys.stderr)
    try:
        print(f"pendulab GUI at {server.url} (Ctrl-C to stop)", flush=True)
        if not args.no_browser:
            import webbrowser

            threading.Thread(target=webbrowser.open, args=(server.url,), daemon=True).start()
        server.serve_forever(poll_interval=0.2)
    except KeyboardInterrupt:
        print("pendulab GUI stopped", file=sys.stderr)
    finally:
        server.server_close()
    return 0
