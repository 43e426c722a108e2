"""/docs and /redoc work offline: their scripts and styles are served by the app, nothing from a CDN."""

from __future__ import annotations

import re

from fastapi.testclient import TestClient


def test_docs_pages_load_only_local_assets(client: TestClient) -> None:
    for page, assets in (
        ("/docs", ["/docs-static/swagger-ui-bundle.js", "/docs-static/swagger-ui.css"]),
        ("/redoc", ["/docs-static/redoc.standalone.js"]),
    ):
        r = client.get(page)
        assert r.status_code == 200 and "text/html" in r.headers["content-type"]
        html = r.text
        for asset in assets:
            assert asset in html
            got = client.get(asset)
            assert got.status_code == 200 and len(got.content) > 100_000
        assert not re.search(r"""(src|href)=["']https?://""", html), "a page asset comes from another host"
        assert "cdn" not in html.lower() and "fonts.googleapis" not in html
    assert client.get("/docs-static/favicon.png").headers["content-type"] == "image/png"
    assert client.get("/openapi.json").json()["openapi"].startswith("3.1")  # Swagger UI 5 reads 3.1
    bundle = client.get("/docs-static/swagger-ui-bundle.js").text
    assert re.search(r'"5\.\d+\.\d+"', bundle)  # Swagger UI 5.x (4.x cannot render OpenAPI 3.1)
