"""A second signal while ``testbed run`` writes the partial results the first one left.

A Ctrl-C stops the run at t ≈ 2 s; a SIGTERM (a second Ctrl-C, a supervisor's stop) lands
while its partial results are written. ``write_run`` holds it until they are whole, then
raises it, and the command said "interrupted while plotting; results without plots" — which
no plotting happened in, and which reads as a whole run — with the second signal's exit code.
It must say what the first interrupt did: the time reached and where the partial results are,
exit 130, and the files must be the marked partial set.

The run is a child process; both signals are real. The first is sent by the scenario's pilot
(a file of the user's, sampled as the run goes) once the run passes 2 s, the second by the
recorder as it starts writing events.csv.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

from tests.processes import check_set, default_sigint

PILOT = """
import os
import signal

from testbed.operator.pilots import PilotSample


class Impatient:  # a person at the terminal: Ctrl-C 2 s into the run
    def sample(self, t_s):
        if t_s > 2.0:
            os.kill(os.getpid(), signal.SIGINT)
        return PilotSample((0.0,) * 6)
"""

SECOND_SIGNAL_WHILE_WRITING = """
import os, signal, sys
from testbed.run.recorder import Recorder

original = Recorder.write_events_csv

def write_events_csv(self, *args, **kwargs):  # the second signal, as the results are written
    os.kill(os.getpid(), signal.SIGTERM)
    return original(self, *args, **kwargs)

Recorder.write_events_csv = write_events_csv
from testbed.cli.main import main
sys.exit(main({argv!r}))
"""


def test_a_second_signal_while_partial_results_are_written_keeps_the_first_ones_line(
    tmp_path: Path,
) -> None:
    (tmp_path / "impatient.py").write_text(textwrap.dedent(PILOT))
    out = tmp_path / "out"
    argv = ["run", "--set", "duration_s=20", "--out", str(out)]
    argv += ["--set", f'pilot={{kind="python", factory="{tmp_path / "impatient.py"}:Impatient"}}']
    done = subprocess.run(
        [sys.executable, "-c", SECOND_SIGNAL_WHILE_WRITING.format(argv=argv)],
        capture_output=True,
        text=True,
        timeout=300.0,
        preexec_fn=default_sigint,
    )
    metrics = check_set(out)  # the marked partial set: no plots, metrics.json naming the rest
    assert metrics["complete"] is False and 2.0 < metrics["sim_s"] < 3.0
    assert set(metrics["files"]) == {"events.csv", "series.csv"}
    assert done.returncode == 130, done.stderr
    assert done.stderr.splitlines() == [
        f"testbed: interrupted at t = {metrics['sim_s']:.1f} s of 20 s; partial results in {out}"
    ]
