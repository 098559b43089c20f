"""Pages for people: the clip viewer (``/viewer``), Swagger UI (``/docs``) and ReDoc (``/redoc``), all from
files shipped in ``service/api/static`` (no CDN), and the ``/static`` mount they load their scripts from."""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter, FastAPI, Request
from fastapi.openapi.docs import get_redoc_html, get_swagger_ui_html
from fastapi.responses import HTMLResponse
from starlette.staticfiles import StaticFiles
from starlette.types import Scope

STATIC_DIR = Path(__file__).resolve().parents[1] / "static"
STATIC_CACHE = "no-cache"  # revalidate (ETag / Last-Modified): files change when the service is upgraded
# The pages load and call nothing but this service (ReDoc's bundle would fetch its logo from a CDN): inline
# scripts and styles are the pages' own (import map, Swagger UI's start-up, styled-components).
CSP = ("default-src 'self'; script-src 'self' 'unsafe-inline'; style-src 'self' 'unsafe-inline'; "
       "img-src 'self' data: blob:; font-src 'self' data:; worker-src 'self' blob:; connect-src 'self'; "
       "frame-ancestors 'none'; base-uri 'self'")
PAGE_HEADERS = {"Cache-Control": STATIC_CACHE, "Content-Security-Policy": CSP,
                "Referrer-Policy": "no-referrer"}
# The viewer: its own modules and this service, plus what GLTFLoader needs to read the source model's
# embedded resources: it fetches a GLB's images through blob: URLs (ImageBitmapLoader) or shows them in
# <img> (TextureLoader), and a .gltf's data: URIs the same ways. Its one worker is a module of 'self'.
VIEWER_CSP = ("default-src 'self'; script-src 'self' 'unsafe-inline'; style-src 'self'; "
              "img-src 'self' blob: data:; connect-src 'self' blob: data:; worker-src 'self'; "
              "frame-ancestors 'none'; base-uri 'self'")
VIEWER_HEADERS = {**PAGE_HEADERS, "Content-Security-Policy": VIEWER_CSP}

router = APIRouter(include_in_schema=False)


class RevalidatedStaticFiles(StaticFiles):
    """Static files that browsers revalidate on every use (cheap 304s), so an upgrade is seen at once."""

    def file_response(self, full_path, stat_result, scope: Scope, status_code: int = 200):  # noqa: ANN001, ANN201
        response = super().file_response(full_path, stat_result, scope, status_code)
        response.headers["Cache-Control"] = STATIC_CACHE
        return response


def _root(request: Request) -> str:
    return request.scope.get("root_path", "").rstrip("/")


@router.get("/docs")
def swagger_ui(request: Request) -> HTMLResponse:
    """Swagger UI on the app's OpenAPI document, from the vendored swagger-ui-dist."""
    root = _root(request)
    page = get_swagger_ui_html(openapi_url=f"{root}{request.app.openapi_url}", title="pdeanim API",
                               swagger_js_url=f"{root}/static/vendor/swagger-ui/swagger-ui-bundle.js",
                               swagger_css_url=f"{root}/static/vendor/swagger-ui/swagger-ui.css",
                               swagger_favicon_url=f"{root}/static/vendor/swagger-ui/favicon-32x32.png")
    page.headers.update(PAGE_HEADERS)
    return page


@router.get("/redoc")
def redoc(request: Request) -> HTMLResponse:
    """ReDoc on the app's OpenAPI document, from the vendored redoc bundle (no web fonts)."""
    root = _root(request)
    page = get_redoc_html(openapi_url=f"{root}{request.app.openapi_url}", title="pdeanim API",
                          redoc_js_url=f"{root}/static/vendor/redoc/redoc.standalone.js",
                          redoc_favicon_url=f"{root}/static/vendor/swagger-ui/favicon-32x32.png",
                          with_google_fonts=False)
    page.headers.update(PAGE_HEADERS)
    return page


@router.get("/viewer")
def viewer(request: Request) -> HTMLResponse:
    """The clip viewer page; it reads ``#clip=ID&key=KEY`` (the fragment never reaches the server)."""
    html = (STATIC_DIR / "viewer" / "index.html").read_text().replace("{{ROOT}}", _root(request))
    return HTMLResponse(html, headers=VIEWER_HEADERS)


def install_pages(app: FastAPI) -> None:
    """Add the page routes and mount ``/static``."""
    app.include_router(router)
    app.mount("/static", RevalidatedStaticFiles(directory=STATIC_DIR), name="static")
