"""One request to the viewer's server: the checks every request passes, then its route's answer.

A request reaches :class:`Handler` from the transport (:mod:`bokehfit.view.transport`,
driven by :class:`bokehfit.view.server.ViewerServer`) as its head, then its body. The
routes are listed in :mod:`bokehfit.view.server`; what they answer is computed elsewhere:
the WGSL and uniform layout in :mod:`bokehfit.view.wgsl`, the settings in
:mod:`bokehfit.view.settings`, the masks in :mod:`bokehfit.view.masks`, a photo's compare
in :mod:`bokehfit.view.photo`.

Each request is checked in one place before any route sees it: exactly one
Host header, and it names the server (``127.0.0.1:PORT`` or
``localhost:PORT``; else 400 or 421), so that another web site cannot reach it
through a rebound DNS name; a method the path serves (else 405); a request line
and header block within their caps (414, 431); for POST, a write from the
viewer's own page (403 else): an Origin of the server itself (or
``Sec-Fetch-Site: same-origin``) and this run's random token, which the page
receives in its HTML and sends back in ``X-Bokehfit-Token``; the route's
content type (``application/json``, ``image/png``; 415 else), none of which a
page of another site can send without a preflight; a Content-Length within
``MAX_BODY_BYTES`` (411, 413), checked before a byte of the body is read. JSON
bodies are scanned in linear time for their nesting and number of values
before they are parsed (:mod:`bokehfit.view.bodies`); uploaded PNGs keep only
their pixel chunks (:func:`bokehfit.view.masks.png_pixels_only`). Every request gets
a status line and a JSON ``{"error": message}`` body when refused; an
unexpected failure answers 500 and logs one line on stderr.
"""

from __future__ import annotations

import hmac
import io
import json
import re
import secrets
from functools import lru_cache
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler
from importlib import resources
from urllib.parse import parse_qs, urlsplit

from bokehfit import __version__
from bokehfit.errors import InputError
from bokehfit.view.bodies import MAX_BODY_BYTES, brief, collector_paused, parse_json_body
from bokehfit.view.masks import MaskStore, mask_upload
from bokehfit.view.settings import TOKEN_HEADER, params_for_query, query_int, settings_from_compare, viewer_config
from bokehfit.view.transport import log_line
from bokehfit.view.wgsl import display_source, kernel_config, kernel_source, pathtrace_source_cached

__all__ = ["MAX_HEADER_BYTES", "MAX_REQUEST_LINE_BYTES", "Handler", "Site"]

#: Longest request line (method, target and version, bytes): 414 beyond.
MAX_REQUEST_LINE_BYTES = 8192
#: Largest header block (names, values and separators, bytes): 431 beyond. The
#: header parser (http.client) also stops at 100 lines of 64 KiB while reading.
MAX_HEADER_BYTES = 32768
#: The mark in index.html and photo.html that the server replaces with the token
#: (sent back in ``TOKEN_HEADER`` with every write).
TOKEN_PLACEHOLDER = b"%BOKEHFIT_TOKEN%"

#: The Cornell-box page and its ES modules (common.js is the photo page's too), each named:
#: the server answers no other file of ``static/``.
_STATIC = {
    "/": ("index.html", "text/html; charset=utf-8"),
    "/index.html": ("index.html", "text/html; charset=utf-8"),
    "/viewer.js": ("viewer.js", "text/javascript; charset=utf-8"),
    "/viewer_renderer.js": ("viewer_renderer.js", "text/javascript; charset=utf-8"),
    "/viewer_points.js": ("viewer_points.js", "text/javascript; charset=utf-8"),
    "/viewer_topdown.js": ("viewer_topdown.js", "text/javascript; charset=utf-8"),
    "/viewer_controls.js": ("viewer_controls.js", "text/javascript; charset=utf-8"),
    "/viewer_files.js": ("viewer_files.js", "text/javascript; charset=utf-8"),
    "/png_text.js": ("png_text.js", "text/javascript; charset=utf-8"),
    "/common.js": ("common.js", "text/javascript; charset=utf-8"),
    "/style.css": ("style.css", "text/css; charset=utf-8"),
}
#: The page of ``bokehfit view PHOTO`` and its ES modules (404 where the server has no photo).
_PHOTO_STATIC = {
    "/photo": ("photo.html", "text/html; charset=utf-8"),
    "/photo.js": ("photo.js", "text/javascript; charset=utf-8"),
    "/photo_state.js": ("photo_state.js", "text/javascript; charset=utf-8"),
    "/photo_draw.js": ("photo_draw.js", "text/javascript; charset=utf-8"),
    "/photo_edit.js": ("photo_edit.js", "text/javascript; charset=utf-8"),
    "/photo_results.js": ("photo_results.js", "text/javascript; charset=utf-8"),
    "/photo_match.js": ("photo_match.js", "text/javascript; charset=utf-8"),
    "/photo_kernel.js": ("photo_kernel.js", "text/javascript; charset=utf-8"),
    "/photo_refit.js": ("photo_refit.js", "text/javascript; charset=utf-8"),
}
#: The photo's routes: GET for the photo, its results and a refit's state; POST for the writes.
_PHOTO_GET = ("/photo/info.json", "/photo/image.jpg", "/photo/job", "/photo/result.json", "/photo/tiles.json", "/photo/report.html",
              "/photo/kernel_mc.wgsl")
_PHOTO_POST = ("/photo/refit", "/photo/cancel", "/photo/discs-file")
#: The methods each path serves (HEAD wherever GET); every other method answers 405.
_READ = ("GET", "HEAD")
_ROUTES = {
    **{path: _READ for path in _STATIC},
    "/pathtrace.wgsl": _READ,
    "/display.wgsl": _READ,
    "/config.json": _READ,
    "/params.json": _READ,
    "/favicon.ico": _READ,
    "/mask_table": _READ,
    "/matched": ("POST",),
    "/mask": ("POST",),
    **{path: _READ for path in _PHOTO_STATIC},
    **{path: _READ for path in _PHOTO_GET},
    **{path: ("POST",) for path in _PHOTO_POST},
}
#: What the body of each POST route must be, for the message when it is empty.
_POST_BODIES = {"/matched": "a `bokehfit compare --json` result", "/mask": "an image file (PNG) of transmission",
                "/photo/refit": 'the discs to fit ({"discs": [...], "shapes": [...]})', "/photo/cancel": "{}",
                "/photo/discs-file": 'the picked discs ({"discs": [...]})'}
#: The one content type each POST route takes: neither is one a page of another
#: site may send without a preflight (text/plain, forms).
_POST_TYPES = {"/matched": "application/json", "/mask": "image/png", **{path: "application/json" for path in _PHOTO_POST}}
_METHODS = ("GET", "HEAD", "POST")


class _Refused(Exception):
    """A request answered with ``status`` and a one-line message instead of its route."""

    def __init__(self, status: HTTPStatus, message: str, headers: tuple[tuple[str, str], ...] = ()):
        super().__init__(message)
        self.status = status
        self.message = message
        self.headers = headers


@lru_cache(maxsize=None)
def _static_file(name: str) -> bytes:
    """A file of the page (package data), read once: every answer shares the one copy."""
    return resources.files("bokehfit.view").joinpath("static", name).read_bytes()


def _download_stem(name: str) -> str:
    """The photo's stem for a download's file name, in characters safe in a header."""
    stem = re.sub(r"[^A-Za-z0-9._-]+", "_", name.rsplit(".", 1)[0])[:80]
    return f"{stem or 'photo'}_bokehfit"


def _photo_json_bytes(result: dict) -> bytes:
    """A result's ``compare --json`` document as the command writes it (indent 1)."""
    return (json.dumps(result["json"], indent=1, allow_nan=False) + "\n").encode("utf-8")


@lru_cache(maxsize=8)
def _pathtrace_bytes(scene_name: str) -> bytes:
    return pathtrace_source_cached(scene_name, False).encode("utf-8")


class Site:
    """What every request of one server shares: its names, its token, its masks and its settings."""

    def __init__(self, port: int, scene_name: str, size: tuple[int, int], verbose: bool, photo=None):
        self.photo = photo
        self.scene_name = scene_name
        self.size = size
        self.verbose = verbose
        self.masks = MaskStore()
        self.own_hosts = (f"127.0.0.1:{port}", f"localhost:{port}")
        self.own_origins = tuple(f"http://{host}" for host in self.own_hosts)
        #: The per-run secret the page sends back with every write (in the page it is served).
        self.token = secrets.token_urlsafe(32)
        self.page = _static_file("index.html").replace(TOKEN_PLACEHOLDER, self.token.encode("ascii"))
        self.photo_page = _static_file("photo.html").replace(TOKEN_PLACEHOLDER, self.token.encode("ascii"))


class Handler(BaseHTTPRequestHandler):
    """One request: its head checked in :meth:`begin` (on the event loop), its route run in :meth:`respond`.

    The standard library's request parsing and answering, on the bytes the
    transport (:mod:`bokehfit.view.transport`) collected: ``rfile`` holds the
    head, ``wfile`` collects the answer, which the transport sends.
    """

    server_version = f"bokehfit-view/{__version__}"

    def __init__(self, site: Site):  # not BaseHTTPRequestHandler's: no socket, no handle() on construction
        self.server = site
        self.client_address = ("127.0.0.1", 0)
        self.rfile = io.BytesIO()
        self.wfile = io.BytesIO()
        self.command, self.requestline, self.request_version = "", "", "HTTP/1.0"
        self.close_connection = True  # one request per connection
        self._answered = False
        self._route = None
        self._body = b""  # the answer's body, sent after wfile's head (shared, never copied)

    def log_message(self, format, *args):  # quiet unless --verbose: keep the terminal clean
        if self.server.verbose:
            super().log_message(format, *args)

    # --- answering --------------------------------------------------------------------------

    def _send(self, status: int, body: bytes, content_type: str, headers: tuple[tuple[str, str], ...] = ()) -> None:
        self._answered = True
        self.send_response(status)
        for name, value in headers:
            self.send_header(name, value)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.send_header("X-Content-Type-Options", "nosniff")
        self.send_header("Connection", "close")
        self.end_headers()
        if self.command != "HEAD":
            self._body = body

    def _json(self, status: int, data, headers: tuple[tuple[str, str], ...] = ()) -> None:
        body = json.dumps(data, allow_nan=False).encode("utf-8")
        self._send(status, body, "application/json; charset=utf-8", headers)

    def _error(self, status: int, message: str, headers: tuple[tuple[str, str], ...] = ()) -> None:
        self.log_message('"%s" %d %s', self.requestline[:200], int(status), message)
        self._json(status, {"error": message}, headers)

    def send_error(self, code, message=None, explain=None):
        """The standard library's refusals (bad request line or headers) as JSON like every other."""
        status = HTTPStatus(code)
        self.request_version = "HTTP/1.0"  # a status line even where the request line was unreadable
        self._error(status, f"{status.phrase}: {message}" if message else status.phrase)

    def _answer_late(self, status: HTTPStatus, message: str, headers: tuple[tuple[str, str], ...] = ()) -> None:
        """Answer a failure unless an answer has started."""
        if not self._answered:
            self._error(status, message, headers)

    def _internal(self, error: Exception) -> None:
        """A bug: one line on stderr, 500 to the client."""
        log_line(f"internal error answering {self.requestline[:200]!r}: {type(error).__name__}: {error}")
        self._answer_late(HTTPStatus.INTERNAL_SERVER_ERROR, f"internal error: {type(error).__name__} (see the terminal of `bokehfit view`)")

    # --- the transport's side (bokehfit.view.transport.Exchange) ----------------------------

    def begin(self, head: bytes, too_large: bool) -> int | None:
        """Read and check the head; the body's length to read (0: none), or None where the answer is ready."""
        self.rfile = io.BytesIO(head)
        try:
            self.raw_requestline = self.rfile.readline(MAX_REQUEST_LINE_BYTES + 1)
            if len(self.raw_requestline) > MAX_REQUEST_LINE_BYTES:
                raise _Refused(HTTPStatus.REQUEST_URI_TOO_LONG, f"the request line must be at most {MAX_REQUEST_LINE_BYTES} bytes")
            if not self.raw_requestline.endswith(b"\n"):
                raise _Refused(HTTPStatus.BAD_REQUEST, "the request line ended without a line break")
            if not self.raw_requestline.strip():
                raise _Refused(HTTPStatus.BAD_REQUEST, "the request line is empty")
            if too_large:
                raise _Refused(HTTPStatus.REQUEST_HEADER_FIELDS_TOO_LARGE, f"the headers must be at most {MAX_HEADER_BYTES} bytes")
            if not self.parse_request():
                return None  # parse_request answered through send_error
            if self.request_version == "HTTP/0.9":
                self.request_version = "HTTP/1.0"  # answer with a status line all the same
                raise _Refused(HTTPStatus.BAD_REQUEST, "the request line must end with HTTP/1.0 or HTTP/1.1")
            self._route, length = self._check_request()
            return length
        except _Refused as refused:
            self._answer_late(refused.status, refused.message, refused.headers)
        except Exception as error:
            self._internal(error)
        return None

    def respond(self, body: bytes | bytearray) -> None:
        """Run the route of a request that :meth:`begin` accepted, its body read."""
        try:
            self._route(body)
        except _Refused as refused:
            self._answer_late(refused.status, refused.message, refused.headers)
        except InputError as error:
            self._answer_late(HTTPStatus.BAD_REQUEST, str(error))
        except Exception as error:
            self._internal(error)

    def refuse(self, status: int, message: str) -> None:
        self._answer_late(HTTPStatus(status), message)

    def output(self) -> tuple[bytes, ...]:
        return self.wfile.getvalue(), self._body

    # --- the one gate -----------------------------------------------------------------------

    def _check_request(self):
        """The one gate before any route: Host, target, method, header size, body headers, writes.

        Returns the bound method that answers the request and the body's length; raises ``_Refused``.
        """
        hosts = self.headers.get_all("Host") or []
        if len(hosts) != 1:
            raise _Refused(HTTPStatus.BAD_REQUEST, f"a request must carry exactly one Host header (got {len(hosts)})")
        if hosts[0].strip().lower() not in self.server.own_hosts:
            raise _Refused(HTTPStatus.MISDIRECTED_REQUEST, "unknown Host: open the URL that `bokehfit view` printed")
        size = sum(len(name) + len(value) + 4 for name, value in self.headers.items())
        if size > MAX_HEADER_BYTES:
            raise _Refused(HTTPStatus.REQUEST_HEADER_FIELDS_TOO_LARGE, f"the headers must be at most {MAX_HEADER_BYTES} bytes (got {size})")
        try:
            url = urlsplit(self.path)
        except ValueError:  # e.g. an unbalanced [ in an authority
            url = None
        if url is None or not self.path.startswith("/") or url.netloc:
            raise _Refused(HTTPStatus.BAD_REQUEST, "the request target must be a path starting with /")
        allowed = _ROUTES.get(url.path)
        if self.command not in (allowed or _METHODS):
            allow = ", ".join(allowed or _METHODS)
            raise _Refused(HTTPStatus.METHOD_NOT_ALLOWED, f"{self.command[:20]} is not served here (Allow: {allow})", (("Allow", allow),))
        if allowed is None:
            raise _Refused(HTTPStatus.NOT_FOUND, f"no such page: {url.path[:200]}")
        if self.headers.get_all("Transfer-Encoding"):
            raise _Refused(HTTPStatus.LENGTH_REQUIRED, "send the body with a Content-Length (Transfer-Encoding is not read)")
        if self.command == "POST":
            self._check_write(url.path)
            return self._post, self._content_length()
        return self._get, 0

    def _one_header(self, name: str) -> str | None:
        """The value of header ``name``, None where absent; refused where it is given twice."""
        values = self.headers.get_all(name) or []
        if len(values) > 1:
            raise _Refused(HTTPStatus.BAD_REQUEST, f"a request must carry at most one {name} header (got {len(values)})")
        return values[0].strip() if values else None

    def _check_write(self, path: str) -> None:
        """A write comes from the viewer's own page: its Origin, its token and the route's content type.

        A page of another site can make the browser send a POST here (the
        browser names the right Host), but only a "simple" one: without
        custom headers and with a form or text content type, and with its own
        Origin. The token is in the served page only (another site cannot
        read it: no CORS), and any other content type or the token header
        would need a preflight (OPTIONS, answered 405).
        """
        origin = self._one_header("Origin")
        site = self._one_header("Sec-Fetch-Site")
        if origin is not None and origin.lower() not in self.server.own_origins:
            raise _Refused(HTTPStatus.FORBIDDEN, f"writes are taken from the viewer's own page only (Origin {brief(origin)})")
        if site is not None and site.lower() != "same-origin":
            raise _Refused(HTTPStatus.FORBIDDEN, f"writes are taken from the viewer's own page only (Sec-Fetch-Site {brief(site)})")
        if origin is None and site is None:
            raise _Refused(HTTPStatus.FORBIDDEN, "a write must carry the Origin of the viewer's page (or Sec-Fetch-Site: same-origin)")
        token = self._one_header(TOKEN_HEADER)
        if token is None or not hmac.compare_digest(token.encode("latin-1"), self.server.token.encode("latin-1")):
            raise _Refused(HTTPStatus.FORBIDDEN, f"a write must carry this run's {TOKEN_HEADER} of the page: reload the page")
        wanted = _POST_TYPES[path]
        given = self._one_header("Content-Type")
        if given is None or given.split(";")[0].strip().lower() != wanted:
            raise _Refused(HTTPStatus.UNSUPPORTED_MEDIA_TYPE, f"POST {path} takes Content-Type: {wanted} (got {brief(given)})")

    def _content_length(self) -> int:
        """The POST body's declared length: one Content-Length, 1 byte to MAX_BODY_BYTES."""
        values = self.headers.get_all("Content-Length") or []
        if not values:
            raise _Refused(HTTPStatus.LENGTH_REQUIRED, "a POST request must carry a Content-Length")
        if len(values) != 1 or not values[0].strip().isdigit() or not values[0].strip().isascii():
            raise _Refused(HTTPStatus.BAD_REQUEST, "the Content-Length must be one decimal number")
        digits = values[0].strip()
        if len(digits) > 12 or int(digits) > MAX_BODY_BYTES:
            raise _Refused(HTTPStatus.REQUEST_ENTITY_TOO_LARGE, f"the body must be at most {MAX_BODY_BYTES >> 20} MiB")
        if int(digits) == 0:
            raise _Refused(HTTPStatus.BAD_REQUEST, f"the body is empty: send {_POST_BODIES[urlsplit(self.path).path]}")
        return int(digits)

    # --- the routes -------------------------------------------------------------------------

    def _get(self, body: bytes) -> None:
        url = urlsplit(self.path)
        try:
            if url.path in _STATIC:
                name, content_type = _STATIC[url.path]
                page = self.server.page if name == "index.html" else _static_file(name)
                return self._send(HTTPStatus.OK, page, content_type)
            if url.path == "/pathtrace.wgsl":
                return self._send(HTTPStatus.OK, _pathtrace_bytes(self.server.scene_name), "text/wgsl; charset=utf-8")
            if url.path == "/display.wgsl":
                return self._send(HTTPStatus.OK, display_source().encode("utf-8"), "text/wgsl; charset=utf-8")
            if url.path == "/config.json":
                return self._json(HTTPStatus.OK, viewer_config(self.server.scene_name, self.server.size))
            if url.path == "/params.json":
                return self._json(HTTPStatus.OK, params_for_query(parse_qs(url.query), self.server.scene_name, self.server.masks))
            if url.path == "/mask_table":
                table = self.server.masks.gpu_bytes((parse_qs(url.query).get("mask") or [None])[-1])
                return self._send(HTTPStatus.OK, table, "application/octet-stream")
            if url.path == "/favicon.ico":
                return self._send(HTTPStatus.NO_CONTENT, b"", "image/x-icon")
            if url.path in _PHOTO_STATIC or url.path in _PHOTO_GET:
                return self._photo_get(url)
        except InputError as error:
            return self._error(HTTPStatus.BAD_REQUEST, str(error))
        raise RuntimeError(f"route {url.path!r} is in _ROUTES but has no answer")

    def _photo_session(self):
        if self.server.photo is None:
            raise _Refused(HTTPStatus.NOT_FOUND, "no photo here: start `bokehfit view PHOTO` to compare one")
        return self.server.photo

    def _photo_get(self, url) -> None:
        session = self._photo_session()
        if url.path in _PHOTO_STATIC:
            name, content_type = _PHOTO_STATIC[url.path]
            return self._send(HTTPStatus.OK, self.server.photo_page if name == "photo.html" else _static_file(name), content_type)
        if url.path == "/photo/info.json":
            return self._json(HTTPStatus.OK, {**session.info(), "kernel": kernel_config()})
        if url.path == "/photo/kernel_mc.wgsl":
            return self._send(HTTPStatus.OK, kernel_source().encode("utf-8"), "text/wgsl; charset=utf-8")
        if url.path == "/photo/image.jpg":
            return self._send(HTTPStatus.OK, session.display_jpeg, "image/jpeg")
        query = parse_qs(url.query)
        job = query_int(query, "job", session.auto_job)
        if url.path == "/photo/job":
            return self._json(HTTPStatus.OK, session.status(job))
        result = session.result(job)
        if url.path == "/photo/result.json":
            headers = (("Content-Disposition", f'inline; filename="{_download_stem(session.name)}.json"'),)
            return self._send(HTTPStatus.OK, _photo_json_bytes(result), "application/json; charset=utf-8", headers)
        if url.path == "/photo/tiles.json":
            from bokehfit.report.html import aperture_diagram

            aperture = result["json"]["aperture"]
            svg = aperture_diagram(aperture) if aperture.get("shape") is not None else None
            return self._json(HTTPStatus.OK, {"job": job, "tiles": result["tiles"], "aperture_svg": svg, "summary": result["summary"]})
        headers = (("Content-Disposition", f'inline; filename="{_download_stem(session.name)}.html"'),)
        return self._send(HTTPStatus.OK, result["html"].encode("utf-8"), "text/html; charset=utf-8", headers)

    def _photo_post(self, path: str, body: bytes | bytearray) -> None:
        session = self._photo_session()
        with collector_paused():
            document = parse_json_body(body, object_only=True)
        if path == "/photo/refit":
            return self._json(HTTPStatus.ACCEPTED, {"job": session.refit(document)})
        if path == "/photo/cancel":
            return self._json(HTTPStatus.OK, session.cancel())
        from bokehfit.view.photo import discs_file, refit_labels

        labels, _ = refit_labels({"discs": document.get("discs")}, session.width, session.height)
        return self._json(HTTPStatus.OK, discs_file(labels, session.name, session.sha256, session.width, session.height))

    def _post(self, body: bytes | bytearray) -> None:  # /matched, /mask and the photo's writes
        # One body at a time reaches here (the transport answers bodies on one thread).
        if urlsplit(self.path).path in _PHOTO_POST:
            return self._photo_post(urlsplit(self.path).path, body)
        if urlsplit(self.path).path == "/mask":
            answer = mask_upload(body, self.server.masks)
        else:
            with collector_paused():  # the document is dropped before the collector runs again
                answer = settings_from_compare(parse_json_body(body, object_only=True))
        self._json(HTTPStatus.OK, answer)
