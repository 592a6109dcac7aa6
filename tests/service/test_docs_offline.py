"""/docs and /redoc work without internet (issue 11): the pages name no other host and every
asset they load is served by the API itself, with and without API keys."""
from __future__ import annotations

import re
from urllib.parse import urljoin

import pytest
from fastapi.testclient import TestClient

from service.app import create_app
from service.docs import ASSET_FILES, ASSETS_URL, assets_dir
from service.settings import Settings

KEY = "docs-key-0123456789abcdef"
# src= and href= attributes, and the spec URL Swagger UI's script and ReDoc's element load
REFERENCES = re.compile(r"""(?:src|href|spec-url)\s*=\s*["']([^"']+)["']|url:\s*'([^']+)'""")


@pytest.fixture(scope="module", params=["open", "keys"])
def client(request, tmp_path_factory):
    keys = KEY if request.param == "keys" else None
    settings = Settings(data_dir=tmp_path_factory.mktemp("docs"), broker_url="memory://",
                        api_keys=keys)
    with TestClient(create_app(settings)) as c:
        yield c


def _references(html: str) -> list[str]:
    return [a or b for a, b in REFERENCES.findall(html)]


@pytest.mark.parametrize("page", ["/docs", "/redoc"])
def test_docs_pages_load_only_from_this_service(client, page):
    response = client.get(page)  # no Authorization header: the docs are public
    assert response.status_code == 200
    html = response.text
    refs = _references(html)
    assert refs, html
    assert not re.search(r"(?:https?:)?//[A-Za-z0-9.-]+\.[A-Za-z]", html.replace(
        "window.location.origin", "")), f"{page} names another host:\n{html}"
    assert "fonts.googleapis" not in html and "cdn.jsdelivr" not in html
    for ref in refs:
        assert ref.startswith("/"), ref
        asset = client.get(urljoin(page, ref))
        assert asset.status_code == 200, (ref, asset.status_code)
        assert asset.content, ref
    if page == "/docs":
        assert '"validatorUrl": null' in html  # no badge fetched from validator.swagger.io
        assert f"{ASSETS_URL}/swagger-ui-bundle.js" in refs
    else:
        assert f"{ASSETS_URL}/redoc.standalone.js" in refs


def test_assets_are_the_real_bundles(client):
    js = client.get(f"{ASSETS_URL}/swagger-ui-bundle.js")
    assert js.headers["content-type"].startswith(("application/javascript", "text/javascript"))
    assert "SwaggerUIBundle" in js.text and len(js.content) > 500_000
    redoc = client.get(f"{ASSETS_URL}/redoc.standalone.js")
    assert "Redoc" in redoc.text and len(redoc.content) > 500_000
    assert client.get(f"{ASSETS_URL}/swagger-ui.css").headers["content-type"].startswith("text/css")
    assert client.get(f"{ASSETS_URL}/no-such-file.js").status_code == 404
    assert client.get("/docs/oauth2-redirect").status_code == 200


def test_every_asset_is_installed():
    assert sorted(p.name for p in assets_dir().iterdir() if p.name in ASSET_FILES) == \
        sorted(ASSET_FILES)
