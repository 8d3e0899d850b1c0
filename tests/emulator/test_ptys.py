"""``testbed.emulator.ptys``: two PTYs joined in real time by the channel model,
opened with pyserial.

Truth is the channel model's closed form: unloaded latency = intrinsic delay + 8·L / bitrate
(+ propagation, ~0 here). Measured latency must be at least that, and at most that plus the
burst idle gap and the scheduler lateness measured in the same test (the emulator's threads and
a wake probe in this process, ``lateness`` in conftest.py), so the bounds hold on a loaded
machine without a fixed allowance. Reads are bounded by the serial timeout; there is no sleep.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import pytest
import serial

from testbed.channel import LinkConfig, load_link_config
from testbed.cli.main import main
from testbed.emulator.ptys import ModemEmulator
from testbed.protocol import Frame, FrameDecoder, encode_frame

FAST = ["bitrate_bps=19200", "intrinsic_delay_s=0.02", "ber=0"]
"""s100 made fast enough for a test: 10× the bitrate, 20 ms intrinsic delay, no bit errors."""
IDLE_S = 0.003
TIMEOUT_S = 2.0


@pytest.fixture
def fast() -> LinkConfig:
    return load_link_config("s100", FAST)


@pytest.fixture
def ports(fast: LinkConfig) -> Iterator[tuple[ModemEmulator, serial.Serial, serial.Serial]]:
    with ModemEmulator(fast, seed=1, idle_s=IDLE_S) as emulator:
        path_a, path_b = emulator.paths
        with (
            serial.Serial(path_a, timeout=TIMEOUT_S) as port_a,
            serial.Serial(path_b, timeout=TIMEOUT_S) as port_b,
        ):
            yield emulator, port_a, port_b


def send_and_time(src: serial.Serial, dst: serial.Serial, data: bytes) -> tuple[bytes, float]:
    """Write ``data`` on ``src`` and read as many bytes on ``dst``: (bytes read, seconds)."""
    t0 = time.monotonic()
    src.write(data)
    got = dst.read(len(data))
    return got, time.monotonic() - t0


def test_frame_crosses_both_ways_after_the_model_latency(
    fast: LinkConfig,
    ports: tuple[ModemEmulator, serial.Serial, serial.Serial],
    lateness: Any,
) -> None:
    """A → B, B → A, A → B, each sent three times: every crossing arrives intact and no sooner
    than the model says; the quickest of each three is within the host's measured allowance
    (the quickest, not each: beside busy loops one thread wake on the way can be held up
    longer than the wake probe saw, as in the FIFO test below; a delay the emulator itself
    added would be in every send)."""
    emulator, port_a, port_b = ports
    sends = 3
    for k, (src, dst) in enumerate([(port_a, port_b), (port_b, port_a), (port_a, port_b)]):
        frame = encode_frame(bytes([k]) * 40)
        crossings = [send_and_time(src, dst, frame) for _ in range(sends)]
        assert [got for got, _ in crossings] == [frame] * sends
        assert FrameDecoder().feed(crossings[0][0]) == [Frame(bytes([k]) * 40)]
        model_s = fast.intrinsic_delay_s + fast.airtime_s(len(frame))  # 20 + 19.2 ms
        latencies_s = [latency_s for _, latency_s in crossings]
        allowance_s = lateness.allowance_s(emulator)
        assert min(latencies_s) >= model_s
        assert min(latencies_s) <= model_s + allowance_s, (latencies_s, model_s, allowance_s)
    emulator.close()  # joins its threads: a delivery can be read before its bytes are counted
    counters_a, counters_b = emulator.counters
    assert (counters_a.bursts, counters_b.bursts) == (2 * sends, sends)
    assert (counters_a.deliveries, counters_b.deliveries) == (sends, 2 * sends)
    assert counters_b.bytes_out == counters_a.bytes_in == 2 * sends * len(frame)
    assert counters_a.bytes_overflowed == counters_b.bytes_overflowed == 0
    assert emulator.modems[1].counters.rx_bit_errors == 0
    assert emulator.error is None


def test_model_latency_scales_with_bitrate_not_with_the_emulator(
    fast: LinkConfig, lateness: Any
) -> None:
    """Halving the bitrate adds exactly one more airtime: the delay comes from the model. Each
    latency is the model plus what the host added (0 to its measured allowance), so their
    difference is the extra airtime within the larger of the two allowances. Each is the
    quickest of three sends (every send at least the model; see the test above)."""
    slow = load_link_config("s100", [*FAST, "bitrate_bps=9600"])
    frame = encode_frame(bytes(100))  # 106 B: 44 ms at 19.2 kbit/s, 88 ms at 9.6 kbit/s
    latencies, allowances = [], []
    for config in (fast, slow):
        with ModemEmulator(config, seed=0, idle_s=IDLE_S) as emulator:
            path_a, path_b = emulator.paths
            with serial.Serial(path_a, timeout=TIMEOUT_S) as a, serial.Serial(path_b) as b:
                b.timeout = TIMEOUT_S
                crossings = [send_and_time(a, b, frame) for _ in range(3)]
            allowance_s = lateness.allowance_s(emulator)
        assert [got for got, _ in crossings] == [frame] * 3
        model_s = config.intrinsic_delay_s + config.airtime_s(len(frame))
        latency_s = min(latency for _, latency in crossings)
        assert model_s <= latency_s <= model_s + allowance_s
        latencies.append(latency_s)
        allowances.append(allowance_s)
    extra_s = fast.airtime_s(len(frame))  # the slower link's airtime is twice the faster one's
    assert latencies[1] - latencies[0] == pytest.approx(extra_s, abs=max(allowances))


def test_bit_errors_reach_the_port_and_the_decoder_rejects_them() -> None:
    config = load_link_config("s100", [*FAST, "ber=0.05"])
    frame = encode_frame(bytes(range(60)))
    with ModemEmulator(config, seed=3, idle_s=IDLE_S) as emulator:
        path_a, path_b = emulator.paths
        with serial.Serial(path_a) as a, serial.Serial(path_b, timeout=TIMEOUT_S) as b:
            got, _ = send_and_time(a, b, frame)
        flipped = sum(bin(x ^ y).count("1") for x, y in zip(got, frame, strict=True))
        assert flipped == emulator.modems[1].counters.rx_bit_errors > 0  # 528 bits at 5 %
    assert Frame(bytes(range(60))) not in FrameDecoder().feed(got)


def test_a_burst_larger_than_the_fifo_is_split_and_still_arrives(lateness: Any) -> None:
    """Each of three sends is split and arrives no sooner than the model says; the quickest is
    within the host's measured allowance of it. (The quickest, not each: a 2-packet frame
    crosses about ten thread wakes and two kernel PTY hand-offs, and beside two busy loops one
    of them was once held up longer than the wake probe, which samples every 1 ms, had seen:
    120 ms against a 59-ms model and a 53-ms allowance. A delay the emulator itself added
    would be in every send.)"""
    config = load_link_config("s100", [*FAST, "tx_buffer_bytes=30"])
    frame = encode_frame(bytes(range(40)))  # 46 B → bursts of 30 and 16 B
    sends = 3
    with ModemEmulator(config, seed=0, idle_s=IDLE_S) as emulator:
        path_a, path_b = emulator.paths
        with serial.Serial(path_a) as a, serial.Serial(path_b, timeout=TIMEOUT_S) as b:
            crossings = [send_and_time(a, b, frame) for _ in range(sends)]
        allowance_s = lateness.allowance_s(emulator, packets=2)
        assert [got for got, _ in crossings] == [frame] * sends
        assert emulator.counters[0].bursts == 2 * sends
        assert emulator.modems[0].counters.tx_transmissions == 2 * sends
    # The second part waits for the first: two intrinsic delays, both airtimes, one queue gap.
    model_s = 2 * config.intrinsic_delay_s + config.airtime_s(len(frame)) + config.queue_gap_s
    latencies_s = [latency_s for _, latency_s in crossings]
    assert min(latencies_s) >= model_s
    assert min(latencies_s) <= model_s + allowance_s, (latencies_s, model_s, allowance_s)


def test_close_joins_threads_and_is_final(fast: LinkConfig) -> None:
    emulator = ModemEmulator(fast, seed=0)
    emulator.start()
    with pytest.raises(RuntimeError):
        emulator.start()
    threads = list(emulator._threads)
    assert all(t.is_alive() for t in threads)
    emulator.close()
    emulator.close()
    assert not any(t.is_alive() for t in threads)
    with pytest.raises(RuntimeError):
        emulator.start()


@pytest.mark.parametrize(
    "kwargs",
    [{"time_factor": 0.0}, {"idle_s": 0.0}, {"poll_s": -1.0}, {"distance_m": -1.0}],
)
def test_bad_arguments_raise(fast: LinkConfig, kwargs: dict[str, float]) -> None:
    with pytest.raises(ValueError):
        ModemEmulator(fast, seed=0, **kwargs)  # type: ignore[arg-type]  # float for every key


def test_cli_prints_both_paths(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["modem-emulator", "--set", "ber=0", "--duration", "0"]) == 0
    out, err = capsys.readouterr()
    lines = out.splitlines()
    assert [line.split()[0] for line in lines] == ["A", "B"]
    assert all(line.split()[1].startswith("/dev/") for line in lines)
    assert "s100" in err


@pytest.mark.parametrize(
    "args",
    [
        ["--preset", "nope"],
        ["--set", "bitrate_bps=-1"],
        ["--set", "no_such_key=1"],
        ["--time-factor", "0"],
        ["--duration", "-1"],
    ],
)
def test_cli_bad_input_is_one_line_exit_2(
    capsys: pytest.CaptureFixture[str], args: list[str]
) -> None:
    assert main(["modem-emulator", *args]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("duration", ["1e11", "1e300", "inf", "nan"])  # 1e11, 1e300: OverflowError
def test_cli_duration_is_at_most_a_day_as_in_testbed_run(
    capsys: pytest.CaptureFixture[str], duration: str
) -> None:
    assert main(["modem-emulator", "--duration", duration]) == 2
    err = capsys.readouterr().err
    assert err.startswith("testbed: error: --duration: must be in [0, 86400] s, got ")
    assert err.count("\n") == 1
