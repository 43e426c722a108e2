"""The scan loop a person drives: capture, plan, select, override, approve, retry, configure.

Each action checks what it needs, then runs under :meth:`SessionCore.enter` (the transition table decides where it
may start); the long part (a view step, a plan) runs outside the lock and publishes its result through the core.
Auto mode (workbench/session/auto.py) and a discard (workbench/session/discard.py) are built from the same steps:
:func:`make_plan` and :func:`take_view`.
"""

from __future__ import annotations

import secrets
from collections.abc import Callable
from typing import Any

from devices.cell import Cell
from devices.protocols import UnreachableError
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


# ---------------------------------------------------------------------- capture and retry


def capture(s: SessionCore) -> dict[str, Any]:
    """Capture and integrate the first view at the cell's initial pose."""

    def check() -> None:
        if s.planner.iteration > 0:
            raise Conflict(f"session {s.id}: already captured; plan and approve the next view")

    with s.enter(Action.CAPTURE, s.clear_error, check) as claim:
        return take_view(s, Decision(DecisionKind.INITIAL, s.cell.initial_pose()), None, claim.news)


def retry(s: SessionCore) -> dict[str, Any]:
    """Re-do the step a fault interrupted (the same pose, the same decision). Conflict when there is none."""
    step = s.failed

    def check() -> None:
        if s.state != State.ERROR or step is None or s.failed is not step:
            raise Conflict(f"session {s.id}: nothing to retry (state {s.state})")
        if step.entry is not None and s.pending is not step.entry:
            raise Conflict(f"session {s.id}: the plan changed since the fault; approve the new plan")

    action = Action.RETRY_MOVE if step is not None and step.entry is not None else Action.RETRY_CAPTURE
    with s.enter(action, lambda: None if step is None else s.take_retry(step), check) as claim:
        assert step is not None  # check refused it otherwise
        return take_view(s, step.decision, step.entry, claim.news)


# ---------------------------------------------------------------------- plan


def plan(s: SessionCore) -> PendingPlan:
    """Score the candidates and make a new pending plan (an older one goes stale)."""

    with s.enter(Action.PLAN, check=lambda: no_frame_yet(s)) as claim:
        entry = make_plan(s)
        claim.news.append(SessionEvent.PLANNED)
    return entry


def no_frame_yet(s: SessionCore) -> None:
    """Conflict before the first view: there is nothing to plan from."""
    if s.planner.iteration == 0:
        raise Conflict(f"session {s.id}: no frame yet; capture first")


def planning_worker(s: SessionCore) -> SessionWorker | None:
    """The worker that plans (and replays) for this session: its own, unless there is none or the cell judges
    reachability its own way (a replay cell), which a worker's planning cell (the config's geometry and arm
    model) could not reproduce."""
    return s.worker if type(s.cell).is_reachable is Cell.is_reachable else None


def make_plan(s: SessionCore, stopping: Callable[[], bool] = lambda: False) -> PendingPlan:
    """Plan (the caller claimed a busy state) and publish the plan as pending.

    With a worker the plan runs there under ``plan_budget``; killed (budget, DELETE, Stop), the session goes
    to state error with the reason (DeviceFault), its map and pending plan unchanged; plan again to go on.
    stopping: auto mode was asked to stop (a plan killed by that Stop just ends auto mode).
    """
    planner = s.planner
    worker = planning_worker(s)
    s.stop_plan_asked = False
    s.progress.begin("plan", stoppable=worker is not None)
    try:
        if worker is None:
            result = plan_in(s.cell, planner, s.progress.plan)
        else:  # the worker's cell has this cell's geometry, arm model, joints and plate angle
            q, angle = s.cell.joint_positions(), s.cell.angle
            result, planner = worker.plan(planner, s.cell.config, s.plan_budget, q, angle, on_progress=s.progress.plan)
            if planner.voxel_map.bbox is not None:
                s.cell.set_object_box(planner.voxel_map.bbox)  # the box the worker's verdicts used
    except ValueError as exc:
        raise Conflict(f"session {s.id}: {exc}") from None
    except JobKilled as exc:
        if stopping():
            raise  # Stop killed the plan: auto mode ends and the session settles, no error
        if s.stop_plan_asked:  # the state comes back; map and pending plan are unchanged
            raise Conflict(
                f"session {s.id}: the plan was stopped; the map and the pending plan are unchanged"
            ) from None
        s.fail_plan(str(exc))
    finally:
        s.progress.end()
    return s.publish_plan(result, planner, secrets.token_hex(8))


def stop_plan(s: SessionCore) -> bool:
    """Stop a plan running in the worker (state planning): the job is killed at once, the session goes back to
    its state before the plan, map and pending plan unchanged. True when one was running."""
    with s.lock:
        current = s.progress.current
        if s.state != State.PLANNING or s.worker is None or current is None or not current.stoppable:
            return False
        s.stop_plan_asked = True
    return s.worker.cancel("stopped by the operator", kinds=("plan",))  # a timeline read or refit goes on


# ---------------------------------------------------------------------- inspect and override


def candidate_of(entry: PendingPlan, index: int) -> int:
    if not 0 <= index < len(entry.plan.candidates):
        raise NotFound(f"candidate {index}: unknown (plan {entry.plan_id} has {len(entry.plan.candidates)})")
    return index


def select(s: SessionCore, index: int) -> None:
    """Highlight candidate ``index`` of the pending plan (from the list or a click in the scene)."""
    with s.lock:
        if s.pending is None:
            raise Conflict(f"session {s.id}: no pending plan to select from (state {s.state})")
        s.set_selection(candidate_of(s.pending, index))
    s.notify(SessionEvent.SELECTION)


def reachability(s: SessionCore, pose: Pose) -> tuple[bool, str]:
    """Whether the cell can take a view at ``pose``: its arm's reach, and not inside or against the object."""
    try:
        s.cell.plan_motion(pose)
    except UnreachableError as exc:
        return False, str(exc)
    if s.planner.iteration > 0:
        inside = s.object_region().inside_reason(pose.translation, s.devices.camera.min_depth)
        if inside is not None:
            return False, inside
    return True, "reachable"


def set_custom(s: SessionCore, pose: Pose) -> CustomPose:
    """Propose a custom pose (the gizmo); reachability is checked now and again on approval."""
    ok, reason = reachability(s, pose)
    custom = CustomPose(pose, ok, reason)
    with s.lock:
        if s.pending is None:
            raise Conflict(f"session {s.id}: no pending plan to override (state {s.state})")
        s.propose(custom)
    s.notify(SessionEvent.CUSTOM_POSE)
    return custom


# ---------------------------------------------------------------------- approve


def approve(s: SessionCore, plan_id: str, index: int | None = None, pose: Pose | None = None) -> dict[str, Any]:
    """Move to candidate ``index`` (or to ``pose``) of the pending plan ``plan_id``, capture, integrate.

    Conflict for a stale, used or unknown plan_id or a busy session; NotFound for an unknown candidate;
    Unreachable for a target the cell cannot reach (or one inside the object). In all of these nothing moves.
    """
    if (index is None) == (pose is None):
        raise Invalid("approve: give exactly one of 'index' or 'pose'")

    def prepare() -> tuple[Decision, PendingPlan]:
        entry = _check_plan_id(s, plan_id)
        result = entry.plan
        if pose is None:
            assert index is not None  # exactly one of the two, checked above
            target = result.candidates[candidate_of(entry, index)].T_world_camera
        else:
            target = pose
        ok, reason = reachability(s, target)
        if not ok:
            raise Unreachable(f"approve: target pose is {reason}")
        kind = DecisionKind.APPROVE if pose is None and index == result.best_index else DecisionKind.OVERRIDE
        decision = Decision(kind, target, plan_id, index, result.best_index, custom=pose is not None)
        s.clear_error()
        s.take_decision(decision, entry)
        return decision, entry

    with s.enter(Action.APPROVE, prepare, lambda: _check_plan_id(s, plan_id)) as claim:
        assert claim.value is not None
        decision, entry = claim.value
        return take_view(s, decision, entry, claim.news)


def _check_plan_id(s: SessionCore, plan_id: str) -> PendingPlan:
    why = s.is_used_or_stale(plan_id)
    if why is not None:
        raise Conflict(why)
    if s.state in BUSY:
        raise Conflict(f"session {s.id} is busy ({s.state}); approve refused")
    if s.pending is None or s.pending.plan_id != plan_id:
        raise Conflict(f"plan_id {plan_id}: not the pending plan of session {s.id}")
    return s.pending


# ---------------------------------------------------------------------- configuration


def change_config(s: SessionCore, changes: dict[str, Any]) -> dict[str, Any]:
    """Change the sections the planner reads on every plan (``MUTABLE_SECTIONS``); journaled.

    Invalid for another section or a bad value, Conflict while busy. A pending plan stays approvable.
    """
    fixed = sorted(set(changes) - set(MUTABLE_SECTIONS))
    if fixed:
        raise Invalid(
            f"config: {', '.join(fixed)} cannot change during a session (changeable: {', '.join(MUTABLE_SECTIONS)})"
        )
    with s.enter(Action.CONFIGURE):
        try:
            config = s.config.replace(**changes)
        except (ValueError, TypeError) as exc:
            raise Invalid(f"config: {exc}") from None
        check_config(config)
        s.take_config(config, changes)
    return config.to_dict()


# ---------------------------------------------------------------------- the steps actions are built from


def take_view(
    s: SessionCore, decision: Decision, entry: PendingPlan | None, news: list[SessionEvent] | None = None
) -> dict[str, Any]:
    """Move, capture, integrate (the caller has claimed a busy state); returns the new iteration's record.

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
            outcome = s.step_runner.run(s.planner, decision.pose, s.add_move, then)
            s.publish_view(outcome, decision)
            break
        except (UnreachableError, UnusableFrame) as exc:
            if not planners_choice or entry is None or s.deleted:
                s.fail_step(exc, FailedStep(decision, entry))
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
            with s.lock:
                s.refuse_move(decision, exc, fallback)
            if fallback is None:
                last = f"{getattr(exc, 'reason', 'frame_rejected')}: {exc}"
                s.fail_step(
                    UnreachableError(
                        f"no eligible view left in plan {entry.plan_id}: {len(tried)} candidate(s) refused "
                        f"(the last: {last})",
                        "no_eligible_view",
                    ),
                    FailedStep(first, entry),
                )
            decision = fallback
        except Exception as exc:
            s.fail_step(exc, FailedStep(decision, entry))
    if news is None:
        s.notify(SessionEvent.CAPTURED)
    else:
        news.append(SessionEvent.CAPTURED)
    return s.record.iterations[-1]


def next_choice(entry: PendingPlan, tried: set[int]) -> int | None:
    """The next view to take when the planner's choice was refused: the best-scored eligible candidate of the
    pending plan not yet ``tried`` (the headless scan's rule, workbench/evaluation/scan.py), None when none is
    left."""
    plan = entry.plan
    ranked = sorted((c for c in plan.scores if c.eligible and c.index not in tried), key=lambda c: -c.score)
    return None if not ranked else int(ranked[0].index)


def replay(s: SessionCore, journal: Journal, progress: Callable[[str, int, int], None] | None = None) -> Rebuilt:
    """This session's state rebuilt from ``journal`` (a resume, a discard), to take over: in its worker when it
    has one (killed with it on DELETE and at shutdown), else here. ValueError / KeyError / TypeError for a
    journal that cannot be replayed; JobKilled when the worker was killed."""
    samples = s.surface_samples
    worker = planning_worker(s)
    if worker is None:
        truth = None if samples is None else (lambda cloud: coverage(samples, cloud))
        rebuilt = rebuild(journal, s.cell, truth, progress)
        rebuilt.surface = surface_of_journal(journal, s.step_runner.truth).update
        return rebuilt
    q, angle = s.cell.joint_positions(), s.cell.angle
    rebuilt = worker.rebuild(journal, s.cell.config, q, angle, samples, progress)
    if rebuilt.planner.voxel_map.bbox is not None:
        s.cell.set_object_box(rebuilt.planner.voxel_map.bbox)  # the box the replayed plans used
    return rebuilt
