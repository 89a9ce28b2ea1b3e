"""The service's connections: a guard in front of uvicorn's h11 HTTP/1.1 protocol with the
limits a public service needs and that uvicorn's settings do not give.

uvicorn has no deadline for a request's head: a connection that sends nothing, or a few bytes
of headers and then nothing, is held for ever (``timeout_keep_alive`` only starts after a
response, and any byte cancels it). It also answers a head over the size limit
(``h11_max_incomplete_event_size``) or malformed with a plain-text 400 and closes at once,
while the client is still sending, so the client sees a connection reset. An ASGI middleware
cannot help: the app is called once a whole, valid head has arrived.

:class:`GuardedConnection` is an :class:`asyncio.Protocol` that *wraps* (not subclasses) the
protocol uvicorn would run (``uvicorn.Config(http=...)`` takes a protocol class), handing it the
bytes and a transport it watches, and reading the same bytes with its own h11 parser (h11's
public API only). It adds:

* a **head deadline**: from the moment a connection waits for a request (when it is made, and
  after each response) the request line and headers must arrive within ``header_timeout_s``,
  however slowly they trickle; else the connection is closed (with a 408 when part of a head
  had arrived);
* **431** for a head over the size limit, **400** for a malformed request, each (and the 408)
  as JSON for ``/api/*`` and HTML otherwise, with the service's security headers, answered
  before uvicorn sees the bytes;
* a **lingering close** after such an error: the answer is sent, the write side shut, and what
  the client still sends is read and dropped (at most ``linger_bytes``, at most ``linger_s``),
  so the client reads the answer instead of a reset.

A request's body is the app's business (the upload handler has its own deadlines); on SIGTERM,
requests still in flight after uvicorn's ``timeout_graceful_shutdown`` are cancelled (an
upload's temporary file is removed).

Imports h11, uvicorn's h11 protocol (run, not subclassed) and :mod:`leaderboard.http_errors`.
"""

from __future__ import annotations

import asyncio
from collections.abc import Mapping
from typing import Any

import h11

from .http_errors import REASONS, error_body

H11_DEFAULT_HEAD_BYTES = 16 * 1024
"""h11's own limit on a request's line and headers when uvicorn is given none."""
INVALID = "Invalid HTTP request received."
"""What a malformed request is called in the 400's message (uvicorn's words)."""


class _WatchedTransport:
    """The transport the wrapped protocol writes to: the connection's own, with its writes
    shown to the guard (to see when a response ends), and dropped once the guard answered
    the connection itself."""

    def __init__(self, guard: GuardedConnection, transport: asyncio.Transport):
        self._guard, self._transport = guard, transport

    def write(self, data: bytes | bytearray | memoryview) -> None:
        if self._guard.lingering:
            return
        self._transport.write(data)
        self._guard.response_written(bytes(data))

    def writelines(self, chunks: Any) -> None:
        for chunk in chunks:
            self.write(chunk)

    def close(self) -> None:
        if not self._guard.lingering:  # a lingering close ends on the guard's timer
            self._transport.close()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._transport, name)


class GuardedConnection(asyncio.Protocol):
    """uvicorn's HTTP protocol (:attr:`inner_class`) behind a head deadline, 431/400 answers
    and a lingering close (see the module docstring). Subclass it to set the limits
    (:func:`guarded_connection`); uvicorn builds it with the wrapped protocol's arguments."""

    inner_class: type[asyncio.Protocol]
    header_timeout_s: float = 10.0
    max_head_bytes: int = H11_DEFAULT_HEAD_BYTES
    linger_s: float = 2.0
    linger_bytes: int = 4 << 20
    security_headers: Mapping[str, str] = {}

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.inner: Any = self.inner_class(*args, **kwargs)
        self.loop = kwargs.get("_loop") or asyncio.get_event_loop()
        self.transport: asyncio.Transport | None = None
        self.requests = h11.Connection(h11.SERVER, max_incomplete_event_size=self.max_head_bytes)
        self.response: h11.Connection | None = None  # reads the answer to the request in hand
        self.tracking = True  # False once the parser lost step (uvicorn's own handling then)
        self.lingering = False
        self._answered = False  # bytes of the answer to the request in hand were written
        self._dropped = 0
        self._head_timer: asyncio.TimerHandle | None = None
        self._linger_timer: asyncio.TimerHandle | None = None

    # -- asyncio.Protocol --------------------------------------------------------------------

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        self.inner.connection_made(_WatchedTransport(self, transport))
        self._arm_head_timer()

    def data_received(self, data: bytes) -> None:
        if self.lingering:
            self._dropped += len(data)
            if self._dropped > self.linger_bytes and self.transport is not None:
                self.transport.close()
            return
        if self.tracking:
            self.requests.receive_data(data)
            if self._read_requests():
                return  # answered here: uvicorn never sees these bytes
        self.inner.data_received(data)

    def eof_received(self) -> bool | None:
        return self.inner.eof_received()

    def pause_writing(self) -> None:
        self.inner.pause_writing()

    def resume_writing(self) -> None:
        self.inner.resume_writing()

    def connection_lost(self, exc: Exception | None) -> None:
        self._cancel_head_timer()
        if self._linger_timer is not None:
            self._linger_timer.cancel()
            self._linger_timer = None
        self.inner.connection_lost(exc)

    # -- following the requests and their answers --------------------------------------------

    def _read_requests(self) -> bool:
        """Read what the parser can; True when this connection was answered here (an
        invalid or oversized request)."""
        conn = self.requests
        while True:
            try:
                event = conn.next_event()
            except h11.RemoteProtocolError:
                return self._invalid()
            if event is h11.NEED_DATA or event is h11.PAUSED:
                return False
            if isinstance(event, h11.Request):  # a whole head: the app has it now
                self._cancel_head_timer()
                self._expect_response(event.method)
            elif isinstance(event, h11.EndOfMessage):
                # the answer may have come first (an early refusal); as uvicorn does, nothing
                # after the end of a request that closes the connection is read
                if not self._next_cycle() and conn.their_state is h11.MUST_CLOSE:
                    return False
            elif isinstance(event, h11.ConnectionClosed):
                return False

    def _expect_response(self, method: bytes) -> None:
        """Start reading the answer to a request made with ``method`` (its framing depends on
        it: no body for HEAD)."""
        response = h11.Connection(h11.CLIENT)
        method = b"GET" if method == b"CONNECT" else method
        response.send(h11.Request(method=method, target=b"/", headers=[(b"host", b"guard")]))
        response.send(h11.EndOfMessage())
        self.response, self._answered = response, False

    def response_written(self, data: bytes) -> None:
        """The wrapped protocol wrote ``data``; at the end of an answer, the connection waits
        for the next request's head (its deadline starts)."""
        response = self.response
        if not self.tracking or response is None or not data:
            return
        self._answered = True
        response.receive_data(data)
        while True:
            try:
                event = response.next_event()
            except h11.RemoteProtocolError:
                self._stop_tracking()
                return
            if event is h11.NEED_DATA or event is h11.PAUSED:
                return
            if isinstance(event, h11.EndOfMessage):
                self._response_done()
                return

    def _response_done(self) -> None:
        self.response, self._answered = None, False
        try:
            self.requests.send(h11.Response(status_code=200, headers=[(b"content-length", b"0")]))
            self.requests.send(h11.EndOfMessage())
        except h11.LocalProtocolError:
            self._stop_tracking()
            return
        if self._next_cycle():
            self._read_requests()  # pipelined bytes the parser held

    def _next_cycle(self) -> bool:
        """Wait for the next request once both sides are done with this one; True if so."""
        conn = self.requests
        if conn.our_state is not h11.DONE or conn.their_state is not h11.DONE:
            return False
        conn.start_next_cycle()
        if self.transport is not None and not self.transport.is_closing():
            self._arm_head_timer()
        return True

    def _stop_tracking(self) -> None:
        self.tracking, self.response = False, None
        self._cancel_head_timer()

    # -- the head deadline -------------------------------------------------------------------

    def _arm_head_timer(self) -> None:
        self._cancel_head_timer()
        self._head_timer = self.loop.call_later(self.header_timeout_s, self._head_timed_out)

    def _cancel_head_timer(self) -> None:
        if self._head_timer is not None:
            self._head_timer.cancel()
            self._head_timer = None

    def _head_timed_out(self) -> None:
        self._head_timer = None
        transport = self.transport
        if transport is None or transport.is_closing() or self.lingering or not self.tracking:
            return
        if self.response is not None or self.requests.their_state is not h11.IDLE:
            return  # a request is being answered; its handler keeps its own deadlines
        if self.requests.trailing_data[0]:
            self._answer(
                408,
                f"request: expected its line and headers within {self.header_timeout_s:g} s, "
                "found them incomplete",
            )
        else:
            transport.close()

    # -- errors of this layer ----------------------------------------------------------------

    def _invalid(self) -> bool:
        """The parser refused the request: 431 when the head is over the size limit, else
        400; True when answered here (False: an answer had begun, uvicorn handles it)."""
        if self._answered:
            self._stop_tracking()
            return False
        if len(self.requests.trailing_data[0]) > self.max_head_bytes:
            self._answer(
                431,
                f"request: expected a request line and headers of at most "
                f"{self.max_head_bytes} bytes, found more",
            )
        else:
            self._answer(400, f"request: expected valid HTTP/1.1, found otherwise ({INVALID})")
        return True

    def _answer(self, status: int, message: str) -> None:
        """Write an error answer by hand, then close lingering; the wrapped protocol's writes
        are dropped from now on."""
        transport = self.transport
        assert transport is not None
        self._stop_tracking()
        head = self.requests.trailing_data[0][:2048]
        target = head.split(b"\r\n", 1)[0].split(b" ")
        api = len(target) > 1 and target[1].startswith(b"/api/")
        body, content_type = error_body(status, message, api=api)
        lines = [
            f"HTTP/1.1 {status} {REASONS.get(status, 'Error')}",
            f"content-type: {content_type}",
            f"content-length: {len(body)}",
            "connection: close",
            *(f"{name.lower()}: {value}" for name, value in self.security_headers.items()),
        ]
        if api:
            lines.append("cache-control: no-store")
        transport.write(("\r\n".join(lines) + "\r\n\r\n").encode("latin-1") + body)
        self.lingering = True
        if transport.can_write_eof():
            transport.write_eof()
        transport.resume_reading()
        self._linger_timer = self.loop.call_later(self.linger_s, transport.close)


def guarded_connection(
    *,
    header_timeout_s: float,
    max_head_bytes: int,
    security_headers: Mapping[str, str],
    inner_class: type[asyncio.Protocol] | None = None,
) -> type[GuardedConnection]:
    """A :class:`GuardedConnection` class with these limits, for uvicorn's ``http=`` option;
    it runs ``inner_class`` (default: uvicorn's h11 protocol, ``http="h11"``)."""
    if inner_class is None:
        from uvicorn.protocols.http.h11_impl import H11Protocol

        inner_class = H11Protocol
    return type(
        "ServiceConnection",
        (GuardedConnection,),
        {
            "inner_class": inner_class,
            "header_timeout_s": header_timeout_s,
            "max_head_bytes": max_head_bytes,
            "security_headers": dict(security_headers),
        },
    )
