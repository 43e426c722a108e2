"""The scan loop a person drives: capture, plan, select, override, approve, retry, configure.

:class:`ScanLoop` is a session's core (:class:`~workbench.session.core.SessionCore`: the fields, the lock, the one
writer of the state) with its actions as methods. Each action checks what it needs, then runs under
:meth:`SessionCore.enter` (the transition table decides where it may start); the long part (a view step, a plan)
runs outside the lock and publishes its result through the core. Auto mode (workbench/session/auto.py), a discard
and the timeline (workbench/session/session.py, history.py) are built from the same steps: :meth:`make_plan`,
:meth:`take_view`, :meth:`replay`.

One approval: :meth:`approve` checks the plan id once (the claim's check, under the lock), then prepares the move
(:meth:`ScanLoop._prepare_move`: the motion the cell plans to the target, the check against the seen object) and hands that
motion to :meth:`take_view`, which the view step runs as it was planned (``Cell.move_to(..., motion=...)``).
"""

from __future__ import annotations

import secrets
from collections.abc import Callable
from typing import Any

from devices.cell import Motion
from devices.protocols import DeviceError, UnreachableError
from planner import Pose
from workbench.errors import Conflict, Invalid, NotFound, Unreachable
from workbench.evaluation.coverage import coverage
from workbench.journal.rebuild import Rebuilt, rebuild
from workbench.journal.store import Journal
from workbench.journal.surface import surface_of_journal
from workbench.planning import plan_in
from workbench.session.core import SessionCore
from workbench.session.states import BUSY, Action, State
from workbench.session.values import CustomPose, Decision, DecisionKind, FailedStep, PendingPlan, SessionEvent
from workbench.session.view_step import UnusableFrame
from workbench.sources.limits import check_config
from workbench.workers.client import JobKilled, SessionWorker

MUTABLE_SECTIONS = ("termination", "candidates", "partitions")
"""Config sections a running session may change (the planner reads them on every plan); the rest are fixed."""


def next_choice(entry: PendingPlan, tried: set[int]) -> int | None:
    """The next view to take when the planner's choice was refused: the best-scored eligible candidate of the
    pending plan not yet ``tried`` (the headless scan's rule, workbench/evaluation/scan.py), None when none is
    left."""
    plan = entry.plan
    ranked = sorted((c for c in plan.scores if c.eligible and c.index not in tried), key=lambda c: -c.score)
    return None if not ranked else int(ranked[0].index)


class ScanLoop(SessionCore):
    """A session's core with the actions of the scan loop and the steps they are built from."""

    # ------------------------------------------------------------------ capture and retry

    def capture(self) -> dict[str, Any]:
        """Capture and integrate the first view at the cell's initial pose."""

        def check() -> None:
            if self.planner.iteration > 0:
                raise Conflict(f"session {self.id}: already captured; plan and approve the next view")

        with self.enter(Action.CAPTURE, self.clear_error, check) as claim:
            return self.take_view(Decision(DecisionKind.INITIAL, self.cell.initial_pose()), None, claim.news)

    def retry(self) -> dict[str, Any]:
        """Re-do the step a fault interrupted (the same pose, the same decision). Conflict when there is none."""
        step = self.failed

        def check() -> None:
            if self.state != State.ERROR or step is None or self.failed is not step:
                raise Conflict(f"session {self.id}: nothing to retry (state {self.state})")
            if step.entry is not None and self.pending is not step.entry:
                raise Conflict(f"session {self.id}: the plan changed since the fault; approve the new plan")

        action = Action.RETRY_MOVE if step is not None and step.entry is not None else Action.RETRY_CAPTURE
        with self.enter(action, lambda: None if step is None else self.take_retry(step), check) as claim:
            assert step is not None  # check refused it otherwise
            return self.take_view(step.decision, step.entry, claim.news)

    # ------------------------------------------------------------------ plan

    def plan(self) -> PendingPlan:
        """Score the candidates and make a new pending plan (an older one goes stale)."""
        with self.enter(Action.PLAN, check=self.no_frame_yet) as claim:
            entry = self.make_plan()
            claim.news.append(SessionEvent.PLANNED)
        return entry

    def no_frame_yet(self) -> None:
        """Conflict before the first view: there is nothing to plan from."""
        if self.planner.iteration == 0:
            raise Conflict(f"session {self.id}: no frame yet; capture first")

    def planning_worker(self) -> SessionWorker | None:
        """The worker that plans (and replays) for this session: its own, unless there is none or the cell judges
        reachability its own way (a replay cell, ``reach_of_config`` False), which a worker's planning cell (the
        config's geometry and arm model) could not reproduce."""
        return self.worker if self.cell.reach_of_config else None

    def make_plan(self, stopping: Callable[[], bool] = lambda: False) -> PendingPlan:
        """Plan (the caller claimed a busy state) and publish the plan as pending.

        With a worker the plan runs there under ``plan_budget``; killed (budget, DELETE, Stop), the session goes
        to state error with the reason (DeviceFault), its map and pending plan unchanged; plan again to go on. The
        same when a device cannot say where it is (the arm's joints, the plate's angle: a DeviceError).
        stopping: auto mode was asked to stop (a plan killed by that Stop just ends auto mode).
        """
        planner = self.planner
        worker = self.planning_worker()
        self.stop_plan_asked = False
        self.progress.begin("plan", stoppable=worker is not None)
        try:
            if worker is None:
                result = plan_in(self.cell, planner, self.progress.plan)
            else:  # the worker's cell has this cell's geometry, arm model, joints and plate angle
                q, angle = self.cell.joint_positions(), self.cell.angle
                result, planner = worker.plan(
                    planner, self.cell.config, self.plan_budget, q, angle, on_progress=self.progress.plan
                )
                if planner.voxel_map.bbox is not None:
                    self.cell.set_object_box(planner.voxel_map.bbox)  # the box the worker's verdicts used
        except ValueError as exc:
            raise Conflict(f"session {self.id}: {exc}") from None
        except JobKilled as exc:
            if stopping():
                raise  # Stop killed the plan: auto mode ends and the session settles, no error
            if self.stop_plan_asked:  # the state comes back; map and pending plan are unchanged
                raise Conflict(
                    f"session {self.id}: the plan was stopped; the map and the pending plan are unchanged"
                ) from None
            self.fail_plan(str(exc))
        except DeviceError as exc:  # the arm's joints or the plate's angle could not be read (a silent device)
            self.fail_plan(f"device fault: {exc}")
        finally:
            self.progress.end()
        return self.publish_plan(result, planner, secrets.token_hex(8))

    def stop_plan(self) -> bool:
        """Stop a plan running in the worker (state planning): the job is killed at once, the session goes back to
        its state before the plan, map and pending plan unchanged. True when one was running."""
        with self.lock:
            current = self.progress.current
            if self.state != State.PLANNING or self.worker is None or current is None or not current.stoppable:
                return False
            self.stop_plan_asked = True
        return self.worker.cancel("stopped by the operator", kinds=("plan",))  # a timeline read or refit goes on

    # ------------------------------------------------------------------ inspect and override

    @staticmethod
    def candidate_of(entry: PendingPlan, index: int) -> int:
        """``index`` when ``entry``'s plan has that candidate; NotFound otherwise."""
        if not 0 <= index < len(entry.plan.candidates):
            raise NotFound(f"candidate {index}: unknown (plan {entry.plan_id} has {len(entry.plan.candidates)})")
        return index

    def select(self, index: int) -> None:
        """Highlight candidate ``index`` of the pending plan (from the list or a click in the scene)."""
        with self.lock:
            if self.pending is None:
                raise Conflict(f"session {self.id}: no pending plan to select from (state {self.state})")
            self.set_selection(self.candidate_of(self.pending, index))
        self.notify(SessionEvent.SELECTION)

    def _motion_to(self, pose: Pose, then: list[Pose] | None = None) -> Motion:
        """The motion the cell plans to ``pose`` (``then``: the views the plan expects next), after the first view
        also checked against the seen object. UnreachableError when the arm cannot reach it or it is inside or
        against the object."""
        motion = self.cell.plan_motion(pose, then=then or ())
        if self.planner.iteration > 0:
            inside = self.object_region().inside_reason(pose.translation, self.devices.camera.min_depth)
            if inside is not None:
                raise UnreachableError(inside)
        return motion

    def set_custom(self, pose: Pose) -> CustomPose:
        """Propose a custom pose (the gizmo); reachability (the arm's reach, and not inside or against the object) is
        checked now and again on approval."""
        try:
            self._motion_to(pose)
        except UnreachableError as exc:
            custom = CustomPose(pose, False, str(exc))
        else:
            custom = CustomPose(pose, True, "reachable")
        with self.lock:
            if self.pending is None:
                raise Conflict(f"session {self.id}: no pending plan to override (state {self.state})")
            self.propose(custom)
        self.notify(SessionEvent.CUSTOM_POSE)
        return custom

    # ------------------------------------------------------------------ approve

    def approve(self, plan_id: str, index: int | None = None, pose: Pose | None = None) -> dict[str, Any]:
        """Move to candidate ``index`` (or to ``pose``) of the pending plan ``plan_id``, capture, integrate.

        Conflict for a stale, used or unknown plan_id or a busy session; NotFound for an unknown candidate;
        Unreachable for a target the cell cannot reach (or one inside the object). In all of these nothing moves.
        The motion planned to check the target is the one the cell runs.
        """
        if (index is None) == (pose is None):
            raise Invalid("approve: give exactly one of 'index' or 'pose'")

        def check() -> None:
            why = self.is_used_or_stale(plan_id)
            if why is not None:
                raise Conflict(why)
            if self.state in BUSY:
                raise Conflict(f"session {self.id} is busy ({self.state}); approve refused")
            if self.pending is None or self.pending.plan_id != plan_id:
                raise Conflict(f"plan_id {plan_id}: not the pending plan of session {self.id}")

        def prepare() -> tuple[Decision, PendingPlan, Motion | None]:
            entry = self.pending
            assert entry is not None  # check: the pending plan is plan_id's
            result = entry.plan
            if pose is None:
                assert index is not None  # exactly one of the two, checked above
                target = result.candidates[self.candidate_of(entry, index)].T_world_camera
                then = result.then_poses(index)
            else:
                target, then = pose, []
            motion = self._prepare_move(target, then)
            kind = DecisionKind.APPROVE if pose is None and index == result.best_index else DecisionKind.OVERRIDE
            decision = Decision(kind, target, plan_id, index, result.best_index, custom=pose is not None)
            self.clear_error()
            self.take_decision(decision, entry)
            return decision, entry, motion

        with self.enter(Action.APPROVE, prepare, check) as claim:
            assert claim.value is not None
            decision, entry, motion = claim.value
            return self.take_view(decision, entry, claim.news, motion)

    def _prepare_move(self, target: Pose, then: list[Pose]) -> Motion | None:
        """The motion an approval of ``target`` runs (``then``: the views the plan's tour expects next), planned
        once here to check the target; Unreachable (nothing moved) when the view cannot be taken. When only the
        move that also serves ``then`` fails, the view itself is checked as a view without a tour: reachable, the
        step plans the move and, refused, falls back as any refused move of the planner's choice (None)."""
        try:
            return self._motion_to(target, then)
        except UnreachableError as exc:
            if not then:
                raise Unreachable(f"approve: target pose is {exc}") from None
        try:
            self._motion_to(target)
        except UnreachableError as exc:
            raise Unreachable(f"approve: target pose is {exc}") from None
        return None

    # ------------------------------------------------------------------ configuration

    def change_config(self, changes: dict[str, Any]) -> dict[str, Any]:
        """Change the sections the planner reads on every plan (``MUTABLE_SECTIONS``); journaled.

        Invalid for another section or a bad value, Conflict while busy. A pending plan stays approvable.
        """
        fixed = sorted(set(changes) - set(MUTABLE_SECTIONS))
        if fixed:
            raise Invalid(
                f"config: {', '.join(fixed)} cannot change during a session (changeable: {', '.join(MUTABLE_SECTIONS)})"
            )
        with self.enter(Action.CONFIGURE):
            try:
                config = self.config.replace(**changes)
            except (ValueError, TypeError) as exc:
                raise Invalid(f"config: {exc}") from None
            check_config(config)
            self.take_config(config, changes)
        return config.to_dict()

    # ------------------------------------------------------------------ the steps actions are built from

    def take_view(
        self,
        decision: Decision,
        entry: PendingPlan | None,
        news: list[SessionEvent] | None = None,
        motion: Motion | None = None,
    ) -> dict[str, Any]:
        """Move, capture, integrate (the caller has claimed a busy state); returns the new iteration's record.

        motion: the move to ``decision``'s pose, planned already (an approval's check); None: the cell plans it.
        A refused move (Unreachable) or an unusable frame (ValueError of integrate) of the planner's choice never
        ends the step: the next eligible candidate of the pending plan is taken (:func:`next_choice`, score order),
        each refusal journaled (``refused`` event) and decided anew; only "no eligible view left" fails it. A
        person's explicit choice (an override, a custom pose) that is refused fails at once.

        Raises DeviceFault for a device fault, a timeout or a rejected frame, Unreachable when the cell
        refuses the pose; the session is then in state error with the map unchanged. news: where to say that a
        view was integrated once the action settles (None: say it now, auto mode).
        """
        first, tried = decision, set[int]()
        planners_choice = entry is not None and not decision.custom and decision.index == decision.best_index
        while True:
            try:
                then = entry.plan.then_poses(decision.index) if entry is not None and not decision.custom else []
                outcome = self.step_runner.run(self.planner, decision.pose, self.add_move, then, motion)
                self.publish_view(outcome, decision)
                break
            except (UnreachableError, UnusableFrame) as exc:
                if not planners_choice or entry is None or self.deleted:
                    self.fail_step(exc, FailedStep(decision, entry))
                assert decision.index is not None  # the planner's choice is a candidate
                tried.add(decision.index)
                following = next_choice(entry, tried)
                fallback = (
                    None
                    if following is None
                    else Decision(
                        decision.kind,
                        entry.plan.candidates[following].T_world_camera,
                        entry.plan_id,
                        following,
                        first.best_index,
                    )
                )
                with self.lock:
                    self.refuse_move(decision, exc, fallback)
                if fallback is None:
                    last = f"{exc.reason if isinstance(exc, UnreachableError) else 'frame_rejected'}: {exc}"
                    self.fail_step(
                        UnreachableError(
                            f"no eligible view left in plan {entry.plan_id}: {len(tried)} candidate(s) refused "
                            f"(the last: {last})",
                            "no_eligible_view",
                        ),
                        FailedStep(first, entry),
                    )
                decision, motion = fallback, None
            except Exception as exc:
                self.fail_step(exc, FailedStep(decision, entry))
        if news is None:
            self.notify(SessionEvent.CAPTURED)
        else:
            news.append(SessionEvent.CAPTURED)
        return self.record.iterations[-1]

    def replay(self, journal: Journal, progress: Callable[[str, int, int], None] | None = None) -> Rebuilt:
        """This session's state rebuilt from ``journal`` (a resume, a discard), to take over: in its worker when it
        has one (killed with it on DELETE and at shutdown), else here. ValueError / KeyError / TypeError for a
        journal that cannot be replayed; JobKilled when the worker was killed."""
        samples = self.surface_samples
        worker = self.planning_worker()
        if worker is None:
            truth = None if samples is None else (lambda cloud: coverage(samples, cloud))
            rebuilt = rebuild(journal, self.cell, truth, progress)
            rebuilt.surface = surface_of_journal(journal, self.step_runner.truth).update
            return rebuilt
        q, angle = self.cell.joint_positions(), self.cell.angle
        rebuilt = worker.rebuild(journal, self.cell.config, q, angle, samples, progress)
        if rebuilt.planner.voxel_map.bbox is not None:
            self.cell.set_object_box(rebuilt.planner.voxel_map.bbox)  # the box the replayed plans used
        return rebuilt
