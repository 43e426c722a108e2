"""Viewer tickets: the per-tab capability that binds one 3D viewer connection to one session.

The page asks for a ticket with an authenticated REST call (``POST /api/viewer``) and hands it to its viewer
iframe; the viewer's websocket presents it in its URL. A ticket is a random secret, short-lived (``ttl``
seconds from issue to use) and single-use: the first connection that presents it is bound to the ticket's
session, later ones get nothing. The *viewer id* that comes with it is not a secret; the page uses it in
the REST calls that concern its own viewer (layers, camera).
"""

from __future__ import annotations

import secrets
import threading
import time
from dataclasses import dataclass


@dataclass(frozen=True)
class Ticket:
    """One issued ticket: ``secret`` goes into the viewer URL, ``viewer`` names the tab's viewer in REST calls."""

    secret: str
    viewer: str
    session_id: str
    expires: float

    def __post_init__(self) -> None:
        if not self.secret:
            raise ValueError("secret: must not be empty")
        if not self.viewer:
            raise ValueError("viewer: must not be empty")


class TicketBook:
    """Issues and redeems tickets; thread-safe.

    ttl: seconds a ticket may wait for its viewer to connect (default 60 s: a page load, not a session).
    """

    def __init__(self, ttl: float = 60.0) -> None:
        if not ttl > 0:
            raise ValueError(f"ttl: must be > 0 seconds, got {ttl}")
        self.ttl = ttl
        self._lock = threading.Lock()
        self._open: dict[str, Ticket] = {}

    def issue(self, session_id: str) -> Ticket:
        """A new ticket for ``session_id``."""
        ticket = Ticket(secrets.token_urlsafe(24), secrets.token_hex(6), session_id, time.monotonic() + self.ttl)
        with self._lock:
            self._drop_expired()
            self._open[ticket.secret] = ticket
        return ticket

    def redeem(self, secret: str) -> Ticket | None:
        """The ticket ``secret`` names if it is open and not expired (it is used up now); None otherwise."""
        with self._lock:
            self._drop_expired()
            return self._open.pop(secret, None)

    def _drop_expired(self) -> None:
        now = time.monotonic()
        for key in [k for k, t in self._open.items() if t.expires < now]:
            del self._open[key]
