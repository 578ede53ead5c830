"""SQLite persistence of built datasets, and the bookkeeping of the builds that write them.

- :mod:`engine.store.store`: :class:`~engine.store.store.CCSStore`, a dataset's rows, metadata and labels
  written in one transaction and read back decoded;
- :mod:`engine.store.builds`: the builds recorded in the same file (claimed ids, progress, failures);
- :mod:`engine.store.connection`: the open file (a connection per thread, write transactions, WAL, checks);
- :mod:`engine.store.records` and :mod:`engine.store.codec`: the records and their column bytes (no SQL);
- :mod:`engine.store.schema`: the tables and the format number;
- :mod:`engine.store.switch`: replicas switching to a new store file atomically.

No geometry and no reprojection: the rows arrive ready and leave decoded. Importers name the module that holds
a name (as in ``engine.serve`` and ``engine.io``); nothing is re-exported here.
"""
