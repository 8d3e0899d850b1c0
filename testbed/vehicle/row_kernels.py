"""The frame store's write rule for compiled kernels, written once (:mod:`testbed.ecs.store`).

A kernel that writes a store-backed component writes the row's fields and then, only when a
field changed, the row's change tick with the tick of the system that runs it; a row whose
value is unchanged is left alone, so that readers are not woken. :func:`put_row` is that rule;
it is registered with numba (``register_jitable``), so each kernel module compiles it into its
kernels (and names this file to :func:`~testbed.common.jit.refresh_stale_caches`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba.extending import register_jitable

__all__ = ["put_row"]


@register_jitable
def put_row(row: np.ndarray, tick_cell: np.ndarray, tick: int, values: Any) -> None:
    """Write ``values`` (a tuple of floats, the row's fields in order) into ``row`` and, when a
    value changed, ``tick`` into ``tick_cell`` (the row's one-element view of its ticks)."""
    changed = False
    for j, value in enumerate(values):
        if row[j] != value:
            row[j] = value
            changed = True
    if changed:
        tick_cell[0] = tick
