"""The medium access a codec works with: token passing for the paper's teleop codec (its vehicle
only answers orders), free access for the codecs whose vehicle sends on its own. Unnamed, the
scenario's ``link.mac`` follows the codec; a pairing that cannot work is one line naming
``link.mac``. Before, ``--set link.codec=changeset`` on s100-teleop-v1 kept token passing: the
operator's orders went out in token slots at a vehicle that sent at 100 Hz and never yielded
the half-duplex channel, so every order collided and the vehicle never armed."""

from __future__ import annotations

from pathlib import Path

import pytest

from testbed.cli.main import main
from testbed.run import load_scenario, run_scenario


def _unnamed_access(folder: Path) -> str:
    """A scenario of one's own on S100 that names no ``link.mac`` (its path)."""
    path = folder / "mine.toml"
    path.write_text(
        'schema = 1\nid = "mine-v1"\ndescription = "mine"\nduration_s = 30.0\n'
        '[link]\npreset = "s100"\n'
    )
    return str(path)


@pytest.mark.parametrize("codec", ["changeset", "mavlink-raw", "mavlink-hl"])
def test_a_codec_that_sends_on_its_own_gets_free_access_unless_told(
    tmp_path: Path, codec: str
) -> None:
    mine = _unnamed_access(tmp_path)
    assert load_scenario(mine, [f"link.codec={codec}"]).link.mac == "free"
    assert load_scenario(mine).link.mac == "token"


def test_the_ecs_sync_on_a_tether_sends_at_its_rates_and_arms(tmp_path: Path) -> None:
    """Free access: the operator sends at ``uplink_rate_hz`` (the default 50 Hz: 1500 change
    sets in 30 s, all delivered on the full-duplex tether) and the vehicle arms at once. Under
    token passing the same run sent 10 orders in 60 s, armed at 3.8 s and the link-loss
    failsafe disarmed it at 8.8 s."""
    overrides = ["link.preset=tether", "link.codec=changeset"]
    result = run_scenario(load_scenario(_unnamed_access(tmp_path), overrides))
    uplink = result.metrics["link"]["uplink"]
    assert abs(uplink["frames_sent"] - 50 * 30) <= 1
    assert uplink["frames_delivered"] >= uplink["frames_sent"] - 1  # the last still in flight
    kinds = [e.kind for e in result.recorder.events if e.node == "vehicle"]
    assert "arm" in kinds and "disarm" not in kinds


@pytest.mark.parametrize(
    ("overrides", "codec"),
    [
        (["link.codec=changeset", "link.mac=token"], "changeset"),
        (["link.codec=mavlink-raw", "link.mac=token"], "mavlink-raw"),
    ],
)
def test_token_passing_with_a_codec_that_answers_no_order_is_one_line(
    overrides: list[str], codec: str, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["run", "s100-teleop-v1", "--no-plots"]
    for override in overrides:
        argv += ["--set", override]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert f"link.mac: 'token' does not work with link.codec = '{codec}'" in err
