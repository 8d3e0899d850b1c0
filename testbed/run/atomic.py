"""Files written whole or not at all: write to a temporary name beside the target, then rename.

The one write-and-rename of the testbed (:func:`replace_atomically`): results, journals and
figures. It imports nothing of the simulation, so a light command (``testbed plot``) can use it.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Callable
from pathlib import Path

__all__ = ["TMP_PREFIX", "replace_atomically"]

TMP_PREFIX = ".tmp-"
"""The prefix of the temporary names (a writer killed part way leaves ``.tmp-*`` behind)."""

_UMASK = os.umask(0o022)
os.umask(_UMASK)  # read once: the process's file-creation mask


def replace_atomically(write: Callable[[Path], object], path: Path) -> Path:
    """Write through ``write(tmp)`` to a temporary name beside ``path``, then rename.

    The temporary file is made new, under a name no one chose beforehand (``mkstemp``): a
    link planted at a fixed name would have had the results written through it. Whatever
    ends ``write`` (an error, Ctrl-C) removes it, and ``path`` keeps what it held before.

    Raises:
        OSError: the write failed (a full disk): its ``filename`` is ``path``.
    """
    tmp = path
    try:
        handle, name = tempfile.mkstemp(prefix=f"{TMP_PREFIX}{path.name}.", dir=path.parent)
        os.fchmod(handle, 0o666 & ~_UMASK)  # as open() would make it (mkstemp makes 0600)
        os.close(handle)
        tmp = Path(name)
        write(tmp)
        os.replace(tmp, path)
    except OSError as err:  # name the file the user knows, not the temporary one
        raise OSError(err.errno, err.strerror, str(path)) from err
    finally:
        if tmp != path:
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()
    return path
