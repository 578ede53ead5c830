"""A dataset's way in: uploads streamed to disk and checked in a process of their own
(:mod:`~app.datasets.uploads`, :mod:`~app.datasets.upload_check`), and builds run in processes of their own
(:mod:`~app.datasets.builds`)."""
