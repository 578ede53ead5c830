"""Absolute URLs the service hands to clients (styles, TileJSON): built from the one public base."""

from __future__ import annotations

from fastapi import Request


def public_base_url(request: Request) -> str:
    """The service's public base URL, without a trailing slash: the request's own base for now (one place to
    change when a configured public base is added)."""
    return str(request.base_url).rstrip("/")
