"""``/docs``: Swagger UI from files installed with the service, so the page works without the internet.

FastAPI's default page loads Swagger UI from a CDN and is blank offline (a control-room network, a
laptop on a plane).  The ``swagger-ui-bundle-v2`` package (module ``swagger_ui_bundle``) ships Swagger
UI 5's dist files (Swagger UI 4 cannot read FastAPI's OpenAPI 3.1); they are served under
``/docs/assets`` and the page refers only to them (FastAPI, "Custom Docs UI Static Assets").  ReDoc is
off: its page would load from a CDN too, and one documentation page is enough.
"""

from __future__ import annotations

import logging
from pathlib import Path

from fastapi import FastAPI
from fastapi.openapi.docs import get_swagger_ui_html, get_swagger_ui_oauth2_redirect_html
from fastapi.responses import HTMLResponse
from starlette.staticfiles import StaticFiles

log = logging.getLogger(__name__)

ASSETS = "/docs/assets"


def mount_docs(app: FastAPI, path: str = "/docs") -> None:
    """Serve Swagger UI at ``path`` from the installed ``swagger_ui_bundle`` files.

    The app must be created with ``docs_url=None`` (and ``redoc_url=None``) so this page replaces
    FastAPI's CDN one.
    """
    try:
        from swagger_ui_bundle import swagger_ui_path
    except ImportError:
        swagger_ui_path = None
    if swagger_ui_path is None or not Path(swagger_ui_path).is_dir():
        # A broken install must not take REST down with it: say where the API description is instead.
        log.warning("Swagger UI files not installed (swagger-ui-bundle-v2): /docs links to /openapi.json")

        @app.get(path, include_in_schema=False)
        async def no_swagger_ui() -> HTMLResponse:
            return HTMLResponse(f'<p>Swagger UI is not installed (pip install swagger-ui-bundle-v2). '
                                f'The API description is at <a href="{app.openapi_url}">{app.openapi_url}</a>.</p>')
        return

    app.mount(ASSETS, StaticFiles(directory=swagger_ui_path), name="docs-assets")
    redirect = f"{path}/oauth2-redirect"

    @app.get(path, include_in_schema=False)
    async def swagger_ui() -> HTMLResponse:
        return get_swagger_ui_html(
            openapi_url=app.openapi_url, title=f"{app.title} - API", oauth2_redirect_url=redirect,
            swagger_js_url=f"{ASSETS}/swagger-ui-bundle.js", swagger_css_url=f"{ASSETS}/swagger-ui.css",
            swagger_favicon_url=f"{ASSETS}/favicon-32x32.png")

    @app.get(redirect, include_in_schema=False)
    async def swagger_ui_redirect() -> HTMLResponse:
        return get_swagger_ui_oauth2_redirect_html()


__all__ = ["ASSETS", "mount_docs"]
