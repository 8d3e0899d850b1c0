"""Sweep plots: the closed forms against a second method, files from hand-made and real results,
the closed forms built from the rows' own frame and chunk sizes, ``testbed plot`` and its
errors."""

from __future__ import annotations

import csv
import functools
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from matplotlib.figure import Figure

from testbed.cli.main import main
from testbed.config import ConfigError
from testbed.report.closed_forms import (
    ORDER_FRAME_BYTES,
    closed_form_age_s,
    closed_form_images_per_minute,
    closed_form_per,
)
from testbed.report.pair_plots import plot_pair
from testbed.report.sweep_axes import LogAxis, draw, line
from testbed.report.sweep_plots import image_rate_model, plot_ber_sweep
from testbed.report.sweep_results import read_results
from testbed.run.metrics import age_of_information

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
BERS = (0.0, 1e-5, 1e-4, 1e-3)
GAPS = (0.6, 1.8)
LAG_S = 0.145


def _write_results(path: Path) -> Path:
    """A results.csv shaped like testbed sweep's: BER × gap × 3 seeds, metrics from the closed
    forms plus a seed-dependent wobble, one failed run (empty metrics)."""
    head = ["point", "seed", "link.ber", "link.ipg_s", "status", "error", "ipg_s"]
    metrics = [
        "link.uplink.per",
        "link.uplink.mean_frame_bytes",
        "link.downlink.per",
        "link.downlink.mean_frame_bytes",
        "command_lag_s.mean",
        "command_age_s.mean",
        *(f"velocity_tracking_rmse.{a}" for a in ("x", "y", "z", "yaw")),
    ]
    with path.open("w", encoding="utf-8", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow([*head, *metrics])
        point = 0
        for ber in BERS:
            for gap in GAPS:
                for seed in range(3):
                    wobble = 0.01 * (seed - 1)
                    age = float(closed_form_age_s(ber, gap, LAG_S)) + wobble
                    values = [
                        float(closed_form_per(ber, 13)) + wobble / 10,
                        13.0,
                        float(closed_form_per(ber, 60)),
                        60.0,
                        LAG_S,
                        age,
                        0.1 + ber,
                        0.09,
                        0.02,
                        0.05 + wobble,
                    ]
                    writer.writerow([point, seed, ber, gap, "ok", "", gap, *values])
                empty = [""] * (1 + len(metrics))  # as testbed sweep writes a failed run
                writer.writerow([point, 3, ber, gap, "failed", "RuntimeError: boom", *empty])
                point += 1
    return path


# --- closed forms -------------------------------------------------------------------------------


def test_closed_form_per_is_the_probability_of_any_bit_error() -> None:
    from scipy import stats

    ber = np.array([0.0, 1e-5, 1e-4, 1e-3, 3e-3])
    expected = stats.binom.sf(0, 8 * 13, ber)  # P(at least one of the 104 bits flipped)
    np.testing.assert_allclose(closed_form_per(ber, 13), expected, rtol=1e-12, atol=1e-15)
    assert float(closed_form_per(1e-3, 13)) == pytest.approx(0.0988, abs=5e-4)  # README table


def test_closed_form_age_matches_the_formula_and_a_simulated_sawtooth() -> None:
    ber, gap, lag = 3e-3, 0.6, 0.145
    q = (1.0 - ber) ** (8 * ORDER_FRAME_BYTES)
    formula = lag + gap * (2.0 - q) / (2.0 * q)
    assert float(closed_form_age_s(ber, gap, lag)) == pytest.approx(formula, rel=1e-12)
    assert float(closed_form_age_s(0.0, gap, lag)) == pytest.approx(lag + gap / 2, rel=1e-12)
    curve = closed_form_age_s(np.array([[0.0, 1e-4], [1e-3, ber]]), gap, lag)
    assert curve.shape == (2, 2) and curve[1, 1] == pytest.approx(formula, rel=1e-12)
    # second method: orders every T, each lost with 1 − q, applied `lag` after sampling
    rng = np.random.default_rng(7)
    sampled = np.arange(20_000) * gap
    kept = sampled[rng.random(sampled.size) < q]
    updates = [(s + lag, s) for s in kept]
    measured = age_of_information(updates, 10.0, float(sampled[-1]), grid_s=1.0)["mean"]
    assert measured == pytest.approx(formula, rel=0.01)


def test_error_bars_of_a_percentage_stay_within_0_and_100() -> None:
    """PER 2 % and 12 % at one BER: the t interval 7 ± 63.5 % is drawn from 0 %, not −56.5 %."""
    x, y = np.array([1e-3, 1e-3, 1e-2, 1e-2]), np.array([2.0, 12.0, 90.0, 99.0])
    free = line(x, y)
    bounded = line(x, y, (0.0, 100.0))
    assert free.low[0] < 0.0 and free.high[1] > 100.0
    assert bounded.low[0] == 0.0 and bounded.high[0] == pytest.approx(free.high[0])
    assert bounded.high[1] == 100.0 and bounded.low[1] == pytest.approx(free.low[1])
    fig = Figure()
    ax = fig.subplots()
    draw(ax, None, x, y, color="k", label=None, bounds=(0.0, 100.0))
    (bars,) = [c for c in ax.collections if len(c.get_segments())]
    ends = np.concatenate([seg[:, 1] for seg in bars.get_segments()])
    assert ends.min() == 0.0 and ends.max() == 100.0


def test_ber_zero_sits_one_decade_below_the_smallest_positive_value() -> None:
    axis = LogAxis.fit(np.array([0.0, 1e-5, 1e-3, 1e-4]))
    assert axis is not None and axis.zero_at == pytest.approx(1e-6)
    np.testing.assert_allclose(axis.place(np.array([0.0, 1e-5])), [1e-6, 1e-5])
    assert LogAxis.fit(np.array([0.6, 1.0, 1.8])) is None  # under two decades: linear
    assert LogAxis.fit(np.array([-1.0, 1.0, 1000.0])) is None


def test_frame_lengths_come_from_the_protocol_layouts() -> None:
    from testbed.protocol import encode_frame
    from testbed.report.closed_forms import REPLY_FRAME_BYTES, reply_frame_bytes

    assert ORDER_FRAME_BYTES == len(encode_frame(bytes(7))) == 13  # 2-B header + 5-B move
    assert REPLY_FRAME_BYTES == reply_frame_bytes(40) == 60  # REFERENCE §1.6
    assert reply_frame_bytes(20) == 40


# --- closed forms from the rows -------------------------------------------------------------------

IMAGE_BYTES = 598  # a coded image; with its 2-B CRC: 15 chunks of 40 B, 30 of 20 B
IMAGE_GAP_S = 0.6


def _write_image_results(path: Path, *, chunk_in_grid: bool, chunk_column: bool = True) -> Path:
    """An image sweep's results.csv: BER × chunk size (a grid column, or the value recorded
    after the metrics) × 2 seeds, every run completing images of IMAGE_BYTES."""
    grid = ["link.ber", "images.chunk_bytes"] if chunk_in_grid else ["link.ber"]
    metrics = ["ipg_s", "images.completed", "images.bytes_delivered", "images.per_minute"]
    recorded = [] if chunk_in_grid or not chunk_column else ["images.chunk_bytes"]
    point = 0
    with path.open("w", encoding="utf-8", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["point", "seed", *grid, "status", "error", *metrics, *recorded])
        for ber in BERS:
            for chunk in (20, 40) if chunk_in_grid else (20,):
                keys = [ber, chunk] if chunk_in_grid else [ber]
                for seed in range(2):
                    values = [IMAGE_GAP_S, 3, 3 * IMAGE_BYTES, 5.0 - seed]
                    extra = [chunk] if recorded else []
                    writer.writerow([point, seed, *keys, "ok", "", *values, *extra])
                point += 1
    return path


def _by_hand(ber: np.ndarray, chunk_bytes: int) -> np.ndarray:
    """60·q_o·q_r/(n·T): a 13-B order, a reply of 6 B framing + 14 B header + the chunk."""
    q_order = (1.0 - ber) ** (8 * 13)
    q_reply = (1.0 - ber) ** (8 * (6 + 14 + chunk_bytes))
    chunks = math.ceil((IMAGE_BYTES + 2) / chunk_bytes)
    return 60.0 * q_order * q_reply / (chunks * IMAGE_GAP_S)


@pytest.mark.filterwarnings("ignore:No artists with labels")  # no PER or tracking columns here
def test_a_sweep_over_chunk_bytes_draws_one_closed_form_per_chunk_size(tmp_path: Path) -> None:
    results = read_results(_write_image_results(tmp_path / "results.csv", chunk_in_grid=True))
    ber = np.array([0.0, 1e-4, 1e-3])
    models = {}
    for label, mask in results.groups(["images.chunk_bytes"]):
        model = image_rate_model(results, mask)
        assert model is not None
        models[label] = model
    assert list(models) == ["chunk_bytes=20", "chunk_bytes=40"]
    small, large = models["chunk_bytes=20"], models["chunk_bytes=40"]
    assert (small.chunk_bytes, small.chunks, small.reply_bytes) == (20, 30, 40)
    assert (large.chunk_bytes, large.chunks, large.reply_bytes) == (40, 15, 60)
    assert small.gap_s == large.gap_s == IMAGE_GAP_S and small.selective_repeat
    np.testing.assert_allclose(small.per_minute(ber), _by_hand(ber, 20), rtol=1e-12)
    np.testing.assert_allclose(large.per_minute(ber), _by_hand(ber, 40), rtol=1e-12)
    # at BER 0: 60/(30·0.6) = 3.33 images/min with 20-B chunks, 60/(15·0.6) = 6.67 with 40 B
    assert float(small.per_minute(0.0)) == pytest.approx(60.0 / 18.0, rel=1e-12)
    assert float(large.per_minute(0.0)) == pytest.approx(60.0 / 9.0, rel=1e-12)
    names = [p.name for p in plot_ber_sweep(results.path, tmp_path / "plots")]
    assert "ber_vs_images.png" in names


def test_the_chunk_size_a_run_recorded_sets_the_curve_and_old_tables_keep_40_bytes(
    tmp_path: Path,
) -> None:
    ber = np.array([1e-4, 1e-3])
    recorded = read_results(_write_image_results(tmp_path / "recorded.csv", chunk_in_grid=False))
    model = image_rate_model(recorded, np.ones(len(recorded.rows), dtype=bool))
    assert model is not None and (model.chunk_bytes, model.chunks) == (20, 30)
    np.testing.assert_allclose(model.per_minute(ber), _by_hand(ber, 20), rtol=1e-12)
    old = read_results(
        _write_image_results(tmp_path / "old.csv", chunk_in_grid=False, chunk_column=False)
    )
    model = image_rate_model(old, np.ones(len(old.rows), dtype=bool))
    assert model is not None and (model.chunk_bytes, model.chunks) == (40, 15)
    np.testing.assert_allclose(model.per_minute(ber), _by_hand(ber, 40), rtol=1e-12)


# --- files ----------------------------------------------------------------------------------------


def test_hand_made_results_give_the_three_ber_plots(tmp_path: Path) -> None:
    results = read_results(_write_results(tmp_path / "results.csv"))
    assert results.grid == ("link.ber", "link.ipg_s")
    assert len(results.rows) == len(BERS) * len(GAPS) * 3  # failed rows left out
    paths = plot_ber_sweep(results.path, tmp_path / "plots")
    names = ["ber_vs_lag.png", "ber_vs_per.png", "ber_vs_tracking.png"]
    assert [p.name for p in paths] == names
    for path in paths:
        assert path.read_bytes()[:8] == PNG_MAGIC and path.stat().st_size > 20_000


def test_plot_pair_numeric_categorical_and_hue(tmp_path: Path) -> None:
    source = _write_results(tmp_path / "results.csv")
    out = plot_pair(source, "link.ipg_s", "command_age_s.mean", "link.ber", tmp_path / "a.png")
    assert out.read_bytes()[:8] == PNG_MAGIC
    text = source.read_text(encoding="utf-8").replace(",0.6,", ",ecs-4h,")
    (tmp_path / "cat.csv").write_text(text, encoding="utf-8")
    out = plot_pair(tmp_path / "cat.csv", "link.ipg_s", "link.uplink.per", None, tmp_path / "b.png")
    assert out.read_bytes()[:8] == PNG_MAGIC
    with pytest.raises(ConfigError, match="no numeric value"):
        plot_pair(tmp_path / "cat.csv", "link.ber", "error", None, tmp_path / "c.png")


def test_cli_plot_writes_next_to_the_results(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    source = _write_results(tmp_path / "results.csv")
    argv = ["plot", str(source), "--x", "link.ber", "--y", "command_lag_s.mean"]
    assert main([*argv, "--hue", "link.ipg_s"]) == 0
    written = tmp_path / "command_lag_s.mean_vs_link.ber.png"
    assert capsys.readouterr().out.strip() == str(written) and written.is_file()


def test_cli_plot_into_an_existing_directory_writes_y_vs_x_there(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    source = _write_results(tmp_path / "results.csv")
    plots = tmp_path / "plots"
    plots.mkdir()
    argv = ["plot", str(source), "--x", "link.ber", "--y", "command_lag_s.mean"]
    assert main([*argv, "--out", str(plots)]) == 0
    written = plots / "command_lag_s.mean_vs_link.ber.png"
    assert capsys.readouterr().out.strip() == str(written)
    assert written.read_bytes()[:8] == PNG_MAGIC
    assert not (tmp_path / "plots.png").exists()  # not next to the directory


@pytest.mark.parametrize(
    ("option", "column"), [("--x", "link.bre"), ("--y", "command_lag"), ("--hue", "ipg")]
)
def test_cli_plot_unknown_column_exits_2_with_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], option: str, column: str
) -> None:
    source = _write_results(tmp_path / "results.csv")
    args = {"--x": "link.ber", "--y": "command_age_s.mean", "--hue": "link.ipg_s"} | {
        option: column
    }
    assert main(["plot", str(source), *(v for kv in args.items() for v in kv)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert f"{option}: unknown column {column!r}" in err and "command_age_s.mean" in err
    assert not list(tmp_path.glob("*.png"))


def test_missing_or_foreign_file_is_a_config_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read"):
        read_results(tmp_path / "none.csv")
    (tmp_path / "other.csv").write_text("a,b\n1,2\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=r"not a results\.csv"):
        read_results(tmp_path / "other.csv")
    with pytest.raises(ConfigError, match="no BER grid key"):
        source = _write_results(tmp_path / "results.csv")
        text = source.read_text(encoding="utf-8").replace("link.ber", "link.bitrate_bps", 1)
        source.write_text(text, encoding="utf-8")
        plot_ber_sweep(source, tmp_path)


def _replace_row(source: Path, index: int, edit: Callable[[list[str]], list[str]]) -> None:
    """Rewrite data row ``index`` (0 = the first after the head) of ``source`` with ``edit``."""
    with source.open(encoding="utf-8", newline="") as handle:
        rows = list(csv.reader(handle))
    rows[1 + index] = edit(rows[1 + index])
    with source.open("w", encoding="utf-8", newline="") as handle:
        csv.writer(handle).writerows(rows)


@pytest.mark.parametrize(
    ("index", "edit", "message"),
    [  # row 2 of the file is the first data row; the head has 17 columns
        (1, lambda row: row[:10], "row 3: expected 17 fields, got 10"),
        (3, lambda row: row[:6], "row 5: expected 17 fields, got 6"),  # a failed run's row
        (0, lambda row: [*row, "9"], "row 2: expected 17 fields, got 18"),
    ],
)
def test_cli_plot_of_a_ragged_results_file_exits_2_naming_the_row(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    index: int,
    edit: Callable[[list[str]], list[str]],
    message: str,
) -> None:
    source = _write_results(tmp_path / "ragged.csv")
    _replace_row(source, index, edit)
    argv = ["plot", str(source), "--x", "link.ber", "--y", "command_lag_s.mean"]
    assert main([*argv, "--out", str(tmp_path / "p.png")]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1
    assert err == f"testbed: error: {source}: {message}" + (
        " (more cells than the head)\n" if "18" in message else "\n"
    )
    assert not (tmp_path / "p.png").exists()


def test_cli_plot_of_a_non_numeric_metric_cell_exits_2_naming_row_and_column(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    source = _write_results(tmp_path / "results.csv")
    lag = 11  # command_lag_s.mean
    _replace_row(source, 1, lambda row: [*row[:lag], "abc", *row[lag + 1 :]])
    argv = ["plot", str(source), "--x", "link.ber", "--y", "command_lag_s.mean"]
    assert main([*argv, "--out", str(tmp_path / "p.png")]) == 2
    err = capsys.readouterr().err
    assert err == (
        f"testbed: error: {source}: row 3: --y: column 'command_lag_s.mean' holds 'abc', "
        "not a number\n"
    )
    # an empty metric cell (a run without that value) and a non-numeric x (categorical) are fine
    _replace_row(source, 1, lambda row: [*row[:lag], "", *row[lag + 1 :]])
    _replace_row(source, 2, lambda row: [*row[:2], "ecs-4h", *row[3:]])
    assert main([*argv, "--out", str(tmp_path / "p.png")]) == 0
    assert (tmp_path / "p.png").read_bytes()[:8] == PNG_MAGIC


# --- end to end -----------------------------------------------------------------------------------


@pytest.fixture
def inline_runs(monkeypatch: pytest.MonkeyPatch) -> None:
    """The sweeps' runs execute in this process (``execute_run``, the backends' worker function,
    unchanged), not in a process pool that would import the testbed again first (≈ 1.5 s): the
    tests here are about what the sweep writes and plots, whoever ran the runs."""
    from testbed.sweep import execute_run

    monkeypatch.setattr(
        "testbed.sweep.runner.outcomes", lambda specs, *_: (execute_run(s) for s in specs)
    )


def test_a_tiny_real_ber_sweep_is_plotted_at_the_end(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], inline_runs: None
) -> None:
    path = tmp_path / "tiny.toml"
    path.write_text(
        'schema = 1\nid = "tiny-v1"\ndescription = "3 BER"\nscenario = "s100-teleop-v1"\n'
        'seeds = 1\n[grid]\n"link.ber" = [0.0, 1e-4, 1e-3]\n',
        encoding="utf-8",
    )
    out = tmp_path / "out"
    short = ["--set", "duration_s=8", "--set", "metrics.settle_s=1"]
    assert main(["sweep", str(path), *short, "--out", str(out)]) == 0
    assert "ber_vs_lag.png" in capsys.readouterr().out
    for name in ("ber_vs_lag.png", "ber_vs_per.png", "ber_vs_tracking.png"):
        assert (out / name).read_bytes()[:8] == PNG_MAGIC
    results = read_results(out / "results.csv")
    lag = results.numbers("command_lag_s.mean")
    assert len(results.rows) == 3 and np.isfinite(lag).all()
    gap = results.numbers("ipg_s")
    age_at_zero = float(results.numbers("command_age_s.mean")[0])
    # with no loss the age is D + T/2 (8 s runs: within a tenth of a gap)
    assert age_at_zero == pytest.approx(lag[0] + gap[0] / 2, abs=0.1 * gap[0])
    assert not math.isnan(gap[0])


def _simulated_images_per_minute(
    ber: float, gap_s: float, chunks: int, selective_repeat: bool, cycles: int, seed: int
) -> float:
    """The transfer state machines themselves over Bernoulli frame losses (a second method)."""
    from testbed.protocol import AssemblyEvent, ImageAssembler, ImageSender

    rng = np.random.default_rng(seed)
    q_order = (1.0 - ber) ** (8 * 13)
    q_reply = (1.0 - ber) ** (8 * 60)
    sender = ImageSender(40, selective_repeat=selective_repeat)
    assembler = ImageAssembler(40, selective_repeat=selective_repeat)
    image = bytes(range(256)) * 3
    image = image[: chunks * 40 - 2]
    completed = 0
    for _ in range(cycles):
        request = assembler.request()
        if rng.random() >= q_order:
            continue  # order lost: no reply
        sender.on_request(*request)
        if sender.wants_image:
            sender.load(image)
        chunk = sender.next_chunk()
        if chunk is None or rng.random() >= q_reply:
            continue
        event = assembler.on_chunk(
            chunk.first, chunk.last, chunk.image_seq_bit, chunk.cancel, chunk.index, chunk.data
        )
        completed += event is AssemblyEvent.COMPLETED
    return 60.0 * completed / (cycles * gap_s)


@pytest.mark.parametrize("selective_repeat", [True, False])
@pytest.mark.parametrize("ber", [0.0, 2e-4, 6e-4])
def test_images_per_minute_closed_form_matches_the_state_machines(
    ber: float, selective_repeat: bool
) -> None:
    gap_s, chunks, cycles = 0.6, 8, 40_000
    expected = float(
        closed_form_images_per_minute(ber, gap_s, chunks, selective_repeat=selective_repeat)
    )
    simulated = _simulated_images_per_minute(ber, gap_s, chunks, selective_repeat, cycles, 5)
    # images are a renewal count: ≈ Poisson-like spread; 4σ of the count, plus one image
    count = expected * cycles * gap_s / 60.0
    tolerance = (4.0 * math.sqrt(max(count, 1.0)) + 1.0) * 60.0 / (cycles * gap_s)
    assert simulated == pytest.approx(expected, abs=tolerance)


@pytest.mark.filterwarnings("ignore:No artists with labels")  # no PER or tracking columns here
def test_a_supervised_sweep_also_gets_the_mission_plot(tmp_path: Path) -> None:
    path = tmp_path / "results.csv"
    metrics = ["mission.completion_s", "mission.position_error_m.final"]
    with path.open("w", encoding="utf-8", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["point", "seed", "link.ber", "status", "error", *metrics])
        for point, ber in enumerate(BERS):
            for seed in range(2):
                writer.writerow([point, seed, ber, "ok", "", 84.0 + 1e3 * ber + seed, 0.006])
    paths = plot_ber_sweep(path, tmp_path / "plots")
    assert paths[-1].name == "ber_vs_mission.png"
    assert paths[-1].read_bytes()[:8] == PNG_MAGIC and paths[-1].stat().st_size > 20_000


def test_error_bars_of_non_negative_metrics_stop_at_zero(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Seeds far apart at one BER (age 0.01 and 2.0 s): the free t interval of the mean
    reaches below 0; every bar of every BER plot (lag, age, tracking RMSE) stops at 0."""
    import testbed.report.sweep_plots as sweep_plots

    text = _write_results(tmp_path / "results.csv").read_text(encoding="utf-8")
    rows = text.splitlines()
    wild = []
    for row in rows[1:]:
        cells = row.split(",")
        if cells[4] == "ok":  # age and z RMSE: 0.01 for seed 0, 2.0 for the others
            big = cells[1] != "0"
            cells[12] = "2.0" if big else "0.01"  # command_age_s.mean
            cells[15] = "2.0" if big else "0.001"  # velocity_tracking_rmse.z
        wild.append(",".join(cells))
    (tmp_path / "results.csv").write_text("\n".join([rows[0], *wild]) + "\n", encoding="utf-8")
    assert line(np.array([0.0] * 3), np.array([0.01, 2.0, 2.0])).low[0] < 0.0
    drawn: list[object] = []
    real_draw = sweep_plots.draw

    def spy(ax: object, *args: object, **kwargs: object) -> None:
        drawn.append(ax)
        real_draw(ax, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(sweep_plots, "draw", spy)
    monkeypatch.setattr(
        sweep_plots, "draw_non_negative", functools.partial(spy, bounds=(0.0, math.inf))
    )
    # the bars are the axes' collections once drawn: rendering the PNGs (≈ 1 s) is not the
    # subject (the other tests here render them)
    monkeypatch.setattr(sweep_plots, "save", lambda fig, path: path)
    plot_ber_sweep(tmp_path / "results.csv", tmp_path / "plots")
    ends = [
        seg[:, 1]
        for ax in drawn
        for collection in ax.collections  # type: ignore[attr-defined]
        for seg in collection.get_segments()
    ]
    assert ends and min(float(e.min()) for e in ends) == 0.0


def test_titles_name_the_sweep_id_so_equal_results_give_equal_pngs(tmp_path: Path) -> None:
    """The same results.csv in folders of different names, each beside a sweep.json of the
    same id: byte-identical PNGs."""
    outputs = []
    for folder in ("first", "second-name"):
        (tmp_path / folder).mkdir()
        source = _write_results(tmp_path / folder / "results.csv")
        (tmp_path / folder / "sweep.json").write_text('{"id": "ber-small-v1"}\n')
        outputs.append([p.read_bytes() for p in plot_ber_sweep(source, tmp_path / folder)])
    assert outputs[0] == outputs[1]


def test_no_plot_and_no_warning_when_every_run_failed(tmp_path: Path) -> None:
    import warnings

    path = tmp_path / "results.csv"
    path.write_text(
        "point,seed,link.ber,status,error,link.uplink.per\n"
        "0,0,0.0,failed,boom,\n1,0,0.001,failed,boom,\n",
        encoding="utf-8",
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert plot_ber_sweep(path, tmp_path / "plots") == []
    assert not list((tmp_path / "plots").glob("*.png"))


def test_a_sweep_without_tracking_gets_no_empty_tracking_plot(tmp_path: Path) -> None:
    """Supervised control has no stick tracking (every cell empty): no ber_vs_tracking.png."""
    path = tmp_path / "results.csv"
    path.write_text(
        "point,seed,link.ber,status,error,command_lag_s.mean,velocity_tracking_rmse.x\n"
        "0,0,0.0,ok,,0.1,\n0,1,0.0,ok,,0.2,\n1,0,0.001,ok,,0.1,\n",
        encoding="utf-8",
    )
    names = [p.name for p in plot_ber_sweep(path, tmp_path / "plots")]
    assert names == ["ber_vs_lag.png"]


def test_a_title_names_the_failed_runs_and_where_they_failed(tmp_path: Path) -> None:
    """Failed runs have no metrics to draw; the curves ended at the last good BER while the
    title said only "(4 runs ok)". It now says how many failed, and at which grid values."""
    from testbed.report.sweep_results import read_results

    path = tmp_path / "results.csv"
    rows = [
        ["point", "seed", "link.ber", "link.ipg_s", "status", "error", "energy_wh"],
        *[
            [p, s, ber, "0.6", "ok", "", "0.1"]
            for p, ber in ((0, "0.0"), (1, "0.0001"))
            for s in (0, 1)
        ],
        *[[2, s, "0.001", "0.6", "failed", "ValueError: x", ""] for s in (0, 1)],
    ]
    with path.open("w", newline="") as handle:
        csv.writer(handle).writerows(rows)
    results = read_results(path)
    assert len(results.rows) == 4 and len(results.failed) == 2
    assert results.runs_label() == "4 runs ok, 2 failed at link.ber 0.001"
    # and every panel marks where: a red × at the foot of the axis at BER 0.001
    from matplotlib.figure import Figure

    from testbed.report.sweep_plots import _title

    fig = Figure()
    panels = fig.subplots(1, 2)
    _title(fig, results, "BER vs something")
    assert fig.get_suptitle().endswith("(4 runs ok, 2 failed at link.ber 0.001) (×: a failed run)")
    for ax in panels:
        (marks,) = [line for line in ax.lines if line.get_marker() == "x"]
        assert list(marks.get_xdata()) == [0.001] and list(marks.get_ydata()) == [0.0]


def test_no_closed_form_where_replies_outlast_the_gap_and_the_sweep_warns(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    inline_runs: None,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """At S100's 0.594-s gap a reply of 20 + 68 B no longer fits (the run's closed form,
    tests/run/test_images.py): the images-per-minute closed form, which assumes each reply is
    in before the next order, is not drawn for that line (an images researcher's review: it
    was, at 6.7/min over runs making 2/min), and the sweep says which grid values."""
    import testbed.report.sweep_plots as sweep_plots

    # only the images plot (a line without a model is drawn) is this test's; the lag, PER and
    # tracking plots (≈ 1.5 s) are drawn by the other sweeps here
    for other in ("_plot_lag", "_plot_per", "_plot_tracking"):
        monkeypatch.setattr(sweep_plots, other, lambda results, path, *rest: path)
    path = tmp_path / "late.toml"
    path.write_text(
        'schema = 1\nid = "late-v1"\ndescription = "chunks"\nscenario = "s100-video-v1"\n'
        'seeds = 1\n[grid]\n"link.ber" = [0.0, 1e-4]\n"images.chunk_bytes" = [40, 68]\n',
        encoding="utf-8",
    )
    out = tmp_path / "out"
    short = ["--set", "duration_s=20", "--set", "images.changes=[]"]
    assert main(["sweep", str(path), *short, "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert (
        "  warning: in 2 of 4 runs a reply does not fit the token gap (reply_fits_gap false: "
        "images.chunk_bytes 68): the next order leaves before the reply is in\n"
    ) in said
    results = read_results(out / "results.csv")
    models = {
        label: image_rate_model(results, mask)
        for label, mask in results.groups(["images.chunk_bytes"])
    }
    assert models["chunk_bytes=40"] is not None and models["chunk_bytes=68"] is None
    assert (out / "ber_vs_images.png").read_bytes()[:8] == PNG_MAGIC
