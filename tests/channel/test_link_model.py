"""A link model of the user's own (testbed.channel.model): the medium asks it for each
transmission's air time and each receiver's bit errors, against closed forms and a second
method (the preset's own keys)."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from testbed.channel import EventKind, LinkModel, StandardLink, Trace
from testbed.channel.config import load_link_config
from testbed.channel.probe import run_probe
from testbed.cli.main import main
from testbed.protocol import encode_frame
from testbed.run import load_scenario, run_scenario

S100 = load_link_config("s100", ["ber=0"])


@dataclasses.dataclass(frozen=True)
class StepRate:
    """A bit rate that steps from ``before_bps`` to ``after_bps`` at ``at_s``; no errors."""

    before_bps: float
    after_bps: float
    at_s: float

    def airtime_s(self, size_bytes: int, t_s: float) -> float:
        return size_bytes * (8.0 / (self.before_bps if t_s < self.at_s else self.after_bps))

    def error_model(self, rng: np.random.Generator) -> EveryNth:
        return EveryNth(0)


class EveryNth:
    """Flips one bit of every ``n``-th copy a receiver gets (0: none), drawing nothing."""

    def __init__(self, n: int) -> None:
        self.n, self.copies = n, 0

    def corrupt(self, data: bytes, p_independent: float, t_s: float) -> tuple[bytes, int]:
        self.copies += 1
        if self.n and self.copies % self.n == 0:
            return bytes([data[0] ^ 0x80]) + data[1:], 1
        return data, 0


@dataclasses.dataclass(frozen=True)
class EveryThirdLost:
    config: object

    def airtime_s(self, size_bytes: int, t_s: float) -> float:
        return StandardLink(S100).airtime_s(size_bytes, t_s)

    def error_model(self, rng: np.random.Generator) -> EveryNth:
        return EveryNth(3)


def test_a_rate_that_changes_over_time_gives_each_frame_its_closed_form_latency() -> None:
    n, size = 100, 60  # one frame a second; the rate halves from t = 49.5 s
    model: LinkModel = StepRate(1900.0, 950.0, 49.5)
    r = run_probe(S100, frames=n, frame_bytes=size, link_model=model)
    fast, slow = (S100.intrinsic_delay_s + 8 * size / bps for bps in (1900.0, 950.0))
    assert r.frames_delivered == n and r.per == 0.0
    assert r.latency_s.mean == pytest.approx((50 * fast + 50 * slow) / n, abs=1e-9)
    assert r.latency_s.max == pytest.approx(slow, abs=1e-9)
    assert r.link_model.endswith("test_link_model.StepRate")
    assert r.to_json_dict()["link_model"] == r.link_model
    assert run_probe(S100, frames=3).to_json_dict()["link_model"] is None  # the preset's


def test_a_receivers_error_model_decides_which_copies_arrive_corrupted() -> None:
    r = run_probe(S100, frames=300, frame_bytes=40, link_model=EveryThirdLost(S100))
    assert (r.frames_corrupted, r.frames_delivered) == (100, 200)  # the decoder caught each
    assert r.per == pytest.approx(1 / 3)


def order_crossings(trace: Trace) -> list[tuple[float, float, int]]:
    """``(sent at, time to cross, frame bytes)`` of each operator frame the vehicle received
    [s, s, B], from a run's link trace."""
    sent: dict[int, tuple[float, int]] = {}
    crossed = []
    for event in trace.events:
        if event.kind is EventKind.TX_START and event.src == "operator":
            sent[event.frame_id] = (event.t_s, event.size_bytes)
        elif event.kind is EventKind.DELIVER and event.dst == "vehicle":
            t_s, size = sent[event.frame_id]
            crossed.append((t_s, event.t_s - t_s, size))
    return crossed


def test_a_users_constant_rate_model_flies_as_the_presets_key_bit_for_bit() -> None:
    """The second method: a run whose model says 1400 bit/s is the run of the same scenario
    with link.bitrate_bps = 1400, byte for byte; each 13-B order crosses in the intrinsic delay
    plus 8·13/1400 s (19.55 ms more than at 1900 bit/s), and the model is recorded."""
    short = ["duration_s=30", "trials=1"]
    preset = run_scenario(load_scenario("s100-teleop-v1", short))
    keyed = run_scenario(load_scenario("s100-teleop-v1", [*short, "link.bitrate_bps=1400"]))
    modelled = run_scenario(
        load_scenario("s100-teleop-v1", short), link_model=StepRate(1400.0, 1400.0, 0.0)
    )
    for column, values in keyed.recorder.series().items():
        np.testing.assert_array_equal(values, modelled.recorder.series()[column], column)
    crossed = [took for _, took, _ in order_crossings(modelled.recorder.trace)]
    assert len(encode_frame(b"\0" * 7)) == 13  # an order's size on the wire
    expected = S100.intrinsic_delay_s + 8 * 13 / 1400
    # plus the radio's propagation over the few metres between the nodes (≈ 3 ns a metre)
    assert len(crossed) > 40 and crossed == pytest.approx([expected] * len(crossed), abs=1e-7)
    assert modelled.metrics["inputs"]["link_model"].endswith("test_link_model.StepRate")
    assert "link_model" not in preset.metrics["inputs"]


def test_testbed_link_probes_a_link_model_of_ones_own(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``testbed link --model FILE.py:NAME --model-args TOML``: a constant 950 bit/s model gives
    what ``--set bitrate_bps=950`` gives (the second method), the JSON names the model as the
    user did; bad arguments are one line, exit 2 (a link researcher's review: the probe took no
    model)."""
    (tmp_path / "rates.py").write_text(
        "from testbed.channel import StandardLink\n"
        "import dataclasses\n\n"
        "def constant(config, bitrate_bps):\n"
        "    return StandardLink(dataclasses.replace(config, bitrate_bps=bitrate_bps))\n",
        encoding="utf-8",
    )
    target = f"{tmp_path / 'rates.py'}:constant"
    common = ["link", "--frames", "50", "--seed", "3", "--set", "ber=1e-3", "--json"]
    assert main([*common, "--model", target, "--model-args", "{bitrate_bps = 950.0}"]) == 0
    modelled = json.loads(capsys.readouterr().out)
    assert main([*common, "--set", "bitrate_bps=950"]) == 0
    keyed = json.loads(capsys.readouterr().out)
    assert modelled.pop("link_model") == target and keyed.pop("link_model") is None
    for timing in ("wall_s", "rtf"):
        modelled.pop(timing), keyed.pop(timing)
    assert modelled == keyed
    assert modelled["latency_s"]["p50"] == pytest.approx(S100.intrinsic_delay_s + 8 * 60 / 950)
    for bad, says in (
        (["--model-args", "{bitrate_bps = 950.0}"], "--model-args: only used with --model"),
        (["--model", target, "--model-args", "[1]"], "--model-args: expected a TOML inline"),
        (["--model", target, "--model-args", "{bitrate_bps = -1.0}"], "(called with --model-args"),
    ):
        assert main([*common, *bad]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and says in err, err


class Asymmetric:
    """An uplink (the operator's) at 1900 bit/s and a downlink at 950; errors only on copies
    that crossed more than ``cut_m`` (every bit flipped there), and a record of the context."""

    def __init__(self, cut_m: float) -> None:
        self.cut_m = cut_m
        self.receivers: list[str] = []
        self.copies: list[tuple[str, float]] = []

    def airtime_s(self, size_bytes: int, t_s: float, sender: str) -> float:
        return 8.0 * size_bytes / (1900.0 if sender == "operator" else 950.0)

    def error_model(self, rng: np.random.Generator, receiver: str) -> Asymmetric:
        self.receivers.append(receiver)
        return self

    def corrupt(
        self, data: bytes, p_independent: float, t_s: float, **context: float | str
    ) -> tuple[bytes, int]:
        sender, distance_m = str(context["sender"]), float(context["distance_m"])
        self.copies.append((sender, distance_m))
        if distance_m <= self.cut_m:
            return data, 0
        return bytes(b ^ 0xFF for b in data), 8 * len(data)


def test_a_link_model_may_ask_for_the_sender_the_receiver_and_the_distance() -> None:
    """Laws that name ``sender``, ``receiver`` and ``distance_m`` are given them (a link
    researcher's review: an asymmetric link and BER(d) could not be written): each order
    crosses in the intrinsic delay + 8·13/1900 s and each reply in + 8·20/950 s; every copy's
    distance is the nodes' (the vehicle starts 0.5 m from the operator and the scripted pilot
    moves it); beyond the cut every copy is lost."""
    short = ["duration_s=30", "link.ber=0"]
    model = Asymmetric(cut_m=1e9)
    result = run_scenario(load_scenario("s100-teleop-v1", short), link_model=model)
    assert sorted(model.receivers) == ["operator", "vehicle"]
    trace = result.recorder.trace
    start = {e.frame_id: (e.t_s, e.src) for e in trace.of_kind(EventKind.TX_START)}
    crossed = [
        (start[e.frame_id][1], e.t_s - start[e.frame_id][0])
        for e in trace.of_kind(EventKind.DELIVER)
    ]
    intrinsic = S100.intrinsic_delay_s
    for sender, took in crossed:
        size, bps = (13, 1900.0) if sender == "operator" else (20, 950.0)
        assert took == pytest.approx(intrinsic + 8.0 * size / bps, abs=1e-6), sender
    assert {s for s, _ in crossed} == {"operator", "vehicle"}
    distances = [d for _, d in model.copies]
    assert min(distances) == pytest.approx(0.5, abs=0.05) and max(distances) < 20.0
    lost = Asymmetric(cut_m=0.0)
    cut = run_scenario(load_scenario("s100-teleop-v1", short), link_model=lost)
    assert cut.metrics["link"]["uplink"]["frames_delivered"] == 0
