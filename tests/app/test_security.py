"""Security: loopback by default, a token to expose the server, host/origin checks, CORS closed, no path escapes."""

from __future__ import annotations

import logging
import os
import socket
from pathlib import Path

import pytest
from apphelpers import BASE_URL, CUBE_OBJ, SMALL, free_port, running_server
from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import AppSettings, check_exposure, is_loopback, load_settings, viewer_host
from nbv.cli import main as nbv_main

TOKEN = "s3cret-token-for-tests"


# ---------------------------------------------------------------------- binding


def test_loopback_by_default_and_a_token_to_expose(capsys) -> None:
    assert AppSettings().host == "127.0.0.1" and is_loopback("127.0.0.1") and is_loopback("::1")
    assert is_loopback("localhost") and not is_loopback("0.0.0.0") and not is_loopback("192.168.1.5")
    for host in ("0.0.0.0", "192.168.1.5", "::"):
        with pytest.raises(ValueError, match="--token or the NBV_TOKEN"):
            check_exposure(AppSettings(host=host))
        with pytest.raises(ValueError, match="refusing to listen"):
            create_app(AppSettings(host=host, scene=False))
        check_exposure(AppSettings(host=host, token=TOKEN))
    with pytest.raises(ValueError, match="at least 12 characters"):
        AppSettings(host="0.0.0.0", token="short")
    # the command refuses with one clear line and exit code 2 (before binding anything)
    assert nbv_main(["serve", "--host", "0.0.0.0", "--port", "1"]) == 2
    err = capsys.readouterr().err
    assert "refusing to listen on 0.0.0.0" in err and "NBV_TOKEN" in err and "Traceback" not in err


def test_the_token_comes_from_the_flag_or_the_environment(monkeypatch) -> None:
    import argparse

    from nbv import serve

    parser = argparse.ArgumentParser()
    serve.add_arguments(parser)
    monkeypatch.setenv("NBV_TOKEN", TOKEN)
    s = serve.settings_from_args(parser.parse_args(["--host", "0.0.0.0"]))
    assert (s.host, s.token, s.viser_host) == ("0.0.0.0", TOKEN, "0.0.0.0")
    assert viewer_host(s) == "127.0.0.1"  # viser has no authentication: it stays local
    assert viewer_host(s.replace(viser_public=True)) == "0.0.0.0"
    monkeypatch.delenv("NBV_TOKEN")
    s = serve.settings_from_args(parser.parse_args(["--token", "another-long-token", "--cors-origin", "http://a.b"]))
    assert s.token == "another-long-token" and s.cors_origins == ("http://a.b",)
    assert load_settings(None, token=None).token is None


# ---------------------------------------------------------------------- the token


@pytest.fixture
def token_client(settings: AppSettings):
    with TestClient(create_app(settings.replace(token=TOKEN, scene=True)), base_url=BASE_URL) as c:
        yield c


def api_routes(client: TestClient) -> list[tuple[str, str]]:
    """Every (method, path) of the API, from its OpenAPI document (path parameters filled in)."""
    out = []
    for path, ops in client.get("/openapi.json", params={"token": TOKEN}).json()["paths"].items():
        assert path.startswith("/api/"), path
        filled = path.replace("{session_id}", "0000aaaa").replace("{index}", "0")
        out += [(m.upper(), filled) for m in ops]
    return out


def test_every_api_call_needs_the_token(token_client: TestClient) -> None:
    routes = api_routes(token_client)
    assert len(routes) >= 25
    for method, path in routes:
        r = token_client.request(method, path)
        assert r.status_code == 401, (method, path, r.status_code)
        assert "token" in r.json()["detail"] and r.headers["www-authenticate"] == "Bearer"
        wrong = token_client.request(method, path, headers={"Authorization": "Bearer not-the-token-at-all"})
        assert wrong.status_code == 401
        for good in ({"headers": {"Authorization": f"Bearer {TOKEN}"}}, {"params": {"token": TOKEN}}):
            assert token_client.request(method, path, **good).status_code != 401, (method, path)
    # the page and its assets load without it (they hold no data); the page then sends it
    assert token_client.get("/").status_code == 200 and token_client.get("/static/app.js").status_code == 200
    assert "Authorization" in token_client.get("/static/app.js").text


def test_the_viewer_link_never_carries_the_token(token_client: TestClient) -> None:
    v = token_client.get("/api/viewer", params={"token": TOKEN}).json()
    assert TOKEN not in str(v) and v["url"].startswith("http://127.0.0.1:")
    spec = token_client.get("/openapi.json", params={"token": TOKEN}).json()
    assert spec["components"]["securitySchemes"]["bearer"] == {"type": "http", "scheme": "bearer"}


def test_docs_and_the_schema_need_the_token(token_client: TestClient) -> None:
    for path in ("/openapi.json", "/docs", "/redoc"):
        assert token_client.get(path).status_code == 401, path
        assert token_client.get(path, headers={"Authorization": f"Bearer {TOKEN}"}).status_code == 200, path
    page = token_client.get("/docs", params={"token": TOKEN}).text
    assert "/openapi.json?token=" in page  # the page's own fetch of the schema carries it
    assert token_client.get("/docs-static/favicon.png").status_code == 200  # assets hold no data


def test_the_access_log_never_shows_the_token(live_server_token) -> None:
    """A real uvicorn writes its access log; the lines that reach the log's handlers carry no token."""
    import httpx

    class Keep(logging.Handler):
        def __init__(self) -> None:
            super().__init__()
            self.lines: list[str] = []

        def emit(self, record: logging.LogRecord) -> None:
            self.lines.append(record.getMessage())

    access = logging.getLogger("uvicorn.access")
    keep, level = Keep(), access.level
    access.addHandler(keep)
    access.setLevel(logging.INFO)
    try:
        url = live_server_token.url
        assert httpx.get(f"{url}/api/health", params={"token": TOKEN}).status_code == 200
        assert httpx.get(f"{url}/api/sessions?x=1&token={TOKEN}&ticket=abc123").status_code == 200
        assert httpx.get(f"{url}/openapi.json?TOKEN={TOKEN}").status_code == 401  # the name is case-sensitive
    finally:
        access.removeHandler(keep)
        access.setLevel(level)
    assert len(keep.lines) == 3, keep.lines
    assert all(TOKEN not in line and "abc123" not in line for line in keep.lines), keep.lines
    assert all("=***" in line for line in keep.lines), keep.lines


@pytest.fixture
def live_server_token(settings: AppSettings):
    with running_server(settings.replace(port=free_port(), token=TOKEN)) as live:
        yield live


# ---------------------------------------------------------------------- host, origin, CORS


def test_foreign_host_headers_are_refused_on_loopback(client: TestClient) -> None:
    for host in ("evil.example", "evil.example:8000", "10.0.0.1"):
        r = client.get("/api/sessions", headers={"host": host})
        assert r.status_code == 400 and "refused" in r.json()["detail"]
    for host in ("127.0.0.1:8000", "localhost", "[::1]:8000"):
        assert client.get("/api/health", headers={"host": host}).status_code == 200


def test_a_proxy_name_can_be_allowed(settings: AppSettings) -> None:
    with TestClient(create_app(settings.replace(allowed_hosts=("Robot.Lab",))), base_url=BASE_URL) as c:
        assert c.get("/api/health", headers={"host": "robot.lab:443"}).status_code == 200
        assert c.get("/api/health", headers={"host": "other.lab"}).status_code == 400


def test_cross_origin_writes_are_refused(client: TestClient) -> None:
    body = {"config": SMALL}
    for origin in ("http://evil.example", "null", "http://127.0.0.1:9999"):
        r = client.post("/api/sessions", json=body, headers={"origin": origin})
        assert r.status_code == 403 and "cross-origin" in r.json()["detail"]
    assert client.get("/api/sessions").json() == []
    assert client.post("/api/sessions", json=body, headers={"origin": "http://127.0.0.1"}).status_code == 201
    assert client.get("/api/health", headers={"origin": "http://evil.example"}).status_code == 200


def test_cors_is_closed_unless_configured(client: TestClient, settings: AppSettings) -> None:
    pre = {"origin": "http://lab.example", "access-control-request-method": "POST"}
    r = client.options("/api/sessions", headers=pre)
    assert "access-control-allow-origin" not in r.headers
    assert "access-control-allow-origin" not in client.get("/api/health", headers={"origin": pre["origin"]}).headers
    with TestClient(create_app(settings.replace(cors_origins=("http://lab.example",))), base_url=BASE_URL) as c:
        r = c.options("/api/sessions", headers={**pre, "access-control-request-headers": "content-type"})
        assert r.status_code == 200 and r.headers["access-control-allow-origin"] == "http://lab.example"
        r = c.post("/api/sessions", json={"config": SMALL}, headers={"origin": "http://lab.example"})
        assert r.status_code == 201 and r.headers["access-control-allow-origin"] == "http://lab.example"
        r = c.post("/api/sessions", json={"config": SMALL}, headers={"origin": "http://other.example"})
        assert r.status_code == 403 and "access-control-allow-origin" not in r.headers


# ---------------------------------------------------------------------- files


@pytest.fixture
def outside(tmp_path: Path) -> Path:
    """A secret mesh and a recording outside the models and data directories."""
    d = tmp_path / "outside"
    d.mkdir()
    (d / "secret.obj").write_text(CUBE_OBJ)
    (d / "rec").mkdir()
    return d


TRICKS = [
    "../outside/secret.obj",
    "../../outside/secret.obj",
    "..%2Foutside%2Fsecret.obj",
    "%2e%2e/outside/secret.obj",
    "uploads/../../outside/secret.obj",
    "uploads/../../../outside/secret.obj",
    "/etc/passwd",
    "{tmp}/outside/secret.obj",
    "link.obj",
    "uploads/link.obj",
    "cube.obj/../../outside/secret.obj",
    "cube.obj\x00.png",
]


def test_no_request_reaches_files_outside_the_models_and_data_dirs(
    client: TestClient, settings: AppSettings, outside: Path, tmp_path: Path
) -> None:
    os.symlink(outside / "secret.obj", settings.models_dir / "link.obj")  # a symlink planted in models_dir
    (settings.data_dir / "uploads").mkdir(parents=True)
    os.symlink(outside / "secret.obj", settings.data_dir / "uploads" / "link.obj")
    (settings.data_dir / "recordings").mkdir()
    os.symlink(outside / "rec", settings.data_dir / "recordings" / "linked")
    names = [m["name"] for m in client.get("/api/models").json()]
    assert "link.obj" not in names and "uploads/link.obj" not in names and "cube.obj" in names
    assert client.get("/api/recordings").json() == []
    for trick in TRICKS:
        name = trick.format(tmp=tmp_path)
        r = client.post("/api/sessions", json={"model": name})
        assert r.status_code == 422 and "unknown" in r.json()["detail"], (name, r.text)
        for rec in (name, "linked", "../outside/rec"):
            r = client.post("/api/sessions", json={"source": {"kind": "replay", "recording": rec}})
            assert r.status_code in (404, 422), (rec, r.text)
    assert client.get("/api/sessions").json() == []


@pytest.mark.parametrize(
    "path",
    [
        "/static/../app/main.py",
        "/static/%2e%2e/main.py",
        "/static/..%2fmain.py",
        "/static/%2e%2e%2f%2e%2e%2fpyproject.toml",
        "/static//etc/passwd",
        "/docs-static/../../../etc/passwd",
        "/docs-static/%2e%2e/__init__.py",
        "/api/sessions/..%2F..%2Fetc/export",
        "/api/sessions/%2e%2e/cloud.ply",
        "/api/sessions/../../etc/passwd",
    ],
)
def test_url_tricks_find_nothing(client: TestClient, path: str) -> None:
    r = client.get(path)
    assert r.status_code in (400, 404, 405), r.status_code
    assert b"import" not in r.content and b"root:" not in r.content and b"[project]" not in r.content


def test_upload_names_cannot_choose_where_they_are_stored(client: TestClient, settings: AppSettings) -> None:
    for i, name in enumerate(["../../evil.obj", "/tmp/evil.obj", "..\\..\\evil.obj", "a/b/../../../evil.obj"]):
        data = CUBE_OBJ + f"# {i}\n"  # a new content each time (the stored name carries a content hash)
        r = client.post("/api/models", files={"file": (name, data.encode(), "text/plain")})
        assert r.status_code == 201, r.text
        stored = r.json()["name"].removeprefix("uploads/")
        assert "/" not in stored and "\\" not in stored and ".." not in stored
        assert (settings.data_dir / "uploads" / stored).is_file()
    assert sorted(p.parent for p in settings.data_dir.rglob("*.obj")) == [settings.data_dir / "uploads"] * 4
    assert not (settings.data_dir.parent / "evil.obj").exists()


def test_a_viewer_handshake_with_two_host_headers_is_refused_with_400(
    settings: AppSettings, caplog: pytest.LogCaptureFixture
) -> None:
    """Which Host (or Origin) counts would be a guess: 400 before any websocket opens, no traceback logged."""
    with TestClient(create_app(settings.replace(scene=True)), base_url=BASE_URL) as c:
        port = c.get("/api/viewer").json()["port"]

        def handshake(*extra: str) -> bytes:
            lines = [
                "GET / HTTP/1.1", f"Host: 127.0.0.1:{port}", *extra, f"Origin: http://127.0.0.1:{port}",
                "Upgrade: websocket", "Connection: Upgrade", "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==",
                "Sec-WebSocket-Version: 13", "Sec-WebSocket-Protocol: viser-v1",
            ]  # fmt: skip
            with socket.create_connection(("127.0.0.1", port), timeout=10) as sock:
                sock.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
                return sock.recv(4096)

        assert handshake().startswith(b"HTTP/1.1 101")  # the same handshake with one Host opens
        for extra in ("Host: evil.example", f"Origin: http://127.0.0.1:{port}"):
            answer = handshake(extra)
            assert answer.startswith(b"HTTP/1.1 400"), answer[:200]
            assert b"header is repeated" in answer
    assert not [r for r in caplog.records if r.exc_info or "MultipleValuesError" in r.getMessage()]
