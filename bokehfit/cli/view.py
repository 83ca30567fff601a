"""``bokehfit view``: serve the interactive viewer on 127.0.0.1 and open it in the browser."""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import threading
import webbrowser
from collections.abc import Iterator
from dataclasses import dataclass

from bokehfit.cli.render import parse_size

__all__ = ["ViewSession", "add_parser", "run"]


@dataclass(frozen=True)
class ViewSession:
    """What ``bokehfit view`` served, once it stopped."""

    url: str
    browser_requested: bool


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "view",
        help="path-trace the Cornell box in the browser (WebGPU), or steer a photo's compare (view PHOTO)",
        description=(
            "Serve a local page (127.0.0.1 only) that path-traces the Cornell box progressively in the "
            "browser through WebGPU, with the same WGSL as `bokehfit render`, beside a top-down sketch "
            "of the box with the focus plane and the depth of field. Hover the page's top-left corner "
            "for edit mode: focus, f-stop, shape, angle, blades or aspect, a `bokehfit compare --json` "
            "result's fitted aperture, and PNG export. With a PHOTO, the page at /photo shows that photo's "
            "compare instead: every candidate outlined (used, usable, rejected), the verdict, the fitted "
            "aperture and the candidates' table; click discs to use or drop them, Shift+drag to add one, "
            "refit on exactly those discs (as compare --discs), save them as a discs file or save the "
            "report. Ctrl-C stops the server."
        ),
    )
    parser.add_argument("photo", nargs="?", metavar="PHOTO",
                        help="a photo to compare in the page (read once at start; the page opens no other file)")
    parser.add_argument("--port", type=int, default=0, help="port to listen on (default 0: any free port)")
    parser.add_argument("--no-browser", action="store_true", help="print the URL but do not open a browser")
    parser.add_argument("--size", default="512x512", metavar="WxH", help="render size in pixels (default 512x512)")
    parser.add_argument("--verbose", action="store_true", help="log every request to stderr")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> ViewSession:
    from bokehfit.view import ViewerServer

    width, height = parse_size(args.size)
    server = ViewerServer(args.port, size=(width, height), verbose=args.verbose, photo=args.photo)
    url = server.photo_url or server.url
    with _ctrl_c_interrupts():
        try:
            print(f"bokehfit view: serving {url} (Ctrl-C stops)", flush=True)
            if not args.no_browser:
                # In a thread: a console browser (www-browser) would otherwise hold up the server.
                threading.Thread(target=_open_browser, args=(url,), name="bokehfit-view-browser", daemon=True).start()
            server.serve_forever()
        except KeyboardInterrupt:
            print("\nbokehfit view: stopped", flush=True)
        finally:
            server.close()
    return ViewSession(url, not args.no_browser)


@contextlib.contextmanager
def _ctrl_c_interrupts() -> Iterator[None]:
    """Ctrl-C (SIGINT) raises KeyboardInterrupt while inside, whatever the process inherited.

    A process started with SIGINT ignored (a shell's background job, a test
    runner in the background) keeps it ignored: Python installs its handler
    only where SIGINT is not ignored at start. The server installs it itself,
    and puts the inherited disposition back on the way out. Signal handlers
    belong to the main thread: elsewhere this does nothing.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    inherited = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        if inherited is not None:  # None: a handler not installed from Python, which cannot be put back
            signal.signal(signal.SIGINT, inherited)


def _open_browser(url: str) -> None:
    if not webbrowser.open(url):
        print("bokehfit view: no browser could be opened: open the URL above", file=sys.stderr)
