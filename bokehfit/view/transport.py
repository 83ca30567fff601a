"""The viewer's connections: accept, read each request within its deadlines, answer, close.

One asyncio event loop (``selectors`` underneath) owns every socket, so no
thread ever waits on a client: a connection that sends nothing, trickles its
head or its body, or never reads its answer costs a few kilobytes and is
closed when its deadline passes, whatever it does meanwhile. Only the work of
answering (the routes) runs on a small pool of threads, and only once a
request is complete.

Deadlines (absolute, not per read, so that a byte now and then does not
extend them):

- **head**: the request line and headers must arrive within
  ``request_timeout_s`` of the connection's accept. A connection that sent
  nothing by then (a browser's preconnect, a half-open socket) is closed
  without an answer; one that sent part of a head is answered 408.
- **body**: ``request_timeout_s`` plus the declared length at
  ``min_rate_bytes_per_s``; 408 beyond.
- **answer**: the same rule for writing it; a client that does not read is dropped.

One request per connection: after the answer the server stops sending, reads
(and drops) what the client still sends for at most ``linger_s`` so that the
close does not reset the connection before the client read the answer, and closes.

Bounds: at most ``max_connections`` sockets (never beyond the process's file
limit); a new connection beyond it closes the oldest one that has no request
being answered (lingering, idle, still sending its head, waiting for room for
its body) instead of waiting or being refused, and only where every socket is
busy reading a body or answering does it wait in the listen queue. Bodies held in memory at once are at most
``body_memory_bytes`` by their declared lengths; a body beyond waits for room
(within its body deadline, 503 after) before a byte of it is read.

Why not an async HTTP stack such as uvicorn or aiohttp: what the viewer needed
was a deadline on the whole request head, and uvicorn has none (its keep-alive
timer is reset by every byte received; the ``--timeout-request-start`` of
uvicorn issue #157 was never added), so a stack would have needed the same
deadline code on top, plus a dependency tree, and would answer malformed heads
with its own bare refusals instead of this server's one-line JSON. The
deadlines here are the event loop's timers (``asyncio.wait_for``) around whole
phases, not checks per case.
"""

from __future__ import annotations

import asyncio
import itertools
import socket
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Callable, Protocol

try:
    import resource
except ImportError:  # not POSIX: no file limit to read
    resource = None

__all__ = ["Exchange", "Limits", "Transport", "connection_cap"]

#: File descriptors kept free for everything else in the process (files, pipes, the GPU).
FD_RESERVE = 64
#: Phases of a connection in the order they are closed to make room for a new one:
#: answered, silent, still sending its head, waiting for room for its body.
_EVICTABLE = ("linger", "idle", "head", "queued")


@dataclass(frozen=True)
class Limits:
    """The transport's deadlines and caps; see the module's docstring (the viewer's values: bokehfit.view.server)."""

    request_timeout_s: float
    min_rate_bytes_per_s: float
    max_head_bytes: int
    max_connections: int
    body_memory_bytes: int
    workers: int
    linger_s: float
    linger_bytes: int

    def transfer_s(self, size: int) -> float:
        """Time allowed to move ``size`` bytes of body or answer (s)."""
        return self.request_timeout_s + size / self.min_rate_bytes_per_s


class Exchange(Protocol):
    """One request and its answer, as the transport drives it (:class:`bokehfit.view.handler.Handler` implements it).

    ``begin`` runs on the event loop and must be quick; ``respond`` runs on a
    worker thread. Neither raises: every failure becomes an answer.
    """

    def begin(self, head: bytes, too_large: bool) -> int | None:
        """Read and check the head; the body's length to read (0: none), or None where the answer is ready."""

    def respond(self, body: bytes | bytearray) -> None:
        """Answer the complete request."""

    def refuse(self, status: int, message: str) -> None:
        """Answer with ``status`` and ``message`` (a deadline passed, the body ended early, no room)."""

    def output(self) -> tuple[bytes, ...]:
        """The answer's parts, status line first (none or empty ones where nothing is to be sent).

        Sent as they are, never joined: a large body shared by many answers stays one copy.
        """


class _ByteBudget:
    """Bytes of body that may be held at once, taken by declared length and given back after the answer."""

    def __init__(self, capacity: int):
        self.capacity = capacity
        self.free = capacity
        self._changed = asyncio.Condition()

    async def take(self, size: int) -> None:
        async with self._changed:
            await self._changed.wait_for(lambda: self.free >= size)
            self.free -= size

    async def give_back(self, size: int) -> None:
        async with self._changed:
            self.free += size
            self._changed.notify_all()


@dataclass(eq=False)
class _Connection:
    sock: socket.socket
    accepted: float
    phase: str = "idle"
    task: asyncio.Task | None = None
    evicted: bool = False


def connection_cap(wanted: int) -> int:
    """``wanted``, or fewer where the process's open-file limit would not allow them."""
    if resource is None:
        return wanted
    soft, _ = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft == resource.RLIM_INFINITY:
        return wanted
    return max(1, min(wanted, soft - FD_RESERVE))


def _head_end(buffer: bytearray, start: int) -> int | None:
    """Index just past the blank line that ends the head (CRLF or bare LF), searching from ``start``."""
    ends = [i for i in (buffer.find(b"\n\r\n", start), buffer.find(b"\n\n", start)) if i >= 0]
    if not ends:
        return None
    end = min(ends)
    return end + (3 if buffer[end + 1 : end + 3] == b"\r\n" else 2)


class Transport:
    """Serve ``listener`` (a bound, listening socket) until :meth:`stop`; each request through ``exchange()``.

    ``run()`` blocks (it runs the event loop); ``stop()`` may be called from any thread.
    """

    def __init__(self, listener: socket.socket, exchange: Callable[[], Exchange], limits: Limits, on_error: Callable[[str], None]):
        self.listener = listener
        self.exchange = exchange
        self.limits = limits
        self.cap = connection_cap(limits.max_connections)
        self._on_error = on_error
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stopping: asyncio.Event | None = None
        self._stop_requested = threading.Event()
        self._connections: dict[int, _Connection] = {}
        self._ids = itertools.count()

    # --- life cycle -------------------------------------------------------------------------

    def run(self) -> None:
        asyncio.run(self._main())

    def stop(self) -> None:
        self._stop_requested.set()
        loop, stopping = self._loop, self._stopping
        if loop is not None and stopping is not None:
            try:
                loop.call_soon_threadsafe(stopping.set)
            except RuntimeError:  # the loop has closed already
                pass

    async def _main(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._stopping = asyncio.Event()
        if self._stop_requested.is_set():
            return
        self._freed = asyncio.Event()
        self._budget = _ByteBudget(self.limits.body_memory_bytes)
        self._pool = ThreadPoolExecutor(self.limits.workers, thread_name_prefix="bokehfit-view")
        # Requests with a body are answered one at a time on a thread of their own: the memory
        # of one body's parse at a time, in one allocator arena.
        self._body_pool = ThreadPoolExecutor(1, thread_name_prefix="bokehfit-view-body")
        self.listener.setblocking(False)
        accepting = asyncio.create_task(self._accept_loop())
        stopping = asyncio.create_task(self._stopping.wait())
        try:
            await asyncio.wait({accepting, stopping}, return_when=asyncio.FIRST_COMPLETED)
        finally:
            tasks = [accepting, stopping] + [c.task for c in self._connections.values() if c.task is not None]
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._body_pool.shutdown(wait=False, cancel_futures=True)
            if accepting.done() and not accepting.cancelled() and accepting.exception() is not None:
                raise accepting.exception()

    # --- accepting --------------------------------------------------------------------------

    async def _accept_loop(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            # Beyond the cap with none to close: the next connection waits in the listen queue.
            while self._active() > self.cap and not self._evict_one():
                self._freed.clear()
                await self._freed.wait()
            try:
                sock, _ = await loop.sock_accept(self.listener)
            except (ConnectionAbortedError, InterruptedError):
                continue
            except OSError:  # out of file descriptors or buffers: make room, or wait a moment
                if not self._evict_one():
                    await asyncio.sleep(0.05)
                continue
            sock.setblocking(False)
            connection = _Connection(sock, time.monotonic())
            key = next(self._ids)
            self._connections[key] = connection
            connection.task = asyncio.create_task(self._serve(connection))
            # Closed when the task ends, however it ends (even cancelled before it started).
            connection.task.add_done_callback(lambda _, key=key: self._closed(key))
            if self._active() > self.cap:
                self._evict_one(spare=connection)
            await asyncio.sleep(0)  # let the connections run between accepts

    def _active(self) -> int:
        return sum(1 for c in self._connections.values() if not c.evicted)

    def _evict_one(self, spare: _Connection | None = None) -> bool:
        """Close the oldest connection with no request to answer (but ``spare``); False where there is none."""
        for phase in _EVICTABLE:
            candidates = [c for c in self._connections.values() if c.phase == phase and not c.evicted and c is not spare]
            if candidates:
                victim = min(candidates, key=lambda c: c.accepted)
                victim.evicted = True
                victim.task.cancel()
                return True
        return False

    # --- one connection ---------------------------------------------------------------------

    async def _serve(self, connection: _Connection) -> None:
        try:
            await self._exchange(connection)
        except (asyncio.CancelledError, asyncio.TimeoutError, ConnectionError, TimeoutError):
            pass
        except Exception as error:  # a bug in the transport: one line, the connection dropped
            self._on_error(f"internal error on a connection: {type(error).__name__}: {error}")

    def _closed(self, key: int) -> None:
        connection = self._connections.pop(key)
        try:
            connection.sock.close()
        except OSError:
            pass
        self._freed.set()

    async def _exchange(self, connection: _Connection) -> None:
        limits, sock = self.limits, connection.sock
        exchange = self.exchange()
        buffer = bytearray()
        head_deadline = connection.accepted + limits.request_timeout_s
        try:
            head, rest, too_large = await asyncio.wait_for(self._read_head(connection, buffer), head_deadline - time.monotonic())
        except asyncio.TimeoutError:
            if not buffer:
                return  # nothing asked: close without an answer
            exchange.refuse(408, f"the request did not arrive within {limits.request_timeout_s:g} s")
            return await self._answer(connection, exchange)
        if head is None:
            return  # the client closed without asking
        connection.phase = "body"
        length = exchange.begin(head, too_large)
        if not length:
            if length == 0:
                await self._work(connection, exchange, b"")
            return await self._answer(connection, exchange)
        transfer_s = limits.transfer_s(length)
        connection.phase = "queued"
        try:
            await asyncio.wait_for(self._budget.take(length), transfer_s)
        except asyncio.TimeoutError:
            exchange.refuse(503, "the server is busy reading other uploads: send it again")
            return await self._answer(connection, exchange)
        connection.phase = "body"
        try:
            body = bytearray(length)
            received = min(len(rest), length)
            body[:received] = rest[:received]
            try:
                received = await asyncio.wait_for(self._read_body(sock, body, received), transfer_s)
            except asyncio.TimeoutError:
                exchange.refuse(408, f"the request did not arrive within {transfer_s:g} s")
                return await self._answer(connection, exchange)
            if received < length:
                exchange.refuse(400, f"the body ended after {received} of {length} bytes")
                return await self._answer(connection, exchange)
            await self._work(connection, exchange, body)
            del body
        finally:
            await self._budget.give_back(length)
        await self._answer(connection, exchange)

    async def _read_head(self, connection: _Connection, buffer: bytearray) -> tuple[bytes | None, bytes, bool]:
        """(head, bytes after it, too large): the head up to its blank line, or what came before EOF or the cap."""
        loop = asyncio.get_running_loop()
        cap = self.limits.max_head_bytes
        while True:
            chunk = await loop.sock_recv(connection.sock, 1 << 16)
            if not chunk:
                return (bytes(buffer) if buffer else None), b"", False
            connection.phase = "head"
            searched = max(0, len(buffer) - 2)
            buffer += chunk
            end = _head_end(buffer, searched)
            if end is not None and end <= cap:
                return bytes(buffer[:end]), bytes(buffer[end:]), False
            if len(buffer) > cap:
                return bytes(buffer[:cap]), b"", True

    async def _read_body(self, sock: socket.socket, body: bytearray, received: int) -> int:
        loop = asyncio.get_running_loop()
        view = memoryview(body)
        try:
            while received < len(body):
                n = await loop.sock_recv_into(sock, view[received : received + (1 << 20)])
                if not n:
                    break
                received += n
        finally:
            view.release()
        return received

    async def _work(self, connection: _Connection, exchange: Exchange, body) -> None:
        connection.phase = "work"
        pool = self._body_pool if body else self._pool
        await asyncio.get_running_loop().run_in_executor(pool, exchange.respond, body)

    @staticmethod
    async def _send_all(sock: socket.socket, parts: list[bytes]) -> None:
        loop = asyncio.get_running_loop()
        for part in parts:
            await loop.sock_sendall(sock, part)

    async def _answer(self, connection: _Connection, exchange: Exchange) -> None:
        """Send the answer within its deadline, then linger and close."""
        loop = asyncio.get_running_loop()
        sock, limits = connection.sock, self.limits
        parts = [part for part in exchange.output() if part]
        if sum(map(len, parts)) <= 1 << 16:
            parts = [b"".join(parts)] if parts else []  # a small answer in one write (no Nagle delay between parts)
        if parts:
            connection.phase = "write"
            try:
                await asyncio.wait_for(self._send_all(sock, parts), limits.transfer_s(sum(map(len, parts))))
            except asyncio.TimeoutError:
                return  # the client does not read: drop it
        connection.phase = "linger"
        try:
            sock.shutdown(socket.SHUT_WR)
        except OSError:
            return
        drained = 0
        deadline = time.monotonic() + limits.linger_s
        while drained < limits.linger_bytes:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                break
            try:
                chunk = await asyncio.wait_for(loop.sock_recv(sock, 1 << 16), remaining)
            except (asyncio.TimeoutError, OSError):
                break
            if not chunk:
                break
            drained += len(chunk)


def log_line(message: str) -> None:
    """One line on stderr: a failure the user should report."""
    print(f"bokehfit view: {message}", file=sys.stderr, flush=True)
