"""Check that a ``--scheduler`` address is a Dask scheduler before Dask connects to it.

Dask's own connect waits without end on a port that accepts and never answers,
and allocates whatever size the first eight bytes of an answer claim (garbage
claims exabytes). :func:`check_scheduler` speaks the first step of Dask's TCP
protocol itself, within :data:`CONNECT_TIMEOUT_S`: a scheduler sends its
handshake as soon as a connection is accepted, one small framed message
(8-byte little-endian length, then msgpack frames naming ``compression``,
``python`` and ``pickle-protocol``). Anything else is refused in one line.

Supported addresses: ``tcp://HOST:PORT`` (or ``HOST:PORT``), ``tls://HOST:PORT``
(with Dask's TLS configuration, ``distributed.comm.tls.*``) and ``inproc://``
(a cluster in this process). Others (``ucx://``, ``ws://``) are refused.
"""

from __future__ import annotations

import socket
import ssl
import struct
import time

from bokehfit.errors import InputError

__all__ = ["CONNECT_TIMEOUT_S", "HANDSHAKE_MAX_BYTES", "check_scheduler"]

#: Seconds to connect to a scheduler and receive its handshake: a scheduler on a loaded
#: machine across a network answers in well under a second; Dask's own default is 30 s.
CONNECT_TIMEOUT_S = 10.0
#: Largest handshake accepted: Dask's is about 60 bytes (three short keys and values).
HANDSHAKE_MAX_BYTES = 1 << 16
#: Keys every Dask handshake holds (``distributed.comm.core.Comm.handshake_info``).
_HANDSHAKE_KEYS = (b"compression", b"python", b"pickle-protocol")
_SCHEMES = ("tcp", "tls", "inproc")


def _refuse(address: str, why: str) -> InputError:
    return InputError(f"--scheduler {address!r}: {why}")


def _host_port(address: str, rest: str) -> tuple[str, int]:
    host, _, port = rest.rpartition(":")
    host = host.strip("[]")
    try:
        number = int(port)
    except ValueError:
        number = -1
    if not host or not 0 < number < 65536:
        raise _refuse(address, "give the scheduler as tcp://HOST:PORT (for example tcp://10.0.0.5:8786)")
    return host, number


def _receive(connection, size: int, deadline: float, address: str) -> bytes:
    data = b""
    while len(data) < size:
        left = deadline - time.monotonic()
        if left <= 0:
            raise socket.timeout
        connection.settimeout(left)
        chunk = connection.recv(size - len(data))
        if not chunk:
            raise _refuse(address, "the connection was closed without a Dask handshake; is it a Dask scheduler's port?")
        data += chunk
    return data


def check_scheduler(address, timeout_s: float = CONNECT_TIMEOUT_S) -> None:
    """``InputError`` unless ``address`` answers as a Dask scheduler within ``timeout_s`` seconds.

    ``address`` that is not text (a connected ``distributed.Client``) is left to Dask.
    """
    if not isinstance(address, str):
        return
    scheme, separator, rest = address.partition("://")
    if not separator:
        scheme, rest = "tcp", address
    if scheme not in _SCHEMES:
        raise _refuse(address, f"{scheme}:// is not supported; give a tcp:// or tls:// Dask scheduler address")
    if scheme == "inproc":
        return
    host, port = _host_port(address, rest)
    deadline = time.monotonic() + timeout_s
    try:
        connection = socket.create_connection((host, port), timeout=timeout_s)
    except socket.timeout:
        raise _refuse(address, f"no answer to a connection within {timeout_s:g} s") from None
    except OSError as error:
        raise _refuse(address, f"can't connect ({error.strerror or error})") from None
    try:
        if scheme == "tls":
            context = ssl.create_default_context()
            context.check_hostname, context.verify_mode = False, ssl.CERT_NONE  # only: does it speak TLS?
            connection.settimeout(max(0.001, deadline - time.monotonic()))
            try:
                connection = context.wrap_socket(connection, server_hostname=host)
            except ssl.SSLError as error:
                if "CERTIFICATE" in str(error).upper() or "ALERT" in str(error).upper():
                    return  # a TLS server that wants the client certificate of Dask's configuration: leave it to Dask
                raise _refuse(address, f"it does not speak TLS ({error.reason or error})") from None
        header = _receive(connection, 8, deadline, address)
        (size,) = struct.unpack("<Q", header)
        if not 8 <= size <= HANDSHAKE_MAX_BYTES:
            raise _refuse(address, "it answered, but not as a Dask scheduler (a message of "
                          f"{size} bytes where a handshake of under {HANDSHAKE_MAX_BYTES} is due)")
        handshake = _receive(connection, size, deadline, address)
        if not all(key in handshake for key in _HANDSHAKE_KEYS):
            raise _refuse(address, "it answered, but not with a Dask scheduler's handshake")
        connection.settimeout(max(0.001, deadline - time.monotonic()))
        connection.sendall(header + handshake)  # complete the handshake (Dask's is symmetric), then leave
    except socket.timeout:
        raise _refuse(address, f"it accepted the connection but sent no Dask handshake within {timeout_s:g} s; "
                      "is it a Dask scheduler's port?") from None
    except OSError as error:
        raise _refuse(address, f"the connection failed ({error.strerror or error})") from None
    finally:
        connection.close()
