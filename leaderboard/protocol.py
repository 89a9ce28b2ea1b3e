"""uvicorn's h11 HTTP/1.1 protocol with the limits a public service needs.

uvicorn (0.54) has no deadline for a request's head: a connection that sends nothing, or a few
bytes of headers and then nothing, is held for ever, and its keep-alive timer is cancelled by
any byte. It also answers a head over h11's size limit (``h11_max_incomplete_event_size``)
with a plain-text 400 and closes at once, while the client is still sending, so the client
sees a connection reset. :class:`GuardedH11Protocol` adds:

* a **head deadline**: from the moment a connection waits for a request (when it is made,
  and after each response) the request line and headers must arrive within
  ``header_timeout_s``, however slowly they trickle; else the connection is closed (with a
  408 when part of a head had arrived);
* **431** for a head over the size limit, and every error this layer answers (400, 408, 431)
  as JSON for ``/api/*`` and HTML otherwise, with the service's security headers;
* a **lingering close** after such an error: the answer is sent, the write side shut, and
  what the client still sends is read and dropped (at most ``linger_bytes``, at most
  ``linger_s``), so the client reads the answer instead of a reset;
* a **bounded shutdown**: on SIGTERM a request whose body is still arriving has
  ``body_grace_s`` to finish it; then its connection is closed, so its handler sees the client
  gone and ends (an upload removes its temporary file) before uvicorn's own deadline
  (``timeout_graceful_shutdown``) would cancel it.

A request's body is the app's business (the upload handler has its own deadlines).
"""

from __future__ import annotations

import asyncio
import html
import json
from collections.abc import Mapping
from typing import Any

import h11
from uvicorn.protocols.http.h11_impl import H11Protocol

H11_DEFAULT_HEAD_BYTES = 16 * 1024
"""h11's own limit on a request's line and headers when uvicorn is given none."""
REASONS = {400: "Bad Request", 408: "Request Timeout", 431: "Request Header Fields Too Large"}


def error_body(status: int, message: str, *, api: bool) -> tuple[bytes, str]:
    """An error's body and content type: ``{"error", "status"}`` JSON for the API, else a
    small HTML page (escaped; no script, no inline style)."""
    if api:
        body = json.dumps({"error": message, "status": status}).encode("utf-8")
        return body, "application/json"
    title = html.escape(f"{status} {REASONS.get(status, 'Error')}")
    page = (
        "<!doctype html><html lang='en'><head><meta charset='utf-8'>"
        f"<title>{title}</title><link rel='stylesheet' href='/assets/board.css'></head>"
        f"<body><main><h1>{title}</h1><p>{html.escape(message)}</p>"
        "<p><a href='/'>Back to the board</a></p></main></body></html>"
    )
    return page.encode("utf-8"), "text/html; charset=utf-8"


class GuardedH11Protocol(H11Protocol):
    """uvicorn's :class:`H11Protocol` with a head deadline, 431 and lingering close (see the
    module docstring). Subclass it to set the limits (:func:`guarded_protocol`)."""

    header_timeout_s: float = 10.0
    linger_s: float = 2.0
    linger_bytes: int = 4 << 20
    body_grace_s: float = 4.0
    security_headers: Mapping[str, str] = {}

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._head_timer: asyncio.TimerHandle | None = None
        self._linger_timer: asyncio.TimerHandle | None = None
        self._grace_timer: asyncio.TimerHandle | None = None
        self._lingering = False
        self._dropped = 0
        size = self.config.h11_max_incomplete_event_size
        self._max_head = H11_DEFAULT_HEAD_BYTES if size is None else size

    # -- the head deadline -------------------------------------------------------------------

    def _arm_head_timer(self) -> None:
        self._cancel_head_timer()
        self._head_timer = self.loop.call_later(self.header_timeout_s, self._head_timed_out)

    def _cancel_head_timer(self) -> None:
        if self._head_timer is not None:
            self._head_timer.cancel()
            self._head_timer = None

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._arm_head_timer()

    def data_received(self, data: bytes) -> None:
        if self._lingering:
            self._dropped += len(data)
            if self._dropped > self.linger_bytes:
                self.transport.close()
            return
        cycle = self.cycle
        super().data_received(data)
        if self.cycle is not cycle:  # a request's head arrived: the app has it now
            self._cancel_head_timer()

    def on_response_complete(self) -> None:
        cycle = self.cycle
        super().on_response_complete()
        if self.transport.is_closing() or self._lingering:
            self._cancel_head_timer()
        elif self.cycle is cycle:  # waiting for the next request (or the rest of this body)
            self._arm_head_timer()
        else:  # a pipelined request started at once
            self._cancel_head_timer()

    def _head_timed_out(self) -> None:
        self._head_timer = None
        if self.transport.is_closing() or self._lingering:
            return
        if self.cycle is not None and not self.cycle.response_complete:
            return  # a request is being answered; its handler keeps its own deadlines
        partial = self.conn.our_state is h11.IDLE and bool(self.conn.trailing_data[0])
        if partial:
            self._answer(
                408,
                f"request: expected its line and headers within {self.header_timeout_s:g} s, "
                "found them incomplete",
            )
        else:
            self.transport.close()

    # -- errors of this layer ----------------------------------------------------------------

    def send_400_response(self, msg: str) -> None:
        """h11 refused the request: 431 when the head is over the size limit, else 400."""
        if len(self.conn.trailing_data[0]) > self._max_head:
            self._answer(
                431,
                f"request: expected a request line and headers of at most {self._max_head} "
                "bytes, found more",
            )
        else:
            self._answer(400, f"request: expected valid HTTP/1.1, found otherwise ({msg})")

    def _answer(self, status: int, message: str) -> None:
        """Write an error answer by hand (h11's state machine is in error or idle), then
        close lingering."""
        self._cancel_head_timer()
        head = self.conn.trailing_data[0][:2048]
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
        self.transport.write(("\r\n".join(lines) + "\r\n\r\n").encode("latin-1") + body)
        self._lingering = True
        if self.transport.can_write_eof():
            self.transport.write_eof()
        self.transport.resume_reading()
        self._linger_timer = self.loop.call_later(self.linger_s, self.transport.close)

    def shutdown(self) -> None:
        """uvicorn's graceful shutdown of this connection, with a deadline for a body still
        arriving."""
        if self._lingering:
            self.transport.close()
            return
        super().shutdown()
        receiving = self.cycle is not None and not self.cycle.response_complete
        if receiving and self.conn.their_state is h11.SEND_BODY:
            self._grace_timer = self.loop.call_later(self.body_grace_s, self._abandon)

    def _abandon(self) -> None:
        self._grace_timer = None
        if self.conn.their_state is h11.SEND_BODY and not self.transport.is_closing():
            self.transport.close()  # the handler's next read sees the client gone

    def connection_lost(self, exc: Exception | None) -> None:
        self._cancel_head_timer()
        for timer in (self._linger_timer, self._grace_timer):
            if timer is not None:
                timer.cancel()
        self._linger_timer = self._grace_timer = None
        super().connection_lost(exc)


def guarded_protocol(
    *, header_timeout_s: float, body_grace_s: float, security_headers: Mapping[str, str]
) -> type[GuardedH11Protocol]:
    """A :class:`GuardedH11Protocol` class with these limits (uvicorn's ``http=`` option)."""
    return type(
        "ServiceH11Protocol",
        (GuardedH11Protocol,),
        {
            "header_timeout_s": header_timeout_s,
            "body_grace_s": body_grace_s,
            "security_headers": dict(security_headers),
        },
    )
