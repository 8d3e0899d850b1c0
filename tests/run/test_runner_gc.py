"""testbed.run.runner.long_lived_frozen: the objects alive at a run's start stay out of the
collector's passes during the run, and the collector is as it was afterwards."""

from __future__ import annotations

import gc

import pytest

from testbed.run.runner import long_lived_frozen


def test_frozen_during_the_run_and_restored_after_also_on_an_interrupt() -> None:
    before = gc.get_freeze_count()
    alive = [object()]  # a tracked object alive on entry
    with long_lived_frozen():
        assert gc.get_freeze_count() >= before + 1  # at least the list above
    assert gc.get_freeze_count() == before
    with pytest.raises(KeyboardInterrupt), long_lived_frozen():
        raise KeyboardInterrupt
    assert gc.get_freeze_count() == before
    assert alive
