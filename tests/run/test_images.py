"""Image feedback end to end: camera → coder → chunks over the simulated S100 → operator.

Independent truth: the transfer timing of a token-passing link without bit errors in closed
form (one chunk per inter-packet gap, the last reply's airtime and delay), the coder itself
(a received image must equal ``decode(encode(captured, budget))``), and the paper's behaviour
(one lost chunk spoils an image) against selective repeat on the same link.
"""

from __future__ import annotations

import csv
import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest

from testbed.channel import EventKind, load_link_config
from testbed.config import ConfigError
from testbed.imaging import decode, encode
from testbed.report.run_plots import write_run_plots
from testbed.run.image_record import image_rows
from testbed.run.outputs import write_run
from testbed.run.runner import RunResult, run_scenario
from testbed.run.scenario import load_scenario

GAP_S = 0.6
CHUNK = 40
REPLY_HEADER_FRAME_BYTES = 20
"""A reply frame without a chunk [B] (6 framing + 14 payload)."""


def run(*overrides: str, seed: int | None = None) -> RunResult:
    return run_scenario(load_scenario("s100-video-v1", overrides), seed=seed)


@pytest.fixture(scope="module")
def clean_run() -> RunResult:
    """60 s, no bit errors, a fixed 0.6-s gap, 600-B images (16 chunks)."""
    return run(
        "duration_s=60",
        "link.ber=0",
        "link.ipg=fixed",
        f"link.ipg_s={GAP_S}",
        "images.budget_bytes=600",
        "images.changes=[]",
    )


def _same_image_as_the_coder_gives(result: RunResult, budget: int) -> None:
    log = result.recorder.images
    for image in log.received:
        source = log.captured[image.number]
        expected = decode(encode(source.pixels, budget))
        np.testing.assert_array_equal(image.pixels, expected)


def _clean_latency_s(encoded_bytes: int, number: int) -> float:
    """Capture to completion of an image on the clean run's link [s] (closed form)."""
    link = load_link_config("s100")
    framed = encoded_bytes + 2  # image CRC
    chunks = math.ceil(framed / CHUNK)
    last_frame = REPLY_HEADER_FRAME_BYTES + framed - (chunks - 1) * CHUNK
    # the reply leaves once the vehicle's half-duplex modem has turned round after the order
    delivery_s = link.queue_gap_s + link.intrinsic_delay_s + last_frame * 8.0 / link.bitrate_bps
    # the capture happens when the order asking for chunk 0 lands; the first image's is the
    # 16-B ImageSettings order, later chunk requests are 13-B moves that land sooner
    early_s = (16 - 13) * 8.0 / link.bitrate_bps if number == 0 else 0.0
    return (chunks - 1) * GAP_S + delivery_s - early_s


def test_without_errors_each_image_takes_one_gap_per_chunk(clean_run: RunResult) -> None:
    link = load_link_config("s100")
    log = clean_run.recorder.images
    assert len(log.received) >= 4
    for image in log.received:
        source = log.captured[image.number]
        expected = _clean_latency_s(image.encoded_bytes, image.number)
        assert image.t_s - source.t_s == pytest.approx(expected, abs=1e-6)
    # the next image is captured when the order acknowledging the last one arrives
    captures = sorted(c.t_s for c in log.captured.values())
    chunks = [math.ceil((log.captured[n].encoded_bytes + 2) / CHUNK) for n in sorted(log.captured)]
    for k in range(1, len(captures)):
        early_s = (16 - 13) * 8.0 / link.bitrate_bps if k == 1 else 0.0
        expected = chunks[k - 1] * GAP_S - early_s
        assert captures[k] - captures[k - 1] == pytest.approx(expected, abs=1e-6)
    _same_image_as_the_coder_gives(clean_run, 600)


def test_images_metrics_and_strip(
    clean_run: RunResult, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    metrics = clean_run.metrics["images"]
    log = clean_run.recorder.images
    assert metrics["completed"] == len(log.received)
    assert metrics["per_minute"] == pytest.approx(len(log.received))  # a 60-s run
    assert metrics["bytes_delivered"] == sum(r.encoded_bytes for r in log.received)
    assert metrics["crc_failures"] == 0 and metrics["spoiled"] == 0
    whole = sum(math.ceil((r.encoded_bytes + 2) / CHUNK) for r in log.received)
    assert (
        whole
        <= metrics["chunks_received"]
        <= metrics["chunks_sent"]
        <= metrics["chunks_received"] + 1
    )
    assert 20.0 < metrics["psnr_db"]["mean"] < 60.0  # lossy at 600 B, not garbage
    assert metrics["latency_s"]["p95"] >= metrics["latency_s"]["mean"] > 0.0
    # the run's other plots (state, speeds, lag: ≈ 1 s) are not the subject, the strip is
    monkeypatch.setattr("testbed.report.run_plots.write_plots", lambda *args, **kwargs: [])
    written = write_run(clean_run, tmp_path, plots=write_run_plots)
    assert tmp_path / "images.png" in written and (tmp_path / "images.png").stat().st_size > 5000
    on_disk = json.loads((tmp_path / "metrics.json").read_text())
    assert on_disk["images"]["completed"] == metrics["completed"]


def test_selective_repeat_completes_what_paper_mode_spoils() -> None:
    """BER 5e-4: a 60-B reply is lost with p ≈ 21 %, so a 16-chunk image survives paper mode
    with p ≈ 0.79^16 ≈ 2 %, while selective repeat completes every image it starts."""
    common = ("duration_s=90", "link.ber=5e-4", "images.budget_bytes=600", "images.changes=[]")
    repeat = run(*common)
    paper = run(*common, "images.selective_repeat=false")
    got, lost = repeat.metrics["images"], paper.metrics["images"]
    assert got["completed"] >= 3 and got["crc_failures"] == 0
    assert got["completed"] >= got["captured"] - 1  # all but the one in flight at the end
    _same_image_as_the_coder_gives(repeat, 600)
    assert lost["completed"] <= 1 and lost["spoiled"] >= 3
    assert paper.metrics["link"]["downlink"]["per"] > 0.1


def test_settings_change_reaches_the_coder() -> None:
    result = run("duration_s=60", "link.ber=0", "images.changes=[{t_s=20, budget_bytes=400}]")
    log = result.recorder.images
    before = [c for c in log.captured.values() if c.t_s < 20.0]
    after = [c for c in log.captured.values() if c.t_s > 21.0]
    assert before and after
    assert all(c.encoded_bytes > 1000 for c in before)  # 1200-B budget of the scenario
    assert all(c.encoded_bytes <= 400 for c in after)
    assert result.metrics["images"]["settings_sent"] == 2  # no loss: each sent once
    assert result.metrics["images"]["settings_acknowledged"] == 2
    # each settings order took a move order's gap (1.19 s between moves, more than the 1-s
    # hold timeout) yet the vehicle's failsafe never held: the order counts as contact
    assert result.metrics["events"]["failsafe"] == 0


def test_same_seed_same_images() -> None:
    args = ("duration_s=40", "link.ber=3e-4", "images.changes=[]")
    first = run(*args, seed=3).recorder.images
    second = run(*args, seed=3).recorder.images
    assert [(r.number, r.t_s) for r in first.received] == [
        (r.number, r.t_s) for r in second.received
    ]
    for a, b in zip(first.received, second.received, strict=True):
        np.testing.assert_array_equal(a.pixels, b.pixels)


@pytest.mark.parametrize(
    ("override", "key"),
    [
        ("vehicle.camera.enabled=false", "images.enabled"),
        ("link.codec=changeset;link.mac=free", "images.enabled"),
        ("images.budget_bytes=3000", "images.budget_bytes"),
        ("images.roi=[0, 0, 200, 10]", "images.roi"),
        ("images.chunk_bytes=151", "images.chunk_bytes"),
    ],
)
def test_bad_image_settings_name_the_key(override: str, key: str) -> None:
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        load_scenario("s100-video-v1", override.split(";"))


def test_run_summary_has_an_images_line(clean_run: RunResult) -> None:
    from testbed.cli.main import format_summary

    images = clean_run.metrics["images"]
    text = format_summary(clean_run.metrics, Path("out"))
    assert f"images {images['completed']}/{images['captured']} completed" in text
    assert f"latency mean {images['latency_s']['mean']:.1f} s" in text
    none_yet = {**clean_run.metrics, "images": {**images, "completed": 0}}
    none_yet["images"]["latency_s"] = {"mean": math.nan}
    none_yet["images"]["psnr_db"] = {"mean": None}
    assert "latency mean n/a, PSNR mean n/a" in format_summary(none_yet, Path("out"))


def test_run_summary_says_n_a_for_a_yaw_error_it_could_not_measure(clean_run: RunResult) -> None:
    # a run with no yaw target to hold (a supervised mission) has no yaw error: n/a, not nan
    from testbed.cli.main import format_summary

    attitude = clean_run.metrics["attitude_error_deg"]
    yaw = attitude["yaw"]
    assert f"yaw error std {yaw['std']:.2f} deg" in format_summary(clean_run.metrics, Path("out"))
    unmeasured = {**clean_run.metrics, "attitude_error_deg": {**attitude, "yaw": {"std": math.nan}}}
    assert "yaw error std n/a;" in format_summary(unmeasured, Path("out"))


def test_an_image_that_decodes_to_no_picture_is_counted_not_scored_lossless() -> None:
    """A budget too small for the coder's header completes an image whose bits decode to a
    (0, 0) picture: it is counted ``undecodable`` and left out of the PSNR (it used to score
    99 dB, "lossless", because min(99, NaN) is 99)."""
    from testbed.run.image_record import CapturedImage, ImageLog, ReceivedImage, image_metrics

    rng = np.random.default_rng(1)
    frame = rng.integers(0, 256, (24, 32), dtype=np.uint8)
    noisy = np.clip(frame.astype(int) + rng.integers(-8, 9, frame.shape), 0, 255).astype(np.uint8)
    log = ImageLog()
    for number in range(3):
        log.captured[number] = CapturedImage(number, float(number), frame, 10)
    log.received.append(ReceivedImage(0, 0.5, np.zeros((0, 0), dtype=np.uint8), 1))
    log.received.append(ReceivedImage(1, 1.5, noisy, 10))
    log.received.append(ReceivedImage(2, 2.5, frame.copy(), 10))
    metrics = image_metrics(log, 60.0)
    error = frame.astype(float) - noisy.astype(float)
    expected = 10.0 * math.log10(255.0**2 / float(np.mean(error * error)))
    assert metrics["completed"] == 3 and metrics["undecodable"] == 1
    assert metrics["psnr_db"]["min"] == pytest.approx(expected)
    assert metrics["psnr_db"]["mean"] == pytest.approx((expected + 99.0) / 2)
    only_undecodable = ImageLog(captured=dict(log.captured), received=log.received[:1])
    assert math.isnan(image_metrics(only_undecodable, 60.0)["psnr_db"]["mean"])


def test_images_before_the_settings_order_arrives_use_the_configured_budget() -> None:
    """Both ends are configured from the scenario: when the operator's first settings orders
    are lost (BER 1e-3, seed 64: 5 sent, 1 acknowledged), the vehicle's first image is still
    coded within the 600-B budget, not the whole 64-chunk limit (2558 B, 74 s to send)."""
    result = run(
        "duration_s=120",
        "link.ber=1e-3",
        "images.budget_bytes=600",
        "images.changes=[]",
        seed=64,
    )
    counters = result.metrics["images"]
    assert counters["settings_acknowledged"] < counters["settings_sent"]  # orders were lost
    captured = result.recorder.images.captured.values()
    assert captured and all(image.encoded_bytes <= 600 for image in captured)


def test_images_csv_lists_each_image_against_the_closed_form(
    clean_run: RunResult, tmp_path: Path
) -> None:
    """``images.csv``: one row per capture; a completed image's latency is the clean link's
    closed form, its PSNR the coder's own result at the budget, and the steady completion
    interval is one gap per chunk (16 chunks of a 600-B image: 9.6 s, 6.25 a minute)."""
    write_run(clean_run, tmp_path)
    with (tmp_path / "images.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    log = clean_run.recorder.images
    assert [int(r["number"]) for r in rows] == sorted(log.captured)
    completed = [r for r in rows if r["completed_s"]]
    assert len(completed) == len(log.received) >= 4
    for row in completed:
        number, size = int(row["number"]), int(row["encoded_bytes"])
        assert float(row["latency_s"]) == pytest.approx(_clean_latency_s(size, number), abs=1e-5)
        assert int(row["chunks"]) == math.ceil((size + 2) / CHUNK) == 16
        assert int(row["replies"]) == 16  # no reply lost: no chunk sent twice
        assert row["budget_bytes"] == "600" and row["roi"] == "" and row["roi_psnr_db"] == ""
        pixels = log.captured[number].pixels
        error = pixels.astype(float) - decode(encode(pixels, 600)).astype(float)
        expected = 10.0 * math.log10(255.0**2 / float(np.mean(error * error)))
        assert float(row["psnr_db"]) == pytest.approx(expected, abs=1e-3)
    interval = clean_run.metrics["images"]["completion_interval_s"]["mean"]
    assert interval == pytest.approx(16 * GAP_S, abs=1e-6)
    # images.npz: the captured pictures, and the received ones as the coder alone decodes them
    with np.load(tmp_path / "images.npz") as npz:
        assert npz["captured_number"].tolist() == sorted(log.captured)
        for number, pixels in zip(npz["captured_number"], npz["captured"], strict=True):
            np.testing.assert_array_equal(pixels, log.captured[int(number)].pixels)
        assert npz["received_number"].tolist() == [int(r["number"]) for r in completed]
        assert npz["received_decodable"].all()
        for number, pixels in zip(npz["received_number"], npz["received"], strict=True):
            source = log.captured[int(number)].pixels
            np.testing.assert_array_equal(pixels, decode(encode(source, 600)))
        times = [float(r["completed_s"]) for r in completed]
        np.testing.assert_allclose(npz["completed_s"], times, atol=1e-6)
    # image_progress.csv: on a clean link the picture grows one 40-B chunk a gap (the first
    # byte held back until the last chunk, where the CRC may start), and its last row is the
    # completed picture: its PSNR the one images.csv took from the operator's own decode
    with (tmp_path / "image_progress.csv").open(newline="") as handle:
        progress = list(csv.DictReader(handle))
    for row in completed:
        mine = [p for p in progress if p["number"] == row["number"]]
        sizes = [int(p["bytes"]) for p in mine]
        assert sizes == [CHUNK * k - 1 for k in range(1, 16)] + [int(row["encoded_bytes"])]
        times = np.array([float(p["t_s"]) for p in mine])
        # a gap apart, but for the first (the 16-B settings order of image 0 lands sooner)
        # and the last (a shorter reply: the image's last bytes)
        np.testing.assert_allclose(np.diff(times)[1:-1], GAP_S, atol=1e-6)
        assert mine[-1]["t_s"] == row["completed_s"]
        assert float(mine[-1]["psnr_db"]) == pytest.approx(float(row["psnr_db"]), abs=1e-3)
        ages = times - float(row["captured_s"])
        np.testing.assert_allclose([float(p["age_s"]) for p in mine], ages, atol=2e-6)
    # events.csv: a capture and a completion line per image, at the times the rows give
    with (tmp_path / "events.csv").open(newline="") as handle:
        events = [r for r in csv.DictReader(handle) if r["kind"].startswith("image_")]
    captured = [
        (int(e["detail"]), float(e["t_s"])) for e in events if e["kind"] == "image_captured"
    ]
    assert captured == [
        (int(r["number"]), pytest.approx(float(r["captured_s"]), abs=1e-6)) for r in rows
    ]
    done = [(int(e["detail"]), float(e["t_s"])) for e in events if e["kind"] == "image_completed"]
    assert done == [
        (int(r["number"]), pytest.approx(float(r["completed_s"]), abs=1e-6)) for r in completed
    ]


def test_selective_repeat_sends_each_chunk_until_a_reply_gets_through() -> None:
    """At BER 1e-3 a 60-B reply arrives with q = (1 − 1e-3)^480 ≈ 0.62; a reply is sent only
    for an order that arrived, and a chunk is sent again until one gets through, so an image of
    n chunks takes ≈ n / q replies (geometric repeats): ``images.csv``'s ``replies`` over the
    completed images against that closed form, within four standard errors."""
    ber = 1e-3
    result = run("duration_s=600", f"link.ber={ber}", "images.changes=[]", seed=4)
    rows = image_rows(result.recorder.images, CHUNK)
    done = [row for row in rows if row[2] != ""]
    chunks = sum(int(row[5]) for row in done)
    replies = sum(int(row[-1]) for row in done)
    q = (1.0 - ber) ** (8 * (CHUNK + 20))
    # replies − chunks: a sum of `chunks` geometric failure counts, mean (1−q)/q, var (1−q)/q²
    repeats, mean, var = replies - chunks, chunks * (1 - q) / q, chunks * (1 - q) / q**2
    assert len(done) >= 10 and abs(repeats - mean) < 4.0 * math.sqrt(var)


def test_roi_psnr_is_the_psnr_inside_the_region() -> None:
    """With a region of interest (raised 4 bit planes), ``roi_psnr_db`` is the PSNR of the
    region's pixels alone, computed here from the coder; the ROI is sharper than the whole."""
    roi = (40, 30, 119, 89)
    result = run(
        "duration_s=40",
        "link.ber=0",
        "images.budget_bytes=600",
        f"images.roi={list(roi)}",
        "images.roi_shift=4",
        "images.changes=[]",
    )
    log = result.recorder.images
    assert len(log.received) >= 2
    inside: list[float] = []
    for image in log.received:
        pixels = log.captured[image.number].pixels
        coded = decode(encode(pixels, 600, roi, 4))
        x0, y0, x1, y1 = roi
        error = pixels[y0 : y1 + 1, x0 : x1 + 1].astype(float) - coded[
            y0 : y1 + 1, x0 : x1 + 1
        ].astype(float)
        inside.append(10.0 * math.log10(255.0**2 / float(np.mean(error * error))))
    metrics = result.metrics["images"]
    assert metrics["roi_psnr_db"]["mean"] == pytest.approx(float(np.mean(inside)), abs=1e-9)
    assert metrics["roi_psnr_db"]["min"] == pytest.approx(min(inside), abs=1e-9)
    assert metrics["roi_psnr_db"]["mean"] > metrics["psnr_db"]["mean"]


@pytest.mark.parametrize(("chunk", "fits"), [(67, True), (68, False)])
def test_replies_overlap_orders_exactly_when_the_closed_form_round_trip_exceeds_the_gap(
    chunk: int, fits: bool
) -> None:
    """The 2021 rule's 0.594-s gap after a 13-B move order holds the order, the vehicle's
    queue gap and a reply of 20 + chunk bytes at 1900 bit/s for chunks up to 67 B
    (0.5918 s); at 68 B (0.5960 s) the next order leaves before the reply is in, and asks
    again for chunks already on their way. The simulated link agrees with the closed form."""
    from testbed.run.run_metrics import token_cycle

    overrides = ("duration_s=40", "link.ber=0", "images.changes=[]", f"images.chunk_bytes={chunk}")
    scenario = load_scenario("s100-video-v1", overrides)
    cycle = token_cycle(scenario)
    assert cycle is not None and cycle.fits is fits
    link = load_link_config("s100")
    airtime_s = (13 + 20 + chunk) * 8.0 / link.bitrate_bps
    assert cycle.round_trip_s == pytest.approx(
        2 * link.intrinsic_delay_s + airtime_s + link.queue_gap_s, abs=1e-6
    )
    result = run_scenario(scenario)
    assert result.metrics["reply_fits_gap"] is fits
    assert result.metrics["token_round_trip_s"] == cycle.round_trip_s
    duplicates = result.metrics["images"]["duplicates"]
    assert (duplicates == 0) if fits else (duplicates >= 10)


@pytest.mark.parametrize("preset", ["s100-teleop-v1", "m64-teleop-v1"])
def test_the_closed_form_round_trip_is_the_simulated_one(preset: str) -> None:
    """From an order's first transmission to the end of its reply's arrival, in the trace,
    equals ``token_round_trip_s``: both deliveries and the vehicle modem's turn-round (its queue
    gap after the order's reception: 0.1 s on m64, 100 µs on S100; m64 cuts each frame into
    8-B packets, a queue gap apart). Within a tenth of the gap: the acoustic propagation
    changes as the vehicle moves (the closed form takes the start's distance)."""
    from testbed.run.run_metrics import token_cycle

    scenario = load_scenario(preset, ["duration_s=40", "link.ber=0"])
    trace = run_scenario(scenario).recorder.trace
    starts: dict[int, tuple[float, str]] = {}
    packets: dict[int, int] = {}
    for e in trace.of_kind(EventKind.TX_START):
        starts.setdefault(e.frame_id, (e.t_s, e.src))
        packets[e.frame_id] = packets.get(e.frame_id, 0) + 1
    ends: dict[int, list[float]] = {}
    for e in trace.of_kind(EventKind.DELIVER):
        ends.setdefault(e.frame_id, []).append(e.t_s)
    frames = sorted(starts.items(), key=lambda item: item[1][0])
    trips = [
        ends[reply][-1] - start_s
        for (_, (start_s, src)), (reply, (_, reply_src)) in itertools.pairwise(frames)
        if src == "operator" and reply_src == "vehicle"
        and len(ends.get(reply, ())) == packets[reply]  # every packet in by the end
    ]  # fmt: skip
    cycle = token_cycle(scenario)  # a move order's cycle: 13 B, the reply 20 B
    assert cycle is not None and len(trips) >= 5
    gap_s = scenario.link.channel.queue_gap_s
    assert trips == pytest.approx([cycle.round_trip_s] * len(trips), abs=0.1 * gap_s)
