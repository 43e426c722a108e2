"""The REST API's shape: one router per resource with its prefix and tags, a response model on every JSON route,
the status shape built from the workbench's own dataclass, and the workbench naming no REST path."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from app.api import loop, sessions
from app.main import create_app
from app.schemas import ERROR_RESPONSES, ErrorOut, SessionOut
from app.settings import AppSettings
from workbench import SessionStatus

ROOT = Path(__file__).resolve().parents[2]


def operations(doc: dict | None = None) -> list[tuple[str, str, dict]]:
    """(method, path, operation) of every documented REST operation (of ``doc``, default a new app's document)."""
    doc = create_app(AppSettings(scene=False)).openapi() if doc is None else doc
    return [(m, path, op) for path, item in doc["paths"].items() for m, op in item.items()]


def typed(schema: dict) -> bool:
    """A documented shape: a model, a list of one, or a mapping to typed values (not ``dict[str, Any]``)."""
    if "$ref" in schema or "anyOf" in schema:
        return True
    if schema.get("type") == "array":
        return typed(schema.get("items", {})) or schema.get("items", {}).get("type") in ("string", "integer")
    values = schema.get("additionalProperties")
    return schema.get("type") == "object" and isinstance(values, dict) and bool(values)


def test_every_json_route_has_a_response_model_and_a_tag() -> None:
    ops = operations()
    assert len(ops) >= 37
    missing = []
    for method, path, op in ops:
        ok = next((op["responses"][c] for c in ("200", "201", "202") if c in op["responses"]), None)
        if ok is None:  # 204: no body
            assert "204" in op["responses"], (method, path)
            continue
        content = ok.get("content", {})
        if set(content) - {"application/json"}:
            continue  # a file (PLY, PNG)
        schema = content.get("application/json", {}).get("schema", {})
        if not typed(schema):
            missing.append(f"{method} {path}")  # no response model: a plain dict or nothing
    assert missing == []
    assert [f"{m} {p}" for m, p, op in ops if not op.get("tags")] == []


def test_every_error_answer_is_documented_as_an_error_out() -> None:
    """The router gives FastAPI the error answers' descriptions only (app/schemas.py ERROR_RESPONSES, no model: a
    model there is built again per app); the document still gives every one of them ErrorOut's body."""
    codes = [str(c) for c in ERROR_RESPONSES]
    doc = create_app(AppSettings(scene=False)).openapi()
    body = {"application/json": {"schema": {"$ref": "#/components/schemas/ErrorOut"}}}
    for method, path, op in operations(doc):
        assert [c for c in op["responses"] if c in codes] == codes, (method, path)  # all nine, in their order
        assert all(op["responses"][c]["content"] == body for c in codes), (method, path)
    error_out = doc["components"]["schemas"]["ErrorOut"]
    assert error_out["required"] == ["detail"] and set(error_out["properties"]) == set(ErrorOut.model_fields)
    assert "default" not in error_out["properties"]["error_id"]  # as FastAPI writes a model (None left out)
    assert list(doc["components"]["schemas"]) == sorted(doc["components"]["schemas"])
    surface = doc["paths"]["/api/sessions/{session_id}/surface.ply"]["get"]["responses"]["409"]
    assert surface["description"].startswith("no surface yet")  # a route's own description stays


def test_every_router_has_its_prefix() -> None:
    for module in (loop, sessions):
        for router in module.routers:
            assert router.prefix.startswith("/") and router.tags
            assert all(not r.path.startswith(router.prefix + router.prefix) for r in router.routes)
    assert loop.router.prefix == "/sessions/{session_id}"


def test_the_status_schema_is_the_workbench_dataclass() -> None:
    fields = [f.name for f in dataclasses.fields(SessionStatus)]
    assert list(SessionOut.model_fields) == fields
    required = [f.name for f in dataclasses.fields(SessionStatus) if f.default is dataclasses.MISSING]
    assert [n for n, f in SessionOut.model_fields.items() if f.is_required()] == required
    assert "discarding" in (SessionOut.model_fields["state"].description or "")


def test_the_workbench_names_no_rest_path() -> None:
    wrong = [
        f"{path.relative_to(ROOT)}:{n}"
        for path in sorted((ROOT / "workbench").rglob("*.py"))
        for n, line in enumerate(path.read_text().splitlines(), 1)
        if "/api/" in line
    ]
    assert wrong == []
