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

The page passes the ticket through viser's ``?websocket=`` URL parameter (see :func:`viewer_url`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Collection
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
    websock = server._websock_server  # viser's WebsockServer: its handshake records are not public API

    async def check(conn: Any) -> None:
        connection = websock._live_connections.get(conn.client_id)
        if connection is None:
            return
        request = connection.request
        if request is None:
            await connection.close(CLOSE_FORBIDDEN, "no handshake")
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
