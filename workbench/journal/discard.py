"""Discarded views in a journal: which events a rebuild replays once a person discarded the last view.

A ``discard`` event names the capture it undoes (``capture_seq``). Replaying the journal without that capture
and without the plans, decisions, refusals, retries and errors that followed it (up to the discard) gives the session
exactly as it was before the capture; config changes in between are kept. The discard event itself stays in
the replayed list, so the session's record (and its export) shows it.
"""

from __future__ import annotations

from typing import Any

UNDONE_KINDS = frozenset({"capture", "plan", "decision", "retry", "error", "refused"})
"""Events after a discarded capture that the discard undoes too."""


def without_discarded(events: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """``events`` with every discarded capture and what followed it up to its discard removed."""
    out: list[dict[str, Any]] = []
    for ev in events:
        if ev.get("kind") == "discard":
            seq = ev.get("capture_seq")
            at = next((i for i, e in enumerate(out) if e.get("kind") == "capture" and e.get("seq") == seq), None)
            if at is not None:
                out = out[:at] + [e for e in out[at + 1 :] if e.get("kind") not in UNDONE_KINDS]
        out.append(ev)
    return out


def last_capture(events: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The last capture event still in effect (not discarded), or None."""
    captures = [e for e in without_discarded(events) if e.get("kind") == "capture"]
    return captures[-1] if captures else None
