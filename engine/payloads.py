"""What a build forwards without opening: an object's pickle, opened where it is used.

The build process is the hub of a build's data: it reads contours from the reader's scratch file and sends
them to workers, and it keeps the surfaces the workers send back in a spool on disk. Where it only forwards an
object, opening it (unpickling) and pickling it again for the next hop was a serial cost of a second core's
worth (issue 26): so a contour waiting on disk travels as the pickle it is kept as, a worker opens it, and a
worker sends a surface back already pickled for a spool on disk.
"""

from __future__ import annotations

import pickle
from typing import Any, TypeVar

T = TypeVar("T")


def pickled(obj: Any) -> bytes:
    """``obj`` as a payload: its pickle, as the scratch file and the spool keep it."""
    return pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)


def opened(payload: T | bytes) -> T:
    """The object a payload holds: a pickle is opened, anything else is the object itself (a set in memory
    forwards its objects as they are)."""
    return pickle.loads(payload) if isinstance(payload, bytes) else payload
