"""The frame store's write rule for compiled kernels, written once (:mod:`testbed.ecs.store`).

A kernel that writes a store-backed component writes the row's fields and then, only when a
field changed, the row's mark: its change tick (the tick of the system that runs it) and its
write count (one more); a row whose value is unchanged is left alone, so that readers are not
woken. :func:`put_row` is that rule;
it is registered with numba (``register_jitable``), so each kernel module compiles it into its
kernels (and names this file to :func:`~testbed.common.jit.refresh_stale_caches`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba.extending import register_jitable

__all__ = ["put_row"]


@register_jitable
def put_row(row: np.ndarray, mark: np.ndarray, tick: int, values: Any) -> None:
    """Write ``values`` (floats, a tuple or an array: the row's fields in order) into ``row``
    and, when a value changed, mark it (``mark``, the row's (2,) view of its change tick and
    write count: ``tick``, and one more write)."""
    changed = False
    for j, value in enumerate(values):
        if row[j] != value:
            row[j] = value
            changed = True
    if changed:
        mark[0] = tick
        mark[1] += 1
