"""The 3D scene: every browser tab's viewer shows exactly one session, in that viewer's own viser scene.

A tab asks for a *viewer* of its session (``POST /api/viewer`` -> :meth:`SceneController.open_viewer_of`): a
ticket (app/scene/tickets.py) whose secret goes into the viewer iframe's websocket URL, and a viewer id the
page quotes in its REST calls. When the viewer connects, app/scene/guard.py checks its Origin and redeems the
ticket; the controller then draws the session into ``client.scene`` (app/scene/drawing.py) and keeps it in
step with the session's events. Nothing session-specific is ever put into the shared ``server.scene``, so a
tab never receives scene messages of another session, and a client without a ticket sees an empty scene
whose clicks reach no callback.

GUI callbacks (a click on a candidate, a gizmo release) call the bound session, never the planner, from the
controller's own worker thread (:class:`SceneWork`): viser's event thread never waits for a session's lock or a
motion planner. The move to the selected view (the ghost arm, the ``path`` layer's frustums) is planned under the
session's lock (:class:`app.scene.movetarget.SessionMoves`) on the thread of the event that changed the selection.
"""

from __future__ import annotations

import io
import logging
import math
import queue
import threading
import time
from collections.abc import Callable, Collection
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import viser

from app.scene.arm import ArmTarget, SessionArm
from app.scene.camera import FRAMING_FOV_DEG, client_cameras, framing
from app.scene.drawing import SessionDrawing
from app.scene.fit_view import FitViews, viewer_message
from app.scene.geometry import COLORS, DEFAULT_LAYERS, SCALE_PERCENTILES, VIRIDIS, candidate_colors, outward_camera
from app.scene.guard import install_guard
from app.scene.lighting import configure_lighting
from app.scene.movetarget import SessionMoves, selected_target
from app.scene.pathlayer import capture_rate, path_preview
from app.scene.reachlayer import REACH_CLASSES, ReachMaps
from app.scene.robot import RobotScene
from app.scene.tickets import Ticket, TicketBook
from planner import Pose
from workbench import (
    Conflict,
    Invalid,
    NotFound,
    Session,
    SessionEvent,
    SessionRegistry,
    State,
    TimelineStep,
    Unreachable,
    WorkbenchError,
)

log = logging.getLogger(__name__)
PICTURE_MAX = 2560
"""Pixels: the longer side of a picture of a viewer (``picture``) at most."""

REDRAW_EVENTS = frozenset(
    {SessionEvent.PLANNED, SessionEvent.CAPTURED, SessionEvent.SELECTION, SessionEvent.CUSTOM_POSE}
)
"""Session events after which a viewer's scene may change (state and progress changes draw nothing)."""

INITIAL_EYE, INITIAL_LOOK_AT = framing(None)
"""Where a tab's camera starts before it is framed on its session (from the front-right, on the object)."""


class SceneWork:
    """Runs what viser's callbacks ask of the sessions (a click, a gizmo release, a new client's move to show) on a
    thread of its own, in the order asked: viser's event thread never waits for a session's lock or a motion
    planner, and a click's selection is planned under the session's lock like a REST request's."""

    def __init__(self) -> None:
        self._queue: queue.SimpleQueue[Callable[[], None]] = queue.SimpleQueue()
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None

    def submit(self, job: Callable[[], None]) -> None:
        self._queue.put(job)
        with self._lock:
            if self._thread is None or not self._thread.is_alive():
                self._thread = threading.Thread(target=self._run, name="scene-work", daemon=True)
                self._thread.start()

    def _run(self) -> None:
        while True:
            job = self._queue.get()
            try:
                job()
            except Exception:  # one failed job never stops the next
                log.exception("scene work failed")


@dataclass(eq=False)
class Viewer:
    """One tab's viewer: the session it shows, its layer visibility, and (once connected) its client."""

    id: str
    session_id: str
    expires: float = math.inf
    """time.monotonic() after which a viewer whose client never connected is forgotten (its ticket expired)."""
    layers: dict[str, bool] = field(default_factory=lambda: dict(DEFAULT_LAYERS))
    client: viser.ClientHandle | None = None
    drawing: SessionDrawing | None = None
    robot: RobotScene | None = None
    """The arm in this viewer's scene (``/robot/...``), when the session's cell has an arm model."""
    step: TimelineStep | None = None
    """The timeline's view this viewer shows (the session after that view), None: the session now."""
    framed: tuple[float, float, float] | None = None
    """Where this page put the client's camera last (:meth:`SceneController._frame`); a camera still there follows
    the arm round (the person did not move it)."""
    readonly: bool = False
    """Watching only (a class seat on the projector): a click or a gizmo release in it changes nothing."""


class SceneController:
    """Per-tab scenes on one viser server; thread-safe.

    registry: where viewers find their sessions; allowed_origins: extra Origins a viewer websocket may come
    from (its own origin always may); ticket_ttl: seconds a viewer ticket waits for its connection.
    """

    def __init__(
        self,
        server: viser.ViserServer,
        registry: SessionRegistry,
        allowed_origins: Collection[str] = (),
        ticket_ttl: float = 60.0,
    ) -> None:
        self.server = server
        self.registry = registry
        self.tickets = TicketBook(ticket_ttl)
        self._lock = threading.RLock()
        self._viewers: dict[str, Viewer] = {}
        self._bound: dict[int, Ticket] = {}  # client id -> ticket, between the handshake and viser's client
        self._watched: set[str] = set()
        """Sessions this controller follows (``SessionRegistry.follow``: their events, whichever object each is;
        one woken from sleep is a new object)."""
        self._arms: dict[str, SessionArm] = {}
        self._moves: dict[str, SessionMoves] = {}
        """The move to each session's selected view (the ghost's and the path layer's), planned once per selection."""
        self.work = SceneWork()
        """Where viser's callbacks call the sessions (never on viser's event thread)."""
        self.fit = FitViews(self)
        self.reach = ReachMaps(self._reach_ready)
        """The ``reach`` layer's maps (app/scene/reachlayer.py), computed only for sessions a tab shows it of."""
        """The Fit panel's actions (app/scene/fit_view.py)."""
        self.viewer_listeners: list[Callable[[str, dict[str, Any]], None]] = []
        """Called with (session id, ``viewer_message``) after a viewer's layers, focus or refit changed."""
        self.other_viewers: list[Callable[[viser.ClientHandle, str], bool]] = []
        """Viewers of something else than a session (a calibration: app/scene/calibration.py): each is asked with
        a newly connected client and its viewer's key, and returns True when it draws it."""
        configure_lighting(server)
        server.initial_camera.position = INITIAL_EYE
        server.initial_camera.look_at = INITIAL_LOOK_AT
        server.initial_camera.near = 0.01
        server.gui.configure_theme(show_share_button=False, show_logo=False)
        server.gui.main_panel.minimize()
        install_guard(server, self.tickets, self._on_ticket, allowed_origins)
        server.on_client_connect(self._on_client)
        server.on_client_disconnect(self._on_client_gone)
        registry.on_delete.append(self._on_session_deleted)
        registry.on_create.append(self._on_session_live)

    # ------------------------------------------------------------------ viewers

    def open_viewer_of(self, key: str, readonly: bool = False) -> Ticket:
        """A ticket for a new viewer of ``key``: a session's id, or what one of ``other_viewers`` draws;
        ``readonly``: its clicks and gizmo change nothing."""
        ticket = self.tickets.issue(key)
        now = time.monotonic()
        with self._lock:
            for k in [k for k, v in self._viewers.items() if v.client is None and v.expires < now]:
                del self._viewers[k]
            self._viewers[ticket.viewer] = Viewer(ticket.viewer, key, expires=ticket.expires + 5.0, readonly=readonly)
        return ticket

    def viewer(self, viewer_id: str) -> Viewer:
        with self._lock:
            v = self._viewers.get(viewer_id)
        if v is None:
            raise NotFound(f"viewer {viewer_id}: unknown (reload the page for a new one)")
        return v

    def _on_ticket(self, client_id: int, ticket: Ticket) -> None:
        with self._lock:
            self._bound[client_id] = ticket

    def _on_client(self, client: viser.ClientHandle) -> None:
        with self._lock:
            ticket = self._bound.pop(client.client_id, None)
            v = None if ticket is None else self._viewers.get(ticket.viewer)
        if v is None:
            return  # unbound: the empty shared scene only
        if any(draw(client, v.session_id) for draw in self.other_viewers):
            with self._lock:
                v.client = client
            return
        try:
            session = self.registry.get(v.session_id)
        except WorkbenchError:
            return
        with self._lock:
            v.client = client
            v.drawing = SessionDrawing(client, v.layers, self._selector(v), self._custom_setter(v))
            v.drawing.on_focus = lambda label, viewer_id=v.id: self.fit.clicked(viewer_id, label)
            self._watch(session)
            data = session.scene_data()
            v.drawing.update(data)
        self._frame(v, session)
        self._sync_reach(session, data.plan)

        @client.camera.on_update
        def _(camera: Any) -> None:  # viser's client puts its camera at the server's initial one when it first draws
            at = np.asarray(camera.position, dtype=float)
            if (
                v.framed is not None
                and np.linalg.norm(at - INITIAL_EYE) < 1e-3
                and np.linalg.norm(at - v.framed) > 1e-3
            ):
                self._frame(v, session)

        arm = self.arm_of(session)
        if arm is not None:
            robot = arm.new_scene(client)
            with self._lock:
                v.robot = robot
        self.work.submit(lambda: self._show_move(session, [v]))

    def _on_client_gone(self, client: viser.ClientHandle) -> None:
        with self._lock:
            self._bound.pop(client.client_id, None)
            gone = [k for k, v in self._viewers.items() if v.client is client]
            robots = [self._viewers[k].robot for k in gone]
            for key in gone:
                del self._viewers[key]
        for robot in robots:
            if robot is not None:
                robot.stop()

    def _watch(self, session: Session) -> None:
        """Hear ``session``'s events from now on, across its sleeps and wakes (caller holds the lock)."""
        if session.id not in self._watched:
            self._watched.add(session.id)
            self.registry.follow(session.id, self._on_event)

    def _on_session_live(self, session: Session) -> None:
        """A session became live (created, resumed, or woken from sleep as a new object): the viewers that show
        it are brought up to date with it (its events reach them through ``follow``)."""
        with self._lock:
            viewers = [v for v in self._viewers.values() if v.session_id == session.id and v.drawing is not None]
        if not viewers:
            return
        data = session.scene_data()
        with self._lock:
            for v in viewers:
                if v.drawing is not None and v.step is None:
                    v.drawing.update(data)
        self.work.submit(lambda: self._show_move(session, viewers))  # the new object's move (none while busy)

    def _on_event(self, session: Session, event: SessionEvent) -> None:
        if event not in REDRAW_EVENTS:
            return
        data = session.scene_data()
        with self._lock:
            for v in self._viewers.values():
                if v.session_id == session.id and v.drawing is not None and v.step is None:
                    v.drawing.update(data)  # a viewer on the timeline keeps showing the past
        self._sync_reach(session, data.plan)
        with self._lock:
            live = [
                v
                for v in self._viewers.values()
                if v.session_id == session.id and v.drawing is not None and v.step is None
            ]
        if not live:
            return  # no tab shows this session now: plan no move for it
        # in auto mode the next move starts at once: no ghost and no path (the arm animates each executed move)
        show_target = event != SessionEvent.CAPTURED and session.state != State.AUTO
        self._show_move(session, live, show_target)
        if event == SessionEvent.CAPTURED:
            arm = self.arm_of(session)
            if arm is not None:
                for robot in self._robots_of(session.id, live_only=True):
                    arm.after_capture(robot)
        if event == SessionEvent.CAPTURED:  # the plate turned: cameras nobody moved go round with it
            with self._lock:
                viewers = [v for v in self._viewers.values() if v.session_id == session.id and v.step is None]
            for v in viewers:
                if v.client is not None and v.framed is not None and self._camera_unmoved(v):
                    self._frame(v, session)

    def _frame(self, v: Viewer, session: Session) -> None:
        """Point ``v``'s client at the object from the side away from the arm's mount (the object in front, the arm
        beside it: :func:`app.scene.camera.framing`)."""
        client = v.client
        if client is None:
            return
        arm = self.arm_of(session)
        mount_xy = None
        if arm is not None:
            angle = float(session.cell.angle)
            t = np.asarray(arm.model.T_base_mount.translation, dtype=float)
            c, s = math.cos(-angle), math.sin(-angle)
            mount_xy = (c * t[0] - s * t[1], s * t[0] + c * t[1])
        eye, look_at = framing(mount_xy)
        with client.atomic():
            client.camera.up_direction = (0.0, 0.0, 1.0)
            client.camera.position = np.asarray(eye, dtype=float)
            client.camera.look_at = np.asarray(look_at, dtype=float)
            client.camera.fov = math.radians(FRAMING_FOV_DEG)
        v.framed = eye

    @staticmethod
    def _camera_unmoved(v: Viewer) -> bool:
        """Whether ``v``'s client camera is still where :meth:`_frame` put it (within 2 cm)."""
        assert v.client is not None and v.framed is not None
        try:
            return bool(np.linalg.norm(np.asarray(v.client.camera.position, dtype=float) - v.framed) < 0.02)
        except Exception:  # a client that never reported its camera
            return True

    def _on_session_deleted(self, session: Session) -> None:
        with self._lock:
            self._watched.discard(session.id)
            self._arms.pop(session.id, None)
            self._moves.pop(session.id, None)
            self.reach.forget(session.id)
            for v in [v for v in self._viewers.values() if v.session_id == session.id]:
                if v.drawing is not None:
                    v.drawing.clear()
                v.drawing = None
                if v.robot is not None:
                    v.robot.remove()
                v.robot = None

    # ------------------------------------------------------------------ the arm and the move to the selection

    def moves_of(self, session: Session) -> SessionMoves:
        """The move to ``session``'s selected view (one per session object: a session woken from sleep is new)."""
        with self._lock:
            moves = self._moves.get(session.id)
            if moves is None or moves.session is not session:
                moves = self._moves[session.id] = SessionMoves(session)
            return moves

    def arm_of(self, session: Session) -> SessionArm | None:
        """The arm of ``session`` as the views show it (None when its cell has no arm model)."""
        if session.cell.kinematics is None:
            return None
        moves = self.moves_of(session)
        with self._lock:
            arm = self._arms.get(session.id)
            if arm is None or arm.session is not session:
                arm = self._arms[session.id] = SessionArm(session, moves)
            return arm

    def _show_move(self, session: Session, viewers: list[Viewer], show: bool = True) -> None:
        """Show the move to ``session``'s selected view in ``viewers`` (those still showing the session now): the
        ghost arm at its target and the path layer's frustums (``show`` False: neither). Plans the move if it
        was not (under the session's lock: call it from a REST request's or the scene's worker thread). A move
        whose selection changed while it was planned is not drawn: the change's own event draws the new one."""
        target = self.moves_of(session).target() if show else None
        preview = None if target is None else path_preview(target, capture_rate(session.cell))
        arm = self.arm_of(session)
        with self._lock:
            if target is not None:
                sel = selected_target(session.scene_data())
                if sel is None or sel[0] != target.key:
                    return
            now = [v for v in viewers if v.step is None and self._viewers.get(v.id) is v]
            for v in now:
                if v.drawing is not None:
                    v.drawing.draw_path(preview)
                if v.robot is not None and arm is not None:
                    arm.show_target(v.robot, target)

    def _robots_of(self, session_id: str, live_only: bool = False) -> list[RobotScene]:
        """The arms of the viewers of ``session_id`` (``live_only``: of those not on the timeline)."""
        with self._lock:
            return [
                v.robot
                for v in self._viewers.values()
                if v.session_id == session_id and v.robot is not None and not (live_only and v.step is not None)
            ]

    def preview(self, session: Session, speed: float = 1.0) -> tuple[ArmTarget, int]:
        """Animate the move to ``session``'s selected target on the ghost in every tab showing ``session``; returns the
        target and the number of tabs animating. Conflict without an arm, a pending plan or a reachable target."""
        arm = self.arm_of(session)
        if arm is None:
            raise Conflict(f"session {session.id}: its cell has no arm model to preview")
        target = arm.target(session.scene_data())
        if target is None:
            raise Conflict(f"session {session.id}: no pending plan to preview a move of (plan first)")
        if target.motion is None or target.motion.trajectory is None:
            raise Unreachable(f"preview: the selected target is unreachable ({target.reason})")
        robots = self._robots_of(session.id, live_only=True)
        for robot in robots:
            robot.animate(target.motion.trajectory, target.motion.angle, ghost=True, speed=speed)
        return target, len(robots)

    def _selector(self, v: Viewer) -> Any:
        def select(index: int) -> None:
            if v.readonly:
                log.info("click on candidate %s ignored: viewer %s only watches", index, v.id)
                return
            if v.step is not None:  # the past is looked at, not changed
                log.info("click on candidate %s ignored: the viewer shows view %d of the timeline", index, v.step.view)
                return

            def run() -> None:
                try:  # the session live now (a session woken from sleep is a new object)
                    self.registry.get(v.session_id).select(index)
                except WorkbenchError as exc:
                    log.info("click on candidate %s ignored: %s", index, exc.detail)

            self.work.submit(run)

        return select

    def _custom_setter(self, v: Viewer) -> Any:
        def set_custom(pose: Pose) -> None:
            if v.readonly:
                log.info("gizmo pose ignored: viewer %s only watches", v.id)
                return
            if v.step is not None:
                log.info("gizmo pose ignored: the viewer shows view %d of the timeline", v.step.view)
                return

            def run() -> None:
                try:
                    self.registry.get(v.session_id).set_custom(pose)
                except (WorkbenchError, ValueError) as exc:
                    log.info("gizmo pose ignored: %s", exc)

            self.work.submit(run)

        return set_custom

    # ------------------------------------------------------------------ the timeline

    def show_step(self, viewer_id: str, view: int | None) -> TimelineStep | None:
        """Show the session after view ``view`` in this viewer (None: the session now again); returns the step.

        The step comes from the session's journal (``Session.history``, rebuilt in its worker, cached); the
        session itself is not changed, and its events redraw this viewer only once it shows now again. NotFound
        for a view the session has not taken, Conflict without a journal."""
        v = self.viewer(viewer_id)
        with self.registry.hold(v.session_id) as session:  # no sleep cuts the rebuild off
            step = nxt = None
            if view is not None:
                steps = session.history.steps()  # outside the lock: the first look replays the journal
                step = session.history.step(view)
                nxt = steps[view] if view < len(steps) else None
        now = session.scene_data()
        with self._lock:
            v.step = step
            if v.drawing is not None:
                v.drawing.update(now if step is None else step.scene_data(now))
            robot = v.robot
        arm = self.arm_of(session)
        if robot is not None and arm is not None:
            if step is None:
                robot.stop()
                robot.show(session.cell.arm.joint_positions(), session.cell.angle)
            else:
                _show_step_arm(robot, step, nxt)
        if step is None:
            self._show_move(session, [v])
        else:
            with self._lock:
                if v.drawing is not None:
                    v.drawing.draw_path(None)  # the past's views are drawn, not the move that is pending now
        self.notify(v)
        return step

    # ------------------------------------------------------------------ layers, info

    def set_layers(self, viewer_id: str, changes: dict[str, bool]) -> dict[str, bool]:
        """Show / hide layers of one viewer; Invalid for an unknown name (nothing changes then)."""
        v = self.viewer(viewer_id)
        unknown = set(changes) - set(v.layers)
        if unknown:
            raise Invalid(f"layers: unknown {sorted(unknown)} (known: {', '.join(v.layers)})")
        with self._lock:
            changes = {k: bool(x) for k, x in changes.items()}
            if v.drawing is not None:
                v.drawing.set_layers(changes)
            else:
                v.layers.update(changes)
            layers = dict(v.layers)
        if changes.get("reach") and v.step is None:
            try:
                session = self.registry.get(v.session_id)
            except WorkbenchError:
                session = None
            if session is not None:
                self._sync_reach(session, session.scene_data().plan)
        self.notify(v)
        return layers

    # ------------------------------------------------------------------ the reach layer

    def _reach_viewers(self, session_id: str) -> list[Viewer]:
        """The viewers of ``session_id`` showing the session now with the ``reach`` layer on (caller holds the lock)."""
        return [
            v
            for v in self._viewers.values()
            if v.session_id == session_id and v.drawing is not None and v.step is None and v.layers.get("reach")
        ]

    def _sync_reach(self, session: Session, plan: Any) -> None:
        """Draw ``session``'s reach map (its current ``plan``'s, else its box's) in the viewers that show the layer:
        the map if it is ready, else nothing while it is computed (``_reach_ready`` draws it then)."""
        with self._lock:
            if not self._reach_viewers(session.id):
                return  # no tab shows the layer: nothing is computed
        reach = self.reach.request(session, plan)
        with self._lock:
            reach = reach or self.reach.current(session, plan)  # a map finished meanwhile: drawn, not cleared
            for v in self._reach_viewers(session.id):
                assert v.drawing is not None
                v.drawing.draw_reach(reach)

    def _reach_ready(self, session_id: str, _reach: Any) -> None:
        try:
            session = self.registry.get(session_id)
        except WorkbenchError:
            return
        self._sync_reach(session, session.scene_data().plan)  # a map of a plan since replaced starts the next one

    @property
    def lock(self) -> AbstractContextManager[Any]:
        """The scene lock (held while a viewer's drawing changes)."""
        return self._lock

    def notify(self, v: Viewer) -> None:
        """Tell the viewer's page (``viewer_listeners``) its layers, focus and refits as they are now."""
        with self._lock:
            message = viewer_message(v)
        for listener in list(self.viewer_listeners):
            try:
                listener(v.session_id, message)
            except Exception:  # a listener never breaks the scene
                log.exception("viewer listener failed")

    def info(self, viewer_id: str) -> dict[str, Any]:
        """The viewer's session, whether its client is connected, layers, drawn nodes and the colour bar."""
        v = self.viewer(viewer_id)
        step = v.step
        try:
            plan = self.registry.get(v.session_id).scene_data().plan if step is None else step.plan
        except WorkbenchError:
            plan = None
        lo_hi = (0.0, 1.0)
        if plan is not None and plan.scores:
            _, lo, hi = candidate_colors([s.score for s in plan.scores], [s.eligible for s in plan.scores])
            lo_hi = (lo, hi)
        with self._lock:
            d = v.drawing
            return {
                "viewer": v.id,
                "session": v.session_id,
                "connected": d is not None,
                "layers": dict(v.layers),
                "nodes": ([] if d is None else d.node_names()) + ([] if v.robot is None else v.robot.node_names()),
                "colormap": [list(c) for c in VIRIDIS],
                "score_range": list(lo_hi),
                "colors": {
                    k: list(COLORS[k])
                    for k in ("occupied", "frontier", "unknown", "empty", "cloud", "nbv", "selected", "path")
                },
                "scale": f"F of eligible candidates, {SCALE_PERCENTILES[0]:g}th to {SCALE_PERCENTILES[1]:g}th percentile",
                "timeline": None if step is None else step.summary(),
                "reach_classes": [
                    {"class": k, "label": lab, "color": list(c)} for k, (lab, c) in REACH_CLASSES.items()
                ],
                "reach": None if d is None or d.reach_map is None else d.reach_map.legend(),
            }

    # ------------------------------------------------------------------ camera

    def look_at_candidate(self, viewer_id: str, index: int, distance: float = 0.3) -> int:
        """Point the viewer's camera at candidate ``index`` from outside the hemisphere; 1 if moved, else 0."""
        v = self.viewer(viewer_id)
        session = self.registry.get(v.session_id)
        entry = session.plan_for()
        if not 0 <= index < len(entry.plan.candidates):
            raise NotFound(f"candidate {index}: out of range")
        target = entry.plan.candidates[index].position
        eye = outward_camera(target, entry.plan.hemisphere_center, distance)
        return self.set_camera(viewer_id, eye, target)

    def set_camera(self, viewer_id: str, position: Any, look_at: Any) -> int:
        """Move the viewer's camera; 1 if its client is connected, else 0."""
        v = self.viewer(viewer_id)
        client = v.client
        if client is None:
            return 0
        with client.atomic():
            client.camera.up_direction = (0.0, 0.0, 1.0)
            client.camera.position = np.asarray(position, dtype=float)
            client.camera.look_at = np.asarray(look_at, dtype=float)
        return 1

    def picture(self, viewer_id: str, timeout: float = 15.0) -> bytes:
        """A PNG of the viewer's 3D view as its tab shows it now (its camera, its canvas size, capped at
        ``PICTURE_MAX`` px), rendered by the browser. Conflict when its client is not connected or does not answer
        within ``timeout`` s."""
        v = self.viewer(viewer_id)
        client = v.client
        if client is None:
            raise Conflict(f"viewer {viewer_id}: not connected (open the tab's 3D view first)")
        cam = client.camera
        width, height = int(cam.image_width or 1280), int(cam.image_height or 720)
        scale = min(1.0, PICTURE_MAX / max(width, height))
        width, height = max(16, int(width * scale)), max(16, int(height * scale))
        try:
            rgba = client.get_render(height, width, transport_format="png", timeout=timeout)
        except Exception as exc:  # a timeout or a disconnect: the tab cannot render now
            raise Conflict(f"viewer {viewer_id}: no picture from the browser ({exc or type(exc).__name__})") from None
        return png_bytes(rgba)

    def cameras(self) -> list[dict[str, Any]]:
        """The camera each connected client reported last (OpenCV pose, vertical fov, canvas size)."""
        return client_cameras(self.server)


def _show_step_arm(robot: RobotScene, step: TimelineStep, nxt: TimelineStep | None) -> None:
    """The arm where it was at ``step``'s capture; the ghost where the approved view took it (``nxt``'s capture)."""
    robot.stop()
    robot.show_path(None)
    here = (step.device_state or {}).get("arm")
    there = None if nxt is None else (nxt.device_state or {}).get("arm")
    if here is not None:
        robot.show(np.asarray(here["q"], dtype=np.float64), float(here["angle"]))
    if there is None:
        robot.show_ghost(None)
    else:
        robot.show_ghost(np.asarray(there["q"], dtype=np.float64), float(there["angle"]))


def png_bytes(image: Any) -> bytes:
    """(H, W, 3 | 4) uint8 RGB(A) as PNG bytes (a transparent background made white, as slides want)."""
    from PIL import Image

    arr = np.asarray(image, dtype=np.uint8)
    if arr.ndim != 3 or arr.shape[2] not in (3, 4):
        raise ValueError(f"image: expected (H, W, 3|4) uint8, got shape {arr.shape}")
    out = Image.fromarray(arr, "RGBA" if arr.shape[2] == 4 else "RGB")
    if out.mode == "RGBA":
        white = Image.new("RGBA", out.size, (255, 255, 255, 255))
        out = Image.alpha_composite(white, out).convert("RGB")
    buf = io.BytesIO()
    out.save(buf, format="PNG")
    return buf.getvalue()
