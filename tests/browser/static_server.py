"""The browser tests' static file server: :mod:`range_server` (mounted folders, HTTP Range, a request log)."""

from range_server import RangeServer, parse_range, resolve, serve_static

__all__ = ["RangeServer", "parse_range", "resolve", "serve_static"]
