"""The 3D viewer's front door: Origin and ticket checks on viser's websocket handshake (docs/security.md).

viser itself authenticates nothing. Its websocket server calls its connection callbacks before it sends a
single message to a new client, with the handshake request already recorded; :func:`install_guard` adds one
there that

1. closes the connection (code 4003) when the ``Origin`` header is missing or is not the viewer's own origin
   (the ``Host`` it was reached at) or one of ``allowed_origins``: a web page elsewhere cannot open the
   viewer's socket in the operator's browser;
2. reads ``?ticket=`` from the websocket URL and hands the redeemed ticket to ``bind`` (the scene then draws
   that session into this client's own scene). A client without a valid ticket stays *unbound*: it gets the
   empty shared scene only and no session node with a click or gizmo callback is ever created for it, so
   its events change nothing.

A handshake (or a plain request to viser's port) that repeats ``Host`` or ``Origin`` is answered 400 before any
websocket opens (RFC 9112 section 3.2: a request with more than one Host is refused with 400): which of the values
counts would be a guess, and a guess in an Origin check is a hole.

The page passes the ticket through viser's ``?websocket=`` URL parameter (see :func:`viewer_url`).
"""

from __future__ import annotations

import inspect
import logging
from collections.abc import Callable, Collection
from http import HTTPStatus
from typing import Any
from urllib.parse import parse_qs, quote, urlsplit

import viser

from app.scene.tickets import Ticket, TicketBook
from app.security import same_origin

log = logging.getLogger(__name__)

CLOSE_FORBIDDEN = 4003
"""The websocket close code of a refused viewer connection."""


def origin_refusal(origin: str | None, host: str | None, allowed_origins: Collection[str]) -> str | None:
    """Why a websocket handshake with these ``Origin`` and ``Host`` headers is refused, or None."""
    if origin is None or origin == "null":
        return "no Origin header"
    return None if same_origin(origin, host, allowed_origins) else f"foreign Origin {origin!r}"


SINGLE_HEADERS = ("Host", "Origin")
"""Headers a viewer's handshake must not repeat (400 otherwise)."""


def repeated_header(headers: Any) -> str | None:
    """The first of :data:`SINGLE_HEADERS` that ``headers`` (websockets' ``Headers``) carries more than once."""
    return next((name for name in SINGLE_HEADERS if len(headers.get_all(name)) > 1), None)


def _refusing_repeated_headers(process_request: Any) -> Any:
    """``process_request`` (a websockets server's, or None) behind the repeated-header check."""

    async def checked(connection: Any, request: Any) -> Any:
        name = repeated_header(request.headers)
        if name is not None:
            log.warning("3D viewer request refused: its %s header is repeated", name)
            return connection.respond(HTTPStatus.BAD_REQUEST, f"the {name} header is repeated\n")
        if process_request is None:
            return None
        response = process_request(connection, request)
        return await response if inspect.isawaitable(response) else response

    return checked


def refuse_repeated_headers() -> None:
    """Answer 400 to any handshake of this process's websockets servers (viser's) that repeats a
    :data:`SINGLE_HEADERS` header, before its ``process_request`` runs. Idempotent."""
    from websockets.asyncio.server import ServerConnection

    original = ServerConnection.handshake
    if getattr(original, "refuses_repeated_headers", False):
        return

    async def handshake(self: ServerConnection, process_request: Any = None, *args: Any, **kwargs: Any) -> None:
        await original(self, _refusing_repeated_headers(process_request), *args, **kwargs)

    handshake.refuses_repeated_headers = True  # type: ignore[attr-defined]
    ServerConnection.handshake = handshake  # type: ignore[method-assign]


def ticket_in(path: str) -> str | None:
    """The ``ticket`` query parameter of a websocket request path (``/?ticket=...``), or None."""
    values = parse_qs(urlsplit(path).query).get("ticket")
    return values[0] if values else None


def viewer_url(scheme: str, host: str, port: int, ticket: str | None) -> str:
    """The viewer page URL whose websocket presents ``ticket`` (viser reads ``?websocket=``)."""
    base = f"{scheme}://{host}:{port}/"
    if ticket is None:
        return base
    ws = f"{'wss' if scheme == 'https' else 'ws'}://{host}:{port}/?ticket={ticket}"
    return f"{base}?websocket={quote(ws, safe='')}"


def install_guard(
    server: viser.ViserServer,
    tickets: TicketBook,
    bind: Callable[[int, Ticket], None],
    allowed_origins: Collection[str] = (),
) -> None:
    """Check every new websocket of ``server`` before viser sends it anything (see the module docstring).

    bind(client_id, ticket) is called for a connection that presented an open ticket.
    """
    refuse_repeated_headers()
    websock = server._websock_server  # viser's WebsockServer: its handshake records are not public API

    async def check(conn: Any) -> None:
        connection = websock._live_connections.get(conn.client_id)
        if connection is None:
            return
        request = connection.request
        if request is None:
            await connection.close(CLOSE_FORBIDDEN, "no handshake")
            return
        repeated = repeated_header(request.headers)  # answered 400 at the handshake already; never a guess here
        if repeated is not None:
            await connection.close(CLOSE_FORBIDDEN, f"the {repeated} header is repeated")
            return
        refusal = origin_refusal(request.headers.get("Origin"), request.headers.get("Host"), allowed_origins)
        if refusal is not None:
            log.warning("3D viewer connection %d refused: %s", conn.client_id, refusal)
            await connection.close(CLOSE_FORBIDDEN, refusal)
            return
        secret = ticket_in(request.path)
        ticket = None if secret is None else tickets.redeem(secret)
        if ticket is None:
            log.info("3D viewer connection %d has no valid ticket: it stays unbound", conn.client_id)
            return
        bind(conn.client_id, ticket)

    websock.on_client_connect(check)
