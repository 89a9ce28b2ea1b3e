"""A seeded fuzz of the leaderboard service (issue 26): ids, query keys and values, headers,
file names and bodies, against the app in process (600 cases) and raw bytes against a real
server on loopback (150 cases). Target: no 5xx answer, and the security headers on every
error answer (JSON for ``/api/*``)."""

from __future__ import annotations

import contextlib
import socket
import warnings
from typing import Any
from urllib.parse import quote

import httpx
import numpy as np
import pytest
from leaderboard_data import running_service, scored_rows, small_benchmark, valid_submission
from starlette.exceptions import StarletteDeprecationWarning

from leaderboard.app import SECURITY_HEADERS, ServiceConfig, create_app
from leaderboard.board import Board

with warnings.catch_warnings():  # starlette asks for httpx2, which is not installed
    warnings.simplefilter("ignore", StarletteDeprecationWarning)
    from starlette.testclient import TestClient

SEED = 20261202
APP_CASES = 600
RAW_CASES = 150
CSP = SECURITY_HEADERS["Content-Security-Policy"]
IDS = [
    "1",
    "2",
    "3",
    "0",
    "-1",
    "00001",
    str(2**63 - 1),
    str(2**63),
    str(2**64),
    "99999999999999999999",
    "9" * 400,
    "1e9",
    "0x10",
    "1.0",
    "\u0663",
    "²",
    "..",
    "%2e%2e",
    "1;DROP TABLE teams",
    "<script>",
    "",
    " ",
]
TEXT = [
    "",
    "x",
    "mine.h5",
    "../../etc/passwd",
    "a/b.h5",
    "..",
    ".h5",
    "x\x00.h5",
    "fce",
    "fce,gsr",
    "fce,nope",
    "classifier",
    ",,,",
    "1",
    "0",
    "-5",
    "9" * 30,
    str(2**64),
    "<script>alert(1)</script>",
    "\u202e\u0645\u0631\u062d\u0628\u0627",
    "\U0001f600" * 20,
    "a" * 5000,
    "%00",
    "'; --",
]
KEYS = ["page", "limit", "filename", "label", "evaluators", "path", "", "PAGE", "x" * 300]
HEADER_NAMES = ["X-Fuzz", "Accept", "Content-Type", "Range", "If-None-Match", "Cookie", "Origin"]


def _text(rng: np.random.Generator) -> str:
    if rng.random() < 0.7:
        return TEXT[rng.integers(len(TEXT))]
    size = int(rng.integers(0, 60))
    return "".join(chr(int(c)) for c in rng.integers(32, 0x2FF, size=size))


def _latin1(rng: np.random.Generator) -> bytes:
    """A header value httpx will send: printable latin-1 bytes without line breaks."""
    size = int(rng.integers(0, 80))
    codes = rng.choice(list(range(32, 127)) + list(range(160, 256)), size)
    return bytes(int(c) for c in codes)


def _case(rng: np.random.Generator, tokens: list[str], files: list[bytes]) -> dict[str, Any]:
    raw = IDS[rng.integers(len(IDS))] if rng.random() < 0.8 else _text(rng)[:40]
    sid = quote(raw, safe="") if rng.random() < 0.8 else quote(raw, safe="/.")
    paths = [
        "/",
        f"/submissions/{sid}",
        f"/api/submissions/{sid}",
        "/api/submissions",
        "/api/submissions",
        "/api/board",
        "/api/queue",
        "/api/health",
        f"/assets/{sid}",
        "/assets/board.css",
        f"/api/{sid}",
        f"/{sid}/{sid}",
    ]
    path = paths[rng.integers(len(paths))]
    method = str(rng.choice(["GET", "GET", "POST", "POST", "HEAD", "PUT", "DELETE", "OPTIONS"]))
    params = [(KEYS[rng.integers(len(KEYS))], _text(rng)) for _ in range(rng.integers(0, 4))]
    if method == "POST" and rng.random() < 0.6:  # mostly well-formed uploads, to reach validation
        method, path = "POST", "/api/submissions"
        params = [("filename", f"f{rng.integers(1000)}.h5")]
        if rng.random() < 0.5:
            params.append(("label", _text(rng)))
        if rng.random() < 0.3:
            params.append(("evaluators", str(rng.choice(["fce", "fce,gsr", "gsr", "nope"]))))
    headers: dict[str, str | bytes] = {}
    choice = rng.integers(6)
    if choice < 3:
        headers["Authorization"] = f"Bearer {tokens[choice % len(tokens)]}"
    elif choice == 3:
        headers["Authorization"] = str(
            rng.choice(["Bearer", "Bearer ", "Basic YTpi", "bearer x", "Bearer dg16m_" + "A" * 43])
        )
    elif choice == 4:
        headers["Authorization"] = _latin1(rng)
    for _ in range(rng.integers(0, 3)):
        headers[str(rng.choice(HEADER_NAMES))] = _latin1(rng)
    body = b""
    if method in ("POST", "PUT"):
        kind = rng.integers(5)
        if kind == 0:
            body = files[rng.integers(len(files))]
        elif kind == 1:
            whole = files[rng.integers(len(files))]
            body = whole[: int(rng.integers(1, len(whole)))]
        elif kind == 2:
            body = b"\x89HDF\r\n\x1a\n" + rng.bytes(int(rng.integers(0, 3000)))
        elif kind == 3:
            body = rng.bytes(int(rng.integers(0, 5000)))
    return {"method": method, "url": path, "params": params, "headers": headers, "content": body}


def _check(answer: httpx.Response, case: dict[str, Any], failures: list[str]) -> None:
    status = answer.status_code
    where = f"{case['method']} {case['url'][:80]} {str(case['params'])[:120]}"
    if status >= 500:
        failures.append(f"{status} for {where}: {answer.text[:200]}")
    if status >= 400:
        if answer.headers.get("content-security-policy") != CSP:
            failures.append(f"{status} without CSP for {where}")
        api = answer.request.url.path.startswith("/api/")
        kind = answer.headers.get("content-type", "")
        if case["method"] != "HEAD" and api and not kind.startswith("application/json"):
            failures.append(f"{status} not JSON for {where}: {kind}")


@pytest.fixture(scope="module")
def world(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    root = tmp_path_factory.mktemp("fuzz")
    bench = small_benchmark(root / "bench3.h5")
    board = Board(root / "board.db", benchmark=bench, evaluators=("fce",))
    tokens = [board.add_team(name)[1] for name in ("fuzz-a", "fuzz-b")]
    scored_rows(board, "fuzz-a", 3)
    files = [
        valid_submission(root / f"v{i}.h5", bench, k=1 + i, offset=i).read_bytes() for i in range(3)
    ]
    return {"board": board, "tokens": [*tokens, "dg16m_" + "x" * 43], "files": files}


def test_fuzz_the_app_no_5xx_and_headers_on_every_error(world: dict[str, Any]) -> None:
    rng = np.random.default_rng(SEED)
    app = create_app(world["board"], ServiceConfig(rate_limit=100_000, max_upload_bytes=40_000))
    failures: list[str] = []
    statuses: dict[int, int] = {}
    with TestClient(app, raise_server_exceptions=False) as client:
        for _ in range(APP_CASES):
            case = _case(rng, world["tokens"], world["files"])
            answer = client.request(**case)
            statuses[answer.status_code] = statuses.get(answer.status_code, 0) + 1
            _check(answer, case, failures)
    assert failures == [], failures[:20]
    assert sum(statuses.values()) == APP_CASES
    assert {200, 401, 404, 405} <= set(statuses), statuses  # the fuzz reaches every kind


def _raw_request(rng: np.random.Generator, token: str) -> bytes:
    """Request bytes, often malformed: odd methods, targets, versions, header lines, sizes."""
    method = rng.choice([b"GET"] * 6 + [b"POST", b"HEAD", b"G\x00T", b"", b"get", b"X" * 300])
    target = rng.choice(
        [
            b"/",
            b"/api/health",
            b"/api/board?page=" + b"9" * 40,
            b"/submissions/" + b"9" * 25,
            b"/api/submissions/18446744073709551616",
            b"*",
            b"http://evil/",
            b"/%ff%fe",
            b"/\x7f",
            b"/api/queue?"
            + rng.bytes(20).replace(b" ", b"").replace(b"\r", b"").replace(b"\n", b""),
        ]
    )
    version = rng.choice([b"HTTP/1.1"] * 6 + [b"HTTP/1.0", b"HTTP/2.0", b"HTTP/1.1x", b""])
    lines = [b" ".join(x for x in (method, target, version) if x)]
    if rng.random() < 0.9:
        lines.append(b"Host: 127.0.0.1")
    for _ in range(rng.integers(0, 5) if rng.random() < 0.5 else 0):
        lines.append(
            rng.choice(
                [
                    b"Authorization: Bearer " + token.encode(),
                    b"Content-Length: "
                    + rng.choice([b"-1", b"abc", b"5", b"99999999999999999999"]),
                    b"Transfer-Encoding: " + rng.choice([b"chunked", b"gzip", b"chunked, chunked"]),
                    b"X-Bin: " + rng.bytes(10).replace(b"\r", b"").replace(b"\n", b""),
                    b"No colon here",
                    b" leading-space: x",
                    b"X-Long: " + b"a" * int(rng.integers(1, 70_000)),
                ]
            )
        )
    lines.append(b"Connection: close")
    body = rng.bytes(int(rng.integers(0, 64))) if rng.random() < 0.3 else b""
    return b"\r\n".join(lines) + b"\r\n\r\n" + body


def _head_of_answer(address: tuple[str, int], data: bytes) -> bytes:
    """The answer's status line and headers (b"" when the server closed without one)."""
    with socket.create_connection(address, timeout=15) as sock:
        with contextlib.suppress(BrokenPipeError, ConnectionResetError):
            sock.sendall(data)
        received = b""
        with contextlib.suppress(ConnectionResetError):
            while b"\r\n\r\n" not in received:
                chunk = sock.recv(65536)
                if not chunk:
                    break
                received += chunk
    return received.split(b"\r\n\r\n", 1)[0]


def test_fuzz_raw_requests_on_loopback(world: dict[str, Any]) -> None:
    rng = np.random.default_rng(SEED + 1)
    config = ServiceConfig(header_timeout_s=1.0, body_idle_timeout_s=1.0, rate_limit=100_000)
    failures: list[str] = []
    answered = 0
    with running_service(world["board"], config) as (_, address):
        for _ in range(RAW_CASES):
            data = _raw_request(rng, world["tokens"][0])
            head = _head_of_answer(address, data)
            if not head:
                continue  # closed without an answer (a head it never finished reading)
            answered += 1
            status_line, _, header_block = head.partition(b"\r\n")
            parts = status_line.split(b" ")
            status = int(parts[1]) if len(parts) > 1 and parts[1].isdigit() else 0
            lowered = header_block.lower()
            if not 100 <= status < 500:
                failures.append(f"{status_line!r} for {data[:120]!r}")
            if status >= 400 and f"content-security-policy: {CSP}".lower().encode() not in lowered:
                failures.append(f"{status} without CSP for {data[:120]!r}")
        health = httpx.get(f"http://{address[0]}:{address[1]}/api/health", timeout=10)
    assert health.status_code == 200
    assert failures == [], failures[:20]
    assert answered >= RAW_CASES * 0.9
