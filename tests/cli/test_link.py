"""``testbed link``: the one-way probe command, its JSON and its one-line usage errors."""

from __future__ import annotations

import json

import pytest

from testbed.cli.main import main

KEYS = {
    "frames_sent",
    "frames_delivered",
    "frames_corrupted",
    "frames_collided",
    "frames_dropped",
    "per",
    "goodput_bps",
    "latency_s",
    "sim_s",
    "wall_s",
    "rtf",
}


def run_json(capsys: pytest.CaptureFixture[str], *args: str) -> dict[str, object]:
    assert main(["link", *args, "--json"]) == 0
    out, err = capsys.readouterr()
    assert err == ""
    result: dict[str, object] = json.loads(out)
    return result


def test_json_happy_path(capsys: pytest.CaptureFixture[str]) -> None:
    result = run_json(capsys, "--frames", "300", "--size", "60", "--set", "ber=0")
    assert set(result) >= KEYS
    assert result["frames_sent"] == result["frames_delivered"] == 300
    assert result["per"] == 0.0
    latency = result["latency_s"]
    assert isinstance(latency, dict) and set(latency) == {"mean", "p50", "p95", "max"}
    # s100: 85.28 ms + 60 B at 1.9 kbps = 337.9 ms (REFERENCE §1.8).
    assert latency["mean"] == pytest.approx(0.3379, abs=1e-4)
    assert isinstance(result["rtf"], float) and result["rtf"] > 0


def test_defaults_are_s100_seed_0_1000_frames(capsys: pytest.CaptureFixture[str]) -> None:
    result = run_json(capsys)
    assert result["link"] == "s100" and result["seed"] == 0
    assert result["frames_sent"] == 1000 and result["frame_bytes"] == 60
    assert 0 < result["frames_corrupted"] < 20  # type: ignore[operator]  # PER 0.34 % (§1.8)


def test_same_seed_same_output(capsys: pytest.CaptureFixture[str]) -> None:
    args = ("--frames", "400", "--set", "ber=1e-3", "--seed", "5", "--preset", "s100")
    first, second = run_json(capsys, *args), run_json(capsys, *args)
    for result in (first, second):
        del result["wall_s"], result["rtf"]
    assert first == second


def test_text_output(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["link", "--preset", "tether", "--frames", "10", "--interval", "0.5"]) == 0
    out, _ = capsys.readouterr()
    assert "link tether" in out and "delivered 10" in out and "latency" in out


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["--set", "bogus=1"], "bogus"),
        (["--set", "bitrate_bps=-5"], "bitrate_bps"),
        (["--set", "propagation.speed_mps=-1"], "propagation.speed_mps"),
        (["--set", "ber=2"], "ber"),
        (["--set", "ber=-1e-3"], "ber"),
        (["--set", "novalue"], "novalue"),
        (["--size", "5"], "--size"),
        (["--size", "1000"], "--size"),
        (["--preset", "nope"], "nope"),
        (["--frames", "0"], "--frames"),
        (["--frames", "-4"], "--frames"),
        (["--frames", "abc"], "--frames"),
        (["--frames", "1000000000000"], "--frames: must be 1..1000000"),  # was a MemoryError
        (["--frames", "1000001"], "--frames: must be 1..1000000"),
        (["--interval", "0"], "--interval"),
        (["--interval", "-1"], "--interval"),
        (["--seed", "-1"], "--seed"),
        (["--distance", "-3"], "--distance"),
    ],
)
def test_bad_input_is_one_line_exit_2(
    capsys: pytest.CaptureFixture[str], args: list[str], fragment: str
) -> None:
    assert exit_code(["link", *args]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert err.count("\n") == 1 and fragment in err
    assert "Traceback" not in err


def exit_code(argv: list[str]) -> int | str | None:
    """``main``'s return value, or the code argparse exits with on a malformed option."""
    try:
        return main(argv)
    except SystemExit as stop:
        return stop.code


def test_a_users_preset_file(tmp_path: object, capsys: pytest.CaptureFixture[str]) -> None:
    """A preset file of one's own (a copy of s100 at 4800 bit/s) is the link probed, by
    `testbed link --preset FILE` and by a scenario's link.preset: the latency is its closed
    form, intrinsic delay + 8 · bytes / bitrate."""
    from importlib import resources
    from pathlib import Path

    from testbed.channel import load_link_config
    from testbed.run.scenario import load_scenario

    text = resources.files("testbed.channel").joinpath("presets", "s100.toml").read_text()
    path = Path(str(tmp_path)) / "fast.toml"
    old = f"bitrate_bps = {load_link_config('s100').bitrate_bps:g}"
    assert old in text
    path.write_text(text.replace(old, "bitrate_bps = 4800"))
    mine = load_link_config(str(path))
    result = run_json(capsys, "--preset", str(path), "--frames", "50", "--size", "60")
    latency = result["latency_s"]
    assert isinstance(latency, dict)
    assert latency["max"] == pytest.approx(mine.intrinsic_delay_s + 8 * 60 / 4800, abs=1e-9)
    scenario = load_scenario("s100-teleop-v1", [f"link.preset={path}"])
    assert scenario.link.channel.bitrate_bps == 4800
    assert str(path) in dict(scenario.files)
    missing = path.with_name("none.toml")
    assert main(["link", "--preset", str(missing)]) == 2
    err = capsys.readouterr().err
    assert err == f"testbed: error: --preset: link preset file not found: {missing.absolute()}\n"
