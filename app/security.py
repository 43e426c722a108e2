"""The workbench's front door: host, origin, token and body-size checks before any route runs (docs/security.md).

One ASGI middleware, in this order:

1. **Host** (DNS rebinding): a server bound to a loopback address answers only
   requests whose ``Host`` is a loopback name (or one of ``allowed_hosts``), so a
   web page whose DNS name is re-pointed at 127.0.0.1 cannot drive the robot. 400 otherwise.
2. **Origin** (cross-site requests): a state-changing request (not GET / HEAD /
   OPTIONS) that carries an ``Origin`` must come from the page's own origin or one
   of ``cors_origins``. 403 otherwise.
3. **Token**: when ``settings.token`` is set, every ``/api`` request must carry it,
   as ``Authorization: Bearer <token>`` or ``?token=<token>``. 401 otherwise.
4. **Body size**: a body over ``max_upload_bytes`` (uploads) or ``max_body_bytes``
   (anything else) is refused with 413 before it is read; a chunked body is
   counted and cut at the limit.

CORS itself (the ``Access-Control-*`` headers) is Starlette's CORSMiddleware,
installed only when ``cors_origins`` is not empty: closed by default.
"""

from __future__ import annotations

import hmac
import logging
import re
from collections.abc import Collection
from typing import Any
from urllib.parse import parse_qs, urlsplit

from starlette.datastructures import Headers
from starlette.responses import JSONResponse
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from app.settings import AppSettings, is_loopback


def same_origin(origin: str, host: str | None, allowed: Collection[str]) -> bool:
    """The one same-origin rule (plain HTTP, the events websocket, the 3D viewer's websocket): ``origin`` is the
    page's own (its host and port are the ``Host`` the request reached) or one of ``allowed`` (``cors_origins``,
    a trailing slash aside). The opaque origin ``null`` is never the page's own."""
    if origin == "null":
        return origin in allowed
    if host is not None and urlsplit(origin).netloc.lower() == host.lower():
        return True
    return origin.rstrip("/") in {o.rstrip("/") for o in allowed}


SAFE_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})
PROTECTED_PAGES = frozenset({"/openapi.json", "/docs", "/docs/oauth2-redirect", "/redoc"})
"""Pages outside ``/api`` that need the token too: the API's description is part of the API."""
SECRET_PARAMS = ("token", "ticket")
"""Query parameters the access log never shows."""
_SECRET_QUERY = re.compile(r"(?i)\b(" + "|".join(SECRET_PARAMS) + r")=[^&\s\"]*")
UPLOAD_OVERHEAD = 64 * 1024
"""Multipart framing allowed on top of ``max_upload_bytes``."""


def _hostname(host_header: str) -> str:
    """``example.org`` of ``example.org:8000``, ``::1`` of ``[::1]:8000``."""
    return urlsplit(f"//{host_header}").hostname or ""


class SecurityMiddleware:
    """See the module docstring."""

    def __init__(self, app: ASGIApp, settings: AppSettings) -> None:
        self.app = app
        self.token = settings.token.encode("utf-8") if settings.token else None
        self.cors = frozenset(settings.cors_origins)
        self.loopback_only = is_loopback(settings.host)
        self.allowed_hosts = frozenset(settings.allowed_hosts)
        self.max_body = settings.max_body_bytes
        self.max_upload = settings.max_upload_bytes + UPLOAD_OVERHEAD

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        headers = Headers(scope=scope)
        refusal = self._refusal(scope, headers)
        if refusal is not None:
            status, detail = refusal
            extra = {"WWW-Authenticate": "Bearer"} if status == 401 else None
            await JSONResponse({"detail": detail}, status_code=status, headers=extra)(scope, receive, send)
            return
        limit = self.max_upload if scope["path"].rstrip("/") == "/api/models" else self.max_body
        length = headers.get("content-length")
        if length is not None:
            if not length.isdigit():
                await JSONResponse({"detail": "bad Content-Length"}, status_code=400)(scope, receive, send)
                return
            if int(length) > limit:
                await self._too_large(scope, receive, send, limit)
                return
            await self.app(scope, receive, send)
            return
        if scope.get("method", "GET") in SAFE_METHODS:
            await self.app(scope, receive, send)
            return
        body = await self._read_capped(receive, limit)  # chunked: count it before the app sees it
        if body is None:
            await self._too_large(scope, receive, send, limit)
            return
        await self.app(scope, _replay(body, receive), send)

    def _refusal(self, scope: Scope, headers: Headers) -> tuple[int, str] | None:
        host = headers.get("host", "")
        name = _hostname(host)
        if self.loopback_only and not is_loopback(name) and name not in self.allowed_hosts:
            return 400, f"host {host!r} refused: this server answers only to 127.0.0.1 / localhost"
        method = scope.get("method", "GET")
        origin = headers.get("origin")
        if method not in SAFE_METHODS and origin is not None and not same_origin(origin, host, self.cors):
            return 403, f"cross-origin request from {origin!r} refused (allowed: this page, cors_origins)"
        path = scope["path"]
        api = path == "/api" or path.startswith("/api/") or path in PROTECTED_PAGES
        if self.token is not None and api and method != "OPTIONS" and not self._has_token(scope, headers):
            return 401, "missing or wrong token: send 'Authorization: Bearer <token>' or '?token=<token>'"
        return None

    def _has_token(self, scope: Scope, headers: Headers) -> bool:
        assert self.token is not None
        auth = headers.get("authorization", "")
        if auth[:7].lower() == "bearer " and hmac.compare_digest(auth[7:].strip().encode("utf-8"), self.token):
            return True
        query = parse_qs(scope.get("query_string", b"").decode("latin-1"))
        return any(hmac.compare_digest(t.encode("utf-8"), self.token) for t in query.get("token", []))

    @staticmethod
    async def _read_capped(receive: Receive, limit: int) -> bytes | None:
        chunks: list[bytes] = []
        size = 0
        while True:
            message = await receive()
            if message["type"] == "http.disconnect":
                return b"".join(chunks)
            chunk = message.get("body", b"")
            size += len(chunk)
            if size > limit:
                return None
            chunks.append(chunk)
            if not message.get("more_body", False):
                return b"".join(chunks)

    @staticmethod
    async def _too_large(scope: Scope, receive: Receive, send: Send, limit: int) -> None:
        detail = f"request body over the limit of {limit} bytes"
        await JSONResponse({"detail": detail}, status_code=413, headers={"Connection": "close"})(scope, receive, send)


def _replay(body: bytes, upstream: Receive) -> Receive:
    """A receive channel that yields the already-read ``body`` once, then the client's own messages."""
    sent = False

    async def receive() -> Message:
        nonlocal sent
        if not sent:
            sent = True
            return {"type": "http.request", "body": body, "more_body": False}
        return await upstream()

    return receive


def openapi_security(schema: dict[str, Any]) -> dict[str, Any]:
    """Declare the bearer token in an OpenAPI document (so /docs has an Authorize button)."""
    components = schema.setdefault("components", {})
    components.setdefault("securitySchemes", {})["bearer"] = {"type": "http", "scheme": "bearer"}
    schema["security"] = [{"bearer": []}]
    return schema


def redact(text: str) -> str:
    """``text`` with the value of every ``token=`` / ``ticket=`` query parameter replaced by ``***``."""
    return _SECRET_QUERY.sub(lambda m: f"{m.group(1)}=***", text)


class RedactSecrets(logging.Filter):
    """A log filter (on ``uvicorn.access``) that removes tokens from the request line of every record."""

    def filter(self, record: logging.LogRecord) -> bool:
        if isinstance(record.args, tuple):
            record.args = tuple(redact(a) if isinstance(a, str) else a for a in record.args)
        elif isinstance(record.msg, str):
            record.msg = redact(record.msg)
        return True


def install_log_redaction() -> None:
    """Add :class:`RedactSecrets` to uvicorn's access and error loggers (once)."""
    for name in ("uvicorn.access", "uvicorn.error"):
        logger = logging.getLogger(name)
        if not any(isinstance(f, RedactSecrets) for f in logger.filters):
            logger.addFilter(RedactSecrets())
