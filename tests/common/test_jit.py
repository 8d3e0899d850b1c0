"""Compiled callers of plain functions: the same bits as Python, and caches that follow edits.

Truth: CPython's own evaluation of the same formulas (compiled and interpreted arithmetic are two
independent implementations of IEEE-754 operations and of the C library's functions), and
numba's documented cache behaviour (a cached kernel is reloaded with whatever it compiled in,
unless its cache is emptied), observed in fresh processes.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numba
import numpy as np

from testbed.common.geometry import (
    attitude_error,
    quat_conjugate,
    quat_multiply,
    quat_normalize,
    quat_rotate,
    quat_rotate_inverse,
    wrap_angle,
)


def _interpreted(
    a: tuple[float, float, float, float], b: tuple[float, float, float, float], angle: float
) -> tuple[object, ...]:
    return (
        quat_multiply(a, b),
        quat_conjugate(a),
        quat_rotate(a, (b[1], b[2], b[3])),
        quat_rotate_inverse(a, (b[1], b[2], b[3])),
        attitude_error(a, b),
        wrap_angle(angle),
    )


_compiled = numba.njit(_interpreted)  # the same source, compiled with geometry's formulas


def test_compiled_geometry_gives_the_same_bits_as_python() -> None:
    rng = np.random.default_rng(7)
    angles = [*rng.uniform(-50.0, 50.0, 2000), math.pi, -math.pi, 0.0, 3 * math.pi, -1e9, 1e9]
    for angle in angles:
        a = quat_normalize(tuple(rng.standard_normal(4)))
        b = quat_normalize(tuple(rng.standard_normal(4)))
        assert _compiled(a, b, float(angle)) == _interpreted(a, b, float(angle))


def test_compiled_wrap_angle_uses_the_c_fmod() -> None:
    # math.fmod is exact, so wrapping keeps the bits of angles already in range
    for angle in (0.1, -3.0, math.pi, math.nextafter(-math.pi, 0.0)):
        assert _compiled((1.0, 0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), angle)[5] == wrap_angle(angle)
    assert wrap_angle(-math.pi) == math.pi  # (−π, π]


_HELPER = """
from numba.extending import register_jitable

@register_jitable
def value():
    return {value}
"""
_KERNEL = """
import numba
import helper
from testbed.common.jit import refresh_stale_caches

@numba.njit(cache=True)
def kernel():
    return helper.value()

{guard}
print(kernel())
"""


def _run(directory: Path) -> str:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(directory), *sys.path])}
    result = subprocess.run(
        [sys.executable, str(directory / "kernel.py")],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
        check=True,
    )
    return result.stdout.strip()


def _write_helper(directory: Path, value: int) -> None:
    helper = directory / "helper.py"
    helper.write_text(textwrap.dedent(_HELPER.format(value=value)))
    stamp = time.time() + value  # strictly newer than any cache saved before
    os.utime(helper, (stamp, stamp))


def test_a_guarded_kernel_follows_an_edit_of_the_file_it_calls_into(tmp_path: Path) -> None:
    guard = "refresh_stale_caches([kernel], [helper])"
    (tmp_path / "kernel.py").write_text(textwrap.dedent(_KERNEL.format(guard=guard)))
    _write_helper(tmp_path, 1)
    assert _run(tmp_path) == "1"
    assert _run(tmp_path) == "1"  # loaded from the cache
    assert list((tmp_path / "__pycache__").glob("kernel.kernel-*.nbi"))
    _write_helper(tmp_path, 2)
    assert _run(tmp_path) == "2"  # the edit is seen, not the stale copy


def test_the_guard_leaves_a_fresh_cache_alone(tmp_path: Path) -> None:
    (tmp_path / "kernel.py").write_text(textwrap.dedent(_KERNEL.format(guard="")))
    _write_helper(tmp_path, 1)
    _run(tmp_path)  # compiled and saved (helper.py is stamped in the future: made older below)
    index = next((tmp_path / "__pycache__").glob("kernel.kernel-*.nbi"))
    later = time.time() + 10
    os.utime(index, (later, later))
    sys.path.insert(0, str(tmp_path))
    try:
        import helper  # type: ignore[import-not-found]
        import kernel  # type: ignore[import-not-found]  # prints 1, loading the cache

        from testbed.common.jit import refresh_stale_caches

        assert refresh_stale_caches([kernel.kernel], [helper]) == 0
        os.utime(index, (0, 0))  # now older than helper.py
        assert refresh_stale_caches([kernel.kernel], [helper]) == 1
    finally:
        sys.path.remove(str(tmp_path))
        sys.modules.pop("helper", None)
        sys.modules.pop("kernel", None)
