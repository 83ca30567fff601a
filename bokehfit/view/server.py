"""The viewer's local web server: its routes, :class:`ViewerServer`, and the limits of its connections.

``bokehfit view`` runs one. Each request is answered by :class:`bokehfit.view.handler.Handler`,
which checks it before any route sees it (its module says how) and then runs its route.

Routes
------
``GET /``, ``/style.css``, ``/viewer.js`` and the modules it imports: ``/viewer_renderer.js``,
``/viewer_points.js``, ``/viewer_topdown.js``, ``/viewer_controls.js``, ``/viewer_files.js``,
``/png_text.js``, ``/common.js`` (the photo page's too)
    The page (package data of :mod:`bokehfit.view`), each file named in the handler's table.
``GET /pathtrace.wgsl``
    The path tracer's WGSL, every include resolved.
``GET /display.wgsl``
    The page's display pass (``shaders/display.wgsl``): the accumulation buffer
    through ``tone_map_srgb8`` of ``shaders/tonemap.wgsl``, the WGSL twin of the
    tone map that ``bokehfit render`` writes PNGs with, into RGBA8.
``GET /config.json``
    Uniform layout, entry points and workgroup sizes (read from the WGSL),
    scene sketch (walls, block, balls, camera), lens constants, shapes,
    slider ranges and the default settings.
``GET /params.json?shape=&angle=&fstop=&focus=&blades=&aspect=&width=&height=&mask=``
    The uniform record's values for these settings (tile = the whole image,
    sample_index 0), the lens as text and JSON, and the depth of field.
    ``mask`` names an uploaded mask (its digest) for shape ``mask``.
    Bad settings: 400 with ``{"error": message}``.
``POST /matched``
    Body (``application/json``): a ``bokehfit compare --json`` document; answer: the viewer
    settings of its fitted aperture (:func:`~bokehfit.view.settings.settings_from_compare`).
``POST /mask``
    Body (``image/png``): an image file (PNG) of transmission, the custom ``mask`` aperture
    of design.md §3b; the server builds its :class:`~bokehfit.apertures.MaskTable`
    (:func:`~bokehfit.apertures.mask.decode_mask`, the same code as
    ``--mask`` of the command line), keeps the last ``MAX_MASKS`` by digest
    and answers the digest, size and the URL of its tables.
``GET /mask_table?mask=DIGEST``
    The mask's CDF tables as little-endian float32 (``MaskTable.gpu_table``):
    the contents of the path tracer's ``mask_table`` binding, which the page
    uploads as they are.

``GET /photo``, ``/photo.js`` and the modules it imports: ``/photo_state.js``, ``/photo_draw.js``,
``/photo_edit.js``, ``/photo_results.js``, ``/photo_match.js``, ``/photo_kernel.js``,
``/photo_refit.js`` (and ``/common.js``, above); ``/photo/info.json``, ``/photo/image.jpg``
    With a photo (``bokehfit view PHOTO``, :mod:`bokehfit.view.photo`): its page,
    its name, size, sha256 and the shapes a refit may try, and its display copy.
    ``info.json`` also says how to run the kernel renderer (:func:`~bokehfit.view.wgsl.kernel_config`).
``GET /photo/kernel_mc.wgsl``
    The Monte-Carlo kernel renderer (``shaders/kernel_mc.wgsl``, every include
    resolved, as :mod:`bokehfit.kernels.mc` compiles it): the page draws each
    fitted disc's kernel with it, packing its ``KernelParams`` and ``ApertureParams``
    by the layouts in ``info.json``.
``GET /photo/job?job=N``, ``/photo/result.json?job=N``, ``/photo/tiles.json?job=N``, ``/photo/report.html?job=N``
    A compare's state (running with its stage, done, failed, cancelled); once
    done, its ``compare --json`` document, its disc tiles (with what the kernel
    needs: :func:`bokehfit.view.photo.kernel_tile`) and aperture diagram,
    and its HTML report (job 0, the default: the automatic compare).
``POST /photo/refit``, ``/photo/cancel``, ``/photo/discs-file``
    Start a compare on exactly the page's discs (``{"discs": [{"center_xy":
    [x, y], "diameter_px": D}], "shapes": [...]}``, checked by
    :func:`bokehfit.view.photo.refit_labels`; 202 with its job), stop the one
    running, or answer the picks as a discs file (the labels' format).
    Without a photo every ``/photo`` route answers 404.

Every other path answers 404, and a route asked with a method it does not
serve answers 405 with ``Allow``.

The server listens on 127.0.0.1 only. Its connections are served by
:mod:`bokehfit.view.transport` on one event loop: the whole request head must
arrive within ``REQUEST_TIMEOUT_S`` of the connection and a body within that
plus its length at ``MIN_TRANSFER_RATE`` (408 after; a connection that sent
nothing is closed); at most ``MAX_CONNECTIONS`` sockets, a new one closing the
oldest idle one; one request per connection. Complete requests are answered on
a few threads, bodies one at a time and at most ``BODY_MEMORY_BYTES`` of them
held at once.
"""

from __future__ import annotations

import socket
import threading

from bokehfit.errors import InputError, check_finite
from bokehfit.scene import SCENES, Scene, build_scene, make_settings
from bokehfit.view.bodies import MAX_BODY_BYTES
from bokehfit.view.handler import MAX_HEADER_BYTES, MAX_REQUEST_LINE_BYTES, Handler, Site
from bokehfit.view.settings import DEFAULT_SIZE
from bokehfit.view.transport import Limits, Transport, log_line
from bokehfit.view.wgsl import display_source, pathtrace_source_cached

__all__ = ["ViewerServer"]

#: Largest head as received (request line, headers, line breaks): the transport
#: stops reading there and the request is answered 431 (bytes).
MAX_HEAD_BYTES = MAX_REQUEST_LINE_BYTES + MAX_HEADER_BYTES + 1024
#: The whole request head must arrive within this long of the connection; one
#: that sent nothing by then is closed (s).
REQUEST_TIMEOUT_S = 5.0
#: Slowest body or answer accepted: each has REQUEST_TIMEOUT_S plus its length
#: at this rate (bytes/s; loopback moves gigabytes a second).
MIN_TRANSFER_RATE = float(2**20)
#: Sockets open at once; a new one beyond closes the oldest idle one (at most
#: the process's file limit less a reserve: bokehfit.view.transport).
MAX_CONNECTIONS = 1024
LISTEN_BACKLOG = 256
#: Bodies held in memory at once, by declared length (bytes): the others wait
#: unread. One body at a time is parsed or decoded.
BODY_MEMORY_BYTES = 2 * MAX_BODY_BYTES
#: Threads that answer complete requests.
WORKERS = 4
#: After answering, the server reads what the client still sends (a body it
#: refused unread) for at most this long and this much before it closes the
#: socket, so that the close does not reset the connection before the client
#: has read the answer (s, bytes).
LINGER_S = 2.0
LINGER_BYTES = MAX_BODY_BYTES


class ViewerServer:
    """The viewer's HTTP server on 127.0.0.1 (``port=0``: any free port).

    ``request_timeout_s``: the whole request head must arrive within this
    long of the connection (408 after; a connection that sent nothing is
    closed), and a body within this long plus its length at
    ``MIN_TRANSFER_RATE`` bytes/s. ``max_connections``: sockets open at once
    (idle ones are closed to make room). Use ``serve_forever()`` in the
    foreground, or ``start()`` for a background thread (tests); ``close()``
    stops it. A context manager.

    Examples
    --------
    >>> with ViewerServer(port=0).start() as server:  # doctest: +SKIP
    ...     print(server.url)
    http://127.0.0.1:54321/
    """

    def __init__(
        self,
        port: int = 0,
        *,
        scene: str = "cornell",
        size: tuple[int, int] = DEFAULT_SIZE,
        verbose: bool = False,
        request_timeout_s: float = REQUEST_TIMEOUT_S,
        max_connections: int = MAX_CONNECTIONS,
        photo=None,
    ):
        if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
            raise InputError(f"port must be an integer from 0 to 65535 (got {port!r})")
        if check_finite("request_timeout_s", request_timeout_s) <= 0:
            raise InputError(f"request_timeout_s must be greater than 0 (got {request_timeout_s!r})")
        if isinstance(max_connections, bool) or not isinstance(max_connections, int) or max_connections < 1:
            raise InputError(f"max_connections must be a positive integer (got {max_connections!r})")
        if scene not in SCENES or not isinstance(build_scene(scene), Scene):
            raise InputError(f"the viewer path-traces the scene 'cornell' (got {scene!r})")
        make_settings(size[0], size[1], 1)  # validates the size
        # Build the shaders now: a broken install fails here, not in the browser.
        pathtrace_source_cached(scene, False)
        display_source()
        session = None
        if photo is not None:  # read the photo first: a bad one is refused before the socket opens
            from bokehfit.view.photo import PhotoSession

            session = photo if isinstance(photo, PhotoSession) else PhotoSession(photo)
        try:
            self._listener = socket.create_server(("127.0.0.1", port), backlog=LISTEN_BACKLOG)
        except BaseException:
            if session is not None:
                session.close()
            raise
        self._site = Site(self.port, scene, tuple(size), verbose, session)
        limits = Limits(
            request_timeout_s=float(request_timeout_s),
            min_rate_bytes_per_s=MIN_TRANSFER_RATE,
            max_head_bytes=MAX_HEAD_BYTES,
            max_connections=max_connections,
            body_memory_bytes=BODY_MEMORY_BYTES,
            workers=WORKERS,
            linger_s=LINGER_S,
            linger_bytes=LINGER_BYTES,
        )
        self._transport = Transport(self._listener, lambda: Handler(self._site), limits, log_line)
        self._thread: threading.Thread | None = None

    @property
    def host(self) -> str:
        return self._listener.getsockname()[0]

    @property
    def port(self) -> int:
        return self._listener.getsockname()[1]

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}/"

    @property
    def photo(self):
        """The :class:`~bokehfit.view.photo.PhotoSession` of ``bokehfit view PHOTO`` (None without a photo)."""
        return self._site.photo

    @property
    def photo_url(self) -> str | None:
        """The photo's page (None without a photo)."""
        return None if self._site.photo is None else f"{self.url}photo"

    @property
    def token(self) -> str:
        """This run's write token (the page receives it in its HTML)."""
        return self._site.token

    @property
    def max_connections(self) -> int:
        """Sockets open at once: ``max_connections``, or fewer where the process's file limit is lower."""
        return self._transport.cap

    def serve_forever(self) -> None:
        """Serve until :meth:`close` (from another thread) or Ctrl-C (KeyboardInterrupt)."""
        self._transport.run()

    def start(self) -> ViewerServer:
        """Serve from a daemon thread; returns self."""
        self._thread = threading.Thread(target=self.serve_forever, name="bokehfit-view", daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        """Stop serving (if started in a thread) and close the socket."""
        self._transport.stop()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        self._listener.close()
        if self._site.photo is not None:
            self._site.photo.close()

    def __enter__(self) -> ViewerServer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
