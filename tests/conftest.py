"""Test-suite settings.

Under CI (``CI`` set in the environment) hypothesis runs derandomized: the same examples every
run, so a submission's CI result does not depend on the draw. Local runs keep hypothesis's
random exploration (and its example database) to find new counterexamples.

Strategies and reference helpers that several test modules use live in ``tests/strategies.py``
(``from tests.strategies import …``): under ``--import-mode=importlib`` test modules cannot
import each other, and fixtures cannot feed ``@given``.
"""

from __future__ import annotations

import os

from hypothesis import settings

settings.register_profile("ci", derandomize=True, deadline=None, print_blob=True)
if os.environ.get("CI"):
    settings.load_profile("ci")
