"""Helpers the tests share, each written once: MVT decoding (mvt), waiting on a service (server), node (node),
an export that fails half way (export), ending child processes (processes).

Imported as ``support.<module>`` (tests/ is on the path, as for tests/reference_mvt.py).
"""
