"""Fixtures of the MAVLink endpoint's tests."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.mavlink.gcs import SimGcs


@pytest.fixture
def gcs() -> Iterator[SimGcs]:
    """A ground station in front of an endpoint on a simulated vehicle (:class:`SimGcs`)."""
    station = SimGcs()
    yield station
    station.close()
