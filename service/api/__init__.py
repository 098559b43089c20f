"""The HTTP API (FastAPI): ``create_app(settings)`` builds it; one route module per resource."""

from .app import create_app

__all__ = ["create_app"]
