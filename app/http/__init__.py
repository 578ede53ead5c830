"""HTTP plumbing under the routes: error answers, compression, HEAD, disconnects, public URLs, API docs.

Nothing here knows datasets or render workers. The package imports no web framework itself, so a render worker
can use :mod:`app.http.compression` without loading one.
"""
