"""The state machine's one table: the diagram in workbench/session/states.py says what TRANSITIONS says, and
only the core assigns the state."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

import workbench.session.states as states
from workbench.session.states import BUSY, RESTING, TRANSITIONS, Action, Listed, State

ROOT = Path(__file__).resolve().parents[2]
ARROW = re.compile(r"^\s{4}(?P<sources>[a-z, ]+) ──(?P<action>[a-z ]+)──► (?P<busy>[a-z]+|·)$")


def diagram() -> dict[Action, tuple[frozenset[State], State | None]]:
    """The transitions drawn in the module docstring."""
    assert states.__doc__ is not None
    drawn = {}
    for line in states.__doc__.splitlines():
        match = ARROW.match(line)
        if match:
            sources = frozenset(State(s.strip()) for s in match["sources"].split(","))
            busy = None if match["busy"] == "·" else State(match["busy"])
            drawn[Action(match["action"])] = (sources, busy)
    return drawn


def test_the_diagram_is_the_table() -> None:
    table = {action: (t.sources, t.busy) for action, t in TRANSITIONS.items()}
    assert diagram() == table


def test_the_diagram_check_sees_a_wrong_line(monkeypatch: pytest.MonkeyPatch) -> None:
    assert states.__doc__ is not None
    monkeypatch.setattr(states, "__doc__", states.__doc__.replace("planned, error ──approve", "planned ──approve"))
    assert diagram()[Action.APPROVE][0] == frozenset({State.PLANNED})
    assert diagram() != {action: (t.sources, t.busy) for action, t in TRANSITIONS.items()}


def test_every_action_has_a_row_and_only_live_states_appear() -> None:
    assert set(TRANSITIONS) == set(Action)
    assert {State.CAPTURING, State.PLANNING, State.MOVING, State.AUTO, State.DISCARDING} == BUSY
    assert {State.NEW, State.READY, State.PLANNED, State.DONE, State.ERROR} == RESTING
    for t in TRANSITIONS.values():
        assert t.sources <= RESTING  # an action starts from a resting state only
    assert not {str(s) for s in Listed} & {str(s) for s in State}  # listing-only states are not live ones


def assigned(path: Path) -> list[tuple[int, ast.Attribute]]:
    """(line, target) of every assignment to an attribute (``x.name = ...``, ``x.name += ...``) in ``path``."""
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Assign):
            targets = node.targets
        elif isinstance(node, ast.AnnAssign | ast.AugAssign):
            targets = [node.target]
        else:
            continue
        found += [(node.lineno, t) for t in targets if isinstance(t, ast.Attribute)]
    return found


def test_the_state_is_assigned_in_one_place() -> None:
    found = {
        str(path.relative_to(ROOT)): lines
        for path in sorted((ROOT / "workbench").rglob("*.py"))
        if (lines := [n for n, target in assigned(path) if target.attr == "_state"])
    }
    core = ROOT / "workbench/session/core.py"
    assert list(found) == ["workbench/session/core.py"]
    assert len(found["workbench/session/core.py"]) == 2  # __init__ and _set_state
    assert "self._state = state" in core.read_text()


def test_no_other_file_writes_the_private_fields_of_a_session() -> None:
    """Outside the core, no ``x._field = ...`` on a session (the other files call the core's methods)."""
    wrong = [
        f"{path.name}:{n} {ast.unparse(target)}"
        for path in sorted((ROOT / "workbench" / "session").glob("*.py"))
        if path.name != "core.py"
        for n, target in assigned(path)
        if target.attr.startswith("_") and not (isinstance(target.value, ast.Name) and target.value.id == "self")
    ]
    assert wrong == []
