"""The server's classes: create one (its seats are ordinary sessions of the registry), find it by id or join code,
let students join, pause all seats, reset one, and the board's view of every seat (without waking a sleeping one).

A class raises the registry's live limit to hold its seats (``SessionRegistry.class_seats``, capped by
``max_class_seats``); idle seats still sleep (the registry's sweeper) and wake on the next request for them."""

from __future__ import annotations

import contextlib
import logging
import secrets
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from workbench.classes.classroom import ClassRoom, Seat, new_code, read_classes
from workbench.classes.picture import cloud_picture
from workbench.errors import Conflict, Invalid, NotFound, WorkbenchError
from workbench.registry.registry import SessionRegistry
from workbench.session.states import State
from workbench.sources.catalog import find_model

__all__ = ["Classes"]
log = logging.getLogger(__name__)

CREATE_THREADS = 2
"""Seats created at once (each builds its cell and map: CPU-bound, a few per core at most)."""
PICTURE_POINTS = 20_000
"""Points of a seat's cloud drawn in its picture at most (evenly subsampled)."""


class Classes:
    """Thread-safe registry of classes, stored in ``data_dir/classes`` (read back at start)."""

    def __init__(self, registry: SessionRegistry) -> None:
        self.registry = registry
        self.settings = registry.settings
        self._lock = threading.Lock()
        self._rooms: dict[str, ClassRoom] = {}
        self._planned: dict[str, int] = {}
        """Class id -> seats of a class being created (they count towards the live limit already)."""
        self._pictures: dict[str, tuple[int, bytes]] = {}
        """Session id -> (views, PNG) of its last picture: a sleeping seat shows its last one."""
        rooms, problems = read_classes(self.settings.data_dir)
        for problem in problems:
            log.warning("class file not read: %s", problem)
        for room in rooms:
            self._rooms[room.id] = room
            for seat in room.seats:  # after a restart: asleep, woken by the next request for it (no resume)
                registry.doze(seat.session)
        self._update_limit()

    # ------------------------------------------------------------------ create

    def create(
        self,
        seats: int,
        models: list[str] | None = None,
        planner: str = "projection",
        guided: bool = False,
        config: dict[str, Any] | None = None,
    ) -> ClassRoom:
        """A class of ``seats`` new sessions; seat i scans ``models[(i - 1) % len(models)]`` (default: the server's
        model). Everything is checked before the first seat is made: 422 for 0 seats, more than
        ``max_class_seats``, an unknown model or planner or a bad config, with nothing created; a seat that
        cannot be created (e.g. every live session busy) deletes the seats made before it."""
        limit = self.settings.max_class_seats
        if isinstance(seats, bool) or not isinstance(seats, int) or not 1 <= seats <= limit:
            raise Invalid(f"seats: an integer from 1 to {limit} (server.max_class_seats), got {seats!r}")
        names = list(models or [self.settings.devices.model])
        for name in names:
            try:
                find_model(self.settings, name)
            except NotFound as exc:
                raise Invalid(exc.detail) from None
        from planner.evaluators import evaluator_names

        if planner not in evaluator_names():
            raise Invalid(f"planner: unknown {planner!r} (known: {', '.join(evaluator_names())})")
        self.registry.planner_config(config, 0)  # Invalid for a bad config, before any seat exists
        room = ClassRoom(self._new_id(), self._new_code(), planner, names, guided, dict(config or {}), time.time())
        with self._lock:
            self._rooms[room.id] = room  # its seats count towards the live limit from now on
            self._planned[room.id] = seats
        try:
            self._update_limit()
            numbers = range(1, seats + 1)
            with ThreadPoolExecutor(CREATE_THREADS, thread_name_prefix="class-seat") as pool:
                futures = [pool.submit(self._new_seat, room, n) for n in numbers]
                made: list[Seat] = []
                failure: BaseException | None = None
                for future in futures:
                    try:
                        made.append(future.result())
                    except BaseException as exc:  # the others finish; then all are deleted
                        failure = failure or exc
            if failure is not None:
                for seat in made:
                    with contextlib.suppress(WorkbenchError):
                        self.registry.delete(seat.session)
                raise failure
            room.seats = made
            room.save(self.settings.data_dir)
        except BaseException:
            with self._lock:
                self._rooms.pop(room.id, None)
            raise
        finally:
            with self._lock:
                self._planned.pop(room.id, None)
            self._update_limit()
        log.info("class %s: %d seats (code %s)", room.id, seats, room.code)
        return room

    def _new_seat(self, room: ClassRoom, number: int, resets: int = 0) -> Seat:
        model = room.models[(number - 1) % len(room.models)]
        session = self.registry.create(model, room.config, seed=number - 1, planner=room.planner, guided=room.guided)
        return Seat(number, session.id, model, resets=resets)

    def _new_id(self) -> str:
        with self._lock:
            while True:
                cid = secrets.token_hex(4)
                if cid not in self._rooms:
                    return cid

    def _new_code(self) -> str:
        with self._lock:
            taken = {r.code for r in self._rooms.values()}
        while True:
            code = new_code()
            if code not in taken:
                return code

    def _update_limit(self) -> None:
        """The registry's live limit follows the seats of every class (and of those being created)."""
        with self._lock:
            total = sum(len(r.seats) for r in self._rooms.values()) + sum(self._planned.values())
        self.registry.class_seats = total

    # ------------------------------------------------------------------ find

    def get(self, class_id: str) -> ClassRoom:
        with self._lock:
            room = self._rooms.get(class_id)
        if room is None or not room.seats:
            raise NotFound(f"class {class_id!r}: unknown")
        return room

    def list(self) -> list[ClassRoom]:
        with self._lock:
            return [r for r in self._rooms.values() if r.seats]

    def by_code(self, code: str) -> ClassRoom:
        wanted = code.strip().upper()
        with self._lock:
            room = next((r for r in self._rooms.values() if r.code == wanted and r.seats), None)
        if room is None:
            raise NotFound(f"join code {code!r}: no class has it (check the code on the teacher's screen)")
        return room

    def class_of(self, session_id: str) -> ClassRoom | None:
        """The class whose seat ``session_id`` is (None: not a seat)."""
        with self._lock:
            for room in self._rooms.values():
                if any(s.session == session_id for s in room.seats):
                    return room
        return None

    def paused(self, session_id: str) -> bool:
        """Whether ``session_id`` is a seat of a paused class (its changes are refused meanwhile)."""
        room = self.class_of(session_id)
        return room is not None and room.paused

    # ------------------------------------------------------------------ students and teacher

    def join(self, code: str, number: int | None = None) -> tuple[ClassRoom, Seat]:
        """A student joins: the first seat nobody joined yet, or seat ``number`` again (a student who closed the
        tab, or whose seat was reset). 409 when every seat is taken."""
        room = self.by_code(code)
        with self._lock:
            if number is not None:
                seat = room.seat(number)
            else:
                seat = next((s for s in room.seats if not s.joined), None)
                if seat is None:
                    raise Conflict(
                        f"class {room.id}: all {len(room.seats)} seats are taken; ask the teacher for your seat "
                        "number and join with it"
                    )
            seat.joined = True
            room.save(self.settings.data_dir)
        return room, seat

    def pause(self, class_id: str, paused: bool) -> ClassRoom:
        """Pause every seat (auto modes and plans stop; each seat refuses changes until resumed) or resume them."""
        room = self.get(class_id)
        with self._lock:
            room.paused = paused
            room.save(self.settings.data_dir)
        if paused:
            for seat in room.seats:
                session, _ = self._peek(seat.session)
                if session is not None and session.state in (State.AUTO, State.PLANNING):
                    with contextlib.suppress(WorkbenchError):
                        session.stop()
        return room

    def reset(self, class_id: str, number: int) -> Seat:
        """Seat ``number`` starts again: its session is deleted and a new one made (same model, planner, guided)."""
        room = self.get(class_id)
        seat = room.seat(number)
        fresh = self._new_seat(room, number, resets=seat.resets + 1)
        fresh.joined = seat.joined
        with self._lock:
            room.seats[number - 1] = fresh
            room.save(self.settings.data_dir)
            self._pictures.pop(seat.session, None)
        with contextlib.suppress(WorkbenchError):
            self.registry.delete(seat.session)
        return fresh

    def delete(self, class_id: str) -> None:
        """Forget the class and delete its seats' sessions."""
        room = self.get(class_id)
        with self._lock:
            self._rooms.pop(class_id, None)
            room.remove(self.settings.data_dir)
        for seat in room.seats:
            with contextlib.suppress(WorkbenchError):
                self.registry.delete(seat.session)
        self._update_limit()

    # ------------------------------------------------------------------ the board

    def _peek(self, session_id: str) -> tuple[Any, dict[str, Any] | None]:
        try:
            return self.registry.peek(session_id)
        except NotFound:
            return None, None

    def board(self, class_id: str) -> dict[str, Any]:
        """The class and every seat's state, views, coverage and whether it sleeps (no seat is woken)."""
        room = self.get(class_id)
        seats = []
        for seat in room.seats:
            session, status = self._peek(seat.session)
            if status is None:
                state, views, coverage, points = "gone", 0, None, 0
            else:
                state = str(status["state"]) if session is not None else "asleep"
                views, coverage, points = int(status["iteration"]), status["coverage"], int(status["points"])
            seats.append(
                {
                    "seat": seat.number,
                    "session": seat.session,
                    "model": seat.model,
                    "joined": seat.joined,
                    "resets": seat.resets,
                    "state": state,
                    "asleep": session is None and status is not None,
                    "views": views,
                    "coverage": coverage,
                    "points": points,
                    "picture": self._has_picture(seat.session, session),
                }
            )
        return {
            "id": room.id,
            "code": room.code,
            "planner": room.planner,
            "models": list(room.models),
            "guided": room.guided,
            "paused": room.paused,
            "created": room.created,
            "live_limit": self.registry.live_limit(),
            "live": sum(1 for s in seats if not s["asleep"] and s["state"] != "gone"),
            "seats": seats,
        }

    def _has_picture(self, session_id: str, session: Any) -> bool:
        with self._lock:
            cached = session_id in self._pictures
        return cached or (session is not None and session.record.iterations != [])

    def picture(self, class_id: str, number: int) -> bytes:
        """A PNG of seat ``number``'s cloud now (a sleeping seat: its last picture); 404 before its first view."""
        seat = self.get(class_id).seat(number)
        session, status = self._peek(seat.session)
        with self._lock:
            cached = self._pictures.get(seat.session)
        if session is None or status is None:
            if cached is None:
                raise NotFound(f"seat {number}: no picture yet (it sleeps and has none from before)")
            return cached[1]
        views = int(status["iteration"])
        if cached is not None and cached[0] == views:
            return cached[1]
        if views == 0:
            raise NotFound(f"seat {number}: no view captured yet")
        cloud = session.planner.cloud
        step = max(1, len(cloud) // PICTURE_POINTS)
        png = cloud_picture(cloud[::step])
        with self._lock:
            self._pictures[seat.session] = (views, png)
        return png
