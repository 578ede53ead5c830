"""Tiles drawn out of the event loop: the jobs a render worker runs (:mod:`~app.render.jobs`), the pools and
lanes that send them (:mod:`~app.render.pool`), and what the workers' fork server compiles first
(:mod:`~app.render.preload`)."""
