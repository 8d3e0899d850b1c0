"""testbed.report.run_plots and .timeline: the timeline's window, and the PNGs of a synthetic
run (the frame classification they draw is tested in tests/channel/test_trace.py)."""

from __future__ import annotations

import math
import struct
from pathlib import Path

import numpy as np
import pytest
from matplotlib import colors
from matplotlib.image import imread

from testbed.channel import EventKind, Trace, transmissions
from testbed.report.run_plots import plot_attitude_errors, write_plots
from testbed.report.timeline import plot_timeline, timeline_window
from testbed.run.recorder import SERIES_COLUMNS, Recorder

K = EventKind
OP, VEH, BUOY = "operator", "vehicle", "buoy"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _sent(trace: Trace, t_s: float, src: str, frame_id: int, size: int, parts: int = 1) -> None:
    """Enqueue a frame and transmit it in ``parts`` packets of ``size`` bytes, 0.2 s each."""
    trace.record(t_s, K.ENQUEUE, src, "*", frame_id, 0, size * parts)
    for part in range(parts):
        start = t_s + 0.2 * part
        trace.record(start, K.TX_START, src, "*", frame_id, part, size)
        trace.record(start + 0.2, K.TX_END, src, "*", frame_id, part, size)


def _received(
    trace: Trace,
    t_s: float,
    kind: EventKind,
    src: str,
    dst: str,
    frame_id: int,
    part: int = 0,
    size: int = 20,
) -> None:
    trace.record(t_s, kind, src, dst, frame_id, part, size, 3 if kind is K.CORRUPT else 0)


def hand_made_trace() -> Trace:
    """A trace with every kind of event and every frame outcome (the timeline's colours)."""
    trace = Trace()
    _sent(trace, 0.0, OP, 0, 20)
    _received(trace, 0.2, K.DELIVER, OP, VEH, 0)
    _sent(trace, 0.5, VEH, 1, 60)
    _received(trace, 0.7, K.CORRUPT, VEH, OP, 1, size=60)
    _sent(trace, 1.0, OP, 2, 20)
    _received(trace, 1.2, K.COLLIDE, OP, VEH, 2)
    _sent(trace, 1.5, VEH, 3, 60)
    _received(trace, 1.7, K.OUTAGE, VEH, OP, 3, size=60)
    _sent(trace, 2.0, OP, 4, 20)
    _received(trace, 2.0, K.OUT_OF_RANGE, OP, VEH, 4)
    trace.record(2.5, K.ENQUEUE, VEH, "*", 5, 0, 300)  # FIFO full
    trace.record(2.5, K.DROP, VEH, "*", 5, 0, 300)
    _sent(trace, 3.0, VEH, 6, 64, parts=2)  # one packet hit: the frame is lost
    _received(trace, 3.2, K.DELIVER, VEH, OP, 6, part=0, size=64)
    _received(trace, 3.4, K.CORRUPT, VEH, OP, 6, part=1, size=64)
    _sent(trace, 4.0, VEH, 7, 64, parts=2)  # collided outranks corrupted
    _received(trace, 4.2, K.CORRUPT, VEH, OP, 7, part=0, size=64)
    _received(trace, 4.4, K.COLLIDE, VEH, OP, 7, part=1, size=64)
    _sent(trace, 5.0, OP, 8, 20)  # two receivers, one lost it
    _received(trace, 5.2, K.DELIVER, OP, VEH, 8)
    _received(trace, 5.2, K.COLLIDE, OP, BUOY, 8)
    _sent(trace, 5.5, VEH, 9, 60, parts=2)  # every packet clean
    _received(trace, 5.7, K.DELIVER, VEH, OP, 9, part=0, size=60)
    _received(trace, 5.9, K.DELIVER, VEH, OP, 9, part=1, size=60)
    _sent(trace, 6.5, OP, 12, 20, parts=2)  # collided outranks out of range
    _received(trace, 6.5, K.OUT_OF_RANGE, OP, VEH, 12, part=0)
    _received(trace, 6.9, K.COLLIDE, OP, VEH, 12, part=1)
    _sent(trace, 7.5, VEH, 13, 60, parts=2)  # outage outranks corrupted
    _received(trace, 7.7, K.CORRUPT, VEH, OP, 13, part=0, size=60)
    _received(trace, 7.9, K.OUTAGE, VEH, OP, 13, part=1, size=60)
    _sent(trace, 9.8, OP, 10, 20)  # on the air when the run ends
    trace.record(9.9, K.ENQUEUE, VEH, "*", 11, 0, 60)  # still queued
    return trace


def synthetic_recorder() -> Recorder:
    """A 10 s run at 100 Hz: step sticks received 0.3 s late, a failsafe, noisy attitude."""
    rec = Recorder(trace=hand_made_trace())
    t = np.arange(1000) * 0.01
    rng = np.random.default_rng(7)
    cols = {name: np.zeros_like(t) for name in SERIES_COLUMNS}
    cols["t_s"] = t
    for k, axis in enumerate(("x", "y", "z", "yaw")):
        on = 1.0 + 2.0 * k
        cols[f"cmd_{axis}"] = np.where((t >= on) & (t < on + 1.5), 0.5, 0.0)
        cols[f"rx_{axis}"] = np.where((t >= on + 0.3) & (t < on + 1.8), 0.5, 0.0)
    cols["north_m"] = 0.2 * t
    cols["east_m"] = np.sin(t)
    cols["down_m"] = 2.0 + 0.1 * np.sin(t)
    cols["yaw_deg"] = (40.0 * t + 180.0) % 360.0 - 180.0  # wraps twice
    for name, std in (("roll", 0.5), ("pitch", 0.8), ("yaw", 2.0)):
        cols[f"err_{name}_deg"] = rng.normal(0.0, std, t.size)
        cols[f"{name}_deg"] += 0.0 if name == "yaw" else cols[f"err_{name}_deg"]
    cols["err_yaw_deg"][t < 0.5] = math.nan
    cols["depth_target_m"] = np.where(t >= 0.5, 2.0, math.nan)
    cols["armed"] = (t >= 0.5).astype(float)
    cols["failsafe"] = np.where((t >= 6.0) & (t < 7.0), 1.0, 0.0)
    rec.rows = [tuple(row) for row in np.column_stack([cols[c] for c in SERIES_COLUMNS])]
    rec.event(0.5, VEH, "armed")
    rec.event(6.0, VEH, "failsafe", "HOLD")
    rec.event(7.0, VEH, "failsafe", "NOMINAL")
    return rec


def png_size(path: Path) -> tuple[int, int]:
    """(width, height) [px] from a PNG's IHDR chunk, after checking the signature."""
    head = path.read_bytes()[:24]
    assert head[:8] == PNG_MAGIC
    assert head[12:16] == b"IHDR"
    width, height = struct.unpack(">II", head[16:24])
    return width, height


def has_colour(rgb: np.ndarray, colour: str, tol: float = 0.02) -> bool:
    """Whether some pixel of an (h, w, 3) image is within ``tol`` (per channel) of ``colour``."""
    target = np.array(colors.to_rgb(colour))
    return bool((np.abs(rgb - target).max(axis=-1) < tol).any())


@pytest.fixture(scope="module")
def plots(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    out = tmp_path_factory.mktemp("plots") / "run"  # not created yet: write_plots makes it
    return write_plots(
        synthetic_recorder(), out, title="synthetic", attitude_experiment=True, settle_s=1.0
    )


# -- the timeline's window ---------------------------------------------------------------------


def test_timeline_window_is_twenty_seconds_from_the_first_transmission_unless_too_dense() -> None:
    sparse = Trace()
    sparse.record(0.5, K.ENQUEUE, OP, "*", 0, 0, 20)  # queued before its slot
    for k in range(100):  # one 20 B frame per second from t = 1 s
        _sent(sparse, 1.0 + k, OP, k, 20)
    assert timeline_window(transmissions(sparse)) == (1.0, 21.0)
    dense = Trace()
    for k in range(1000):  # one every 10 ms from t = 2 s: the 301st packet starts at 5 s
        _sent(dense, 2.0 + 0.01 * k, VEH, k, 20)
    t0, t1 = timeline_window(transmissions(dense), max_packets=300)
    assert (t0, t1) == (2.0, pytest.approx(5.0))
    short = hand_made_trace()  # last event: frame 10's tx_end at 10.0 s
    assert timeline_window(transmissions(short)) == (0.0, pytest.approx(10.0))
    assert timeline_window([]) == (0.0, 0.0)


# -- the PNGs ----------------------------------------------------------------------------------


def test_write_plots_writes_the_four_named_pngs_at_their_figure_sizes(plots: list[Path]) -> None:
    names = [p.name for p in plots]
    assert names == ["timeline.png", "speeds.png", "state.png", "attitude_errors.png"]
    expected_px = {  # figure size [in] × 110 dpi; a timeline row per sender (the buoy only hears)
        "timeline.png": (1320, 748),
        "speeds.png": (1210, 935),
        "state.png": (1430, 990),
        "attitude_errors.png": (1430, 506),
    }
    for path in plots:
        assert png_size(path) == expected_px[path.name]
        assert path.stat().st_size > 20_000  # drawn, not blank
        assert float(imread(path)[..., :3].std()) > 0.05


def test_timeline_draws_each_outcome_in_its_own_colour(plots: list[Path]) -> None:
    timeline = imread(plots[0])[..., :3]
    for colour in ("tab:blue", "tab:orange", "tab:purple", "tab:cyan", "tab:brown", "tab:red"):
        assert has_colour(timeline, colour), colour


def test_empty_recorder_gives_the_three_plots_of_a_non_attitude_run(tmp_path: Path) -> None:
    paths = write_plots(Recorder(), tmp_path, title="empty", attitude_experiment=False, settle_s=0)
    assert [p.name for p in paths] == ["timeline.png", "speeds.png", "state.png"]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(p.name for p in paths)
    for path in paths:
        width, height = png_size(path)
        assert width > 1000 and height > 500


def test_attitude_errors_with_no_settled_sample_still_draw(tmp_path: Path) -> None:
    series = synthetic_recorder().series()
    path = plot_attitude_errors(series, tmp_path / "late.png", title="t", settle_s=60.0)
    assert png_size(path) == (1430, 506)


def test_timeline_rejects_a_non_positive_window_or_packet_count(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="window_s"):
        plot_timeline(Trace(), tmp_path / "x.png", title="t", window_s=0.0)
    with pytest.raises(ValueError, match="max_packets"):
        plot_timeline(Trace(), tmp_path / "x.png", title="t", max_packets=0)
