"""`testbed run` as a real process: Ctrl-C and SIGTERM keep a marked partial result, kill -9
while writing never leaves a mixed or silently partial set, and a bad --out fails before work.

Each run is a child process of this test (``python -m testbed``); signals are real. A run is
signalled once it has shown it is simulating (its results directory exists, made before the
simulation starts); the waits are bounded by generous multiples of what the work needs, polled,
never slept blindly. What involves no signal (a bad --out, the complete runs before and after
the killed one) calls the CLI's ``main`` in this process instead (a child costs ≈ 2 s of imports).
"""

from __future__ import annotations

import functools
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from testbed.cli.main import main
from tests.processes import check_set, default_sigint

LONG = ["--set", "duration_s=86400"]  # a simulated day, minutes of wall time: a signal ends it
WAIT_S = 120.0


def start(args: list[str]) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "testbed", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=default_sigint,
    )


def python_taking_ctrl_c(
    args: list[str], cwd: Path | None = None
) -> subprocess.CompletedProcess[str]:
    """Python with ``args`` to its end (output captured), SIGINT handled as a terminal's Ctrl-C
    is however pytest was started."""
    return subprocess.run(
        [sys.executable, *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=WAIT_S,
        preexec_fn=default_sigint,
    )


def wait_for(condition: object, what: str, proc: subprocess.Popen[str] | None = None) -> None:
    deadline = time.monotonic() + WAIT_S
    while not condition():  # type: ignore[operator]
        if proc is not None and proc.poll() is not None:
            raise AssertionError(f"the run ended ({proc.returncode}) before {what}")
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.05)


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_interrupt_keeps_a_marked_partial_result(
    tmp_path: Path, sig: signal.Signals, code: int
) -> None:
    # The results directory is made before the nodes are built; a signal that lands while they
    # still are (a loaded host) ends the run before it simulates: one line without a time, and
    # the test tries again, waiting twice as long (any amount of simulation will do).
    for attempt, wait_s in enumerate((1.0, 2.0, 4.0, 8.0, 16.0)):
        out = tmp_path / f"run{attempt}"
        proc = start(["run", *LONG, "--no-plots", "--out", str(out)])
        wait_for(out.exists, "the results directory", proc)
        time.sleep(wait_s)
        proc.send_signal(sig)
        stdout, stderr = proc.communicate(timeout=WAIT_S)
        assert proc.returncode == code, stderr
        lines = stderr.strip().splitlines()
        if lines != ["testbed: interrupted"]:
            break
    assert len(lines) == 1 and lines[0].startswith("testbed: interrupted at t = "), stderr
    assert lines[0].endswith(f"of 86400 s; partial results in {out}")
    assert stdout == ""
    metrics = check_set(out)
    assert metrics["complete"] is False
    reached = float(lines[0].split("t = ")[1].split(" s")[0])
    assert 0.0 < metrics["sim_s"] < 86400.0
    assert metrics["sim_s"] == pytest.approx(reached, abs=0.05 + 1e-9)  # the line rounds to 0.1 s
    assert set(metrics["files"]) == {"events.csv", "series.csv"}


def test_kill_while_writing_never_leaves_a_mixed_set(tmp_path: Path) -> None:
    out = tmp_path / "run"
    # A first complete run, then a second into the same directory killed while it writes:
    # what is left is either no metrics.json (no result) or a set it describes exactly.
    assert main(["run", "--no-plots", "--out", str(out)]) == 0
    assert check_set(out)["complete"] is True
    proc = start(["run", "--seed", "2", "--no-plots", "--force", "--out", str(out)])
    # the writer removes the old metrics.json first; kill as soon as it is gone
    gone = lambda: not (out / "metrics.json").exists() or proc.poll() is not None  # noqa: E731
    wait_for(gone, "the old metrics.json to go")
    proc.kill()
    proc.communicate(timeout=WAIT_S)
    assert proc.returncode in (-signal.SIGKILL, 0)
    if (out / "metrics.json").exists():  # it finished before the kill: a whole new set
        assert check_set(out)["seed"] == 2
    # a third run with --force makes a complete set of its own whatever was left
    assert main(["run", "--seed", "3", "--no-plots", "--force", "--out", str(out)]) == 0
    metrics = check_set(out)
    assert metrics["complete"] is True and metrics["seed"] == 3
    assert not [p for p in out.iterdir() if p.name.startswith(".tmp-")]


@pytest.mark.parametrize(
    ("out", "words"),
    [
        ("afile/sub", "cannot write there"),
        ("afile", "exists and is not a directory"),
        ("full", "is not empty (use --force"),
        ("/proc/testbed-out", "cannot write there"),
    ],
)
def test_bad_out_fails_before_any_work(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    out: str,
    words: str,
) -> None:
    (tmp_path / "afile").write_text("x")
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "old.txt").write_text("x")
    monkeypatch.setattr("testbed.run.runner.run_scenario", lambda *a, **k: pytest.fail("ran"))
    assert main(["run", *LONG, "--out", str(tmp_path / out)]) == 2
    stdout, stderr = capsys.readouterr()
    assert stdout == ""
    assert stderr.count("\n") == 1 and stderr.startswith("testbed: error: --out: ")
    assert words in stderr
    assert (tmp_path / "full" / "old.txt").read_text() == "x"


def handles(pid: int, *signals: signal.Signals) -> bool:
    """Whether process ``pid`` has handlers of its own installed for ``signals`` (Linux's
    ``SigCgt`` mask in /proc/PID/status): until then a signal would kill it outright."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    caught = next(int(line.split()[1], 16) for line in status.splitlines() if "SigCgt" in line)
    return all(caught >> (int(sig) - 1) & 1 for sig in signals)


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_link_and_modem_emulator_end_with_one_line(sig: signal.Signals, code: int) -> None:
    # the emulator runs until a signal; the probe of 10^6 frames (the most) takes ~20 s
    for args, last in (
        (["modem-emulator"], "testbed: interrupted; the emulator closed its ports"),
        (["link", "--frames", "1000000"], "testbed: interrupted"),
    ):
        proc = start(args)
        if args[0] == "modem-emulator":
            assert proc.stdout is not None and proc.stdout.readline().startswith("A /dev/pts/")
        else:  # the CLI has set its SIGTERM handler (a loaded host may take seconds)
            ready = functools.partial(handles, proc.pid, signal.SIGINT, signal.SIGTERM)
            wait_for(ready, "handlers", proc)
            time.sleep(0.2)  # into the probe
        proc.send_signal(sig)
        _, stderr = proc.communicate(timeout=WAIT_S)
        assert proc.returncode == code, stderr
        assert stderr.strip().splitlines()[-1] == last
        assert "Traceback" not in stderr


def test_modem_emulator_rejects_an_endless_duration_in_one_line(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["modem-emulator", "--duration", "inf"]) == 2
    stdout, stderr = capsys.readouterr()
    assert stdout == "" and stderr.count("\n") == 1
    assert stderr.startswith("testbed: error: --duration: must be in [0, 86400] s, got inf")


SWALLOWED = """
import os, signal, sys, time
import testbed.cli.run as run

def swallow(args):  # a library that turns the interrupt into an error of its own
    try:
        os.kill(os.getpid(), signal.SIG{name})
        time.sleep(30)
    except KeyboardInterrupt as interrupt:
        raise RuntimeError("lost in a library") from interrupt
    return 0

run._list_scenarios = swallow
from testbed.cli.main import main
sys.exit(main(["scenarios"]))
"""


@pytest.mark.parametrize(("name", "code"), [("INT", 130), ("TERM", 143)])
def test_an_interrupt_a_library_turned_into_its_own_error_still_ends_as_one(
    name: str, code: int
) -> None:
    # The handler raises wherever the program is; code that catches the interrupt and raises
    # something else must not turn Ctrl-C or SIGTERM into a traceback and exit code 1.
    done = python_taking_ctrl_c(["-c", SWALLOWED.format(name=name)])
    assert (done.returncode, done.stderr) == (code, "testbed: interrupted\n")


def test_an_error_with_no_signal_is_not_taken_for_an_interrupt() -> None:
    # the same error from a KeyboardInterrupt no signal raised: a real failure, reported
    script = SWALLOWED.replace("os.kill(os.getpid(), signal.SIG{name})", "raise KeyboardInterrupt")
    done = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        timeout=WAIT_S,
    )
    assert done.returncode == 1 and "RuntimeError: lost in a library" in done.stderr


IN_A_WEAKREF_CALLBACK = """
import gc, os, signal, sys, time, weakref
import testbed.cli.run as run

def plots(args):  # the signal lands in a weakref callback, as it did once while plotting
    class Figure:
        pass

    figure = Figure()
    keep = weakref.ref(figure, lambda _: os.kill(os.getpid(), signal.SIG{name}))
    del figure  # the callback runs here: the interrupt raised in it is "ignored" by Python
    deadline = time.monotonic() + {spin_s}
    while time.monotonic() < deadline:  # the command's own code, where it must end
        pass
    return 0

run._list_scenarios = plots
from testbed.cli.main import main
sys.exit(main(["scenarios"]))
"""


@pytest.mark.parametrize(("name", "code"), [("INT", 130), ("TERM", 143)])
def test_an_interrupt_python_ignored_in_a_callback_still_ends_the_command(
    name: str, code: int
) -> None:
    """An interrupt raised in a weakref callback is printed as "Exception ignored in …" and
    dropped by Python: the command went on and exited 0 after a traceback (a review's Ctrl-C
    during plotting). It is sent again and ends the command in its own code, one line."""
    done = python_taking_ctrl_c(["-c", IN_A_WEAKREF_CALLBACK.format(name=name, spin_s=30.0)])
    assert (done.returncode, done.stderr) == (code, "testbed: interrupted\n")
    # the command ends at once after the callback: the interrupt sent again still lands in it
    done = python_taking_ctrl_c(["-c", IN_A_WEAKREF_CALLBACK.format(name=name, spin_s=0.0)])
    assert (done.returncode, done.stderr) == (code, "testbed: interrupted\n")


PUT_OFF = """
import importlib, pickle, signal, sys, time
from numba.core import serialize
cli = importlib.import_module("testbed.cli.main")
signal.signal(signal.SIGTERM, cli._signalled)

def calls(frame, event, arg):
    return inside if frame.f_code is serialize._numba_unpickle.__code__ else None

arrived = []

def inside(frame, event, arg):  # SIGTERM arrives at the callback's first line: its handler
    if event == "line" and not arrived:
        arrived.append(1)
        cli._signalled(signal.SIGTERM, frame)
        print("put off", cli._SIGNALLED, flush=True)
    return None

sys.settrace(calls)
serialize._numba_unpickle(1, pickle.dumps(1), b"put-off")  # a kernel's callback into Python
sys.settrace(None)
try:
    deadline = time.monotonic() + 60.0
    while time.monotonic() < deadline:  # the program's own code, where it is raised
        pass
except KeyboardInterrupt as interrupt:
    print(type(interrupt).__name__, cli._SIGNALLED == [signal.SIGTERM])
try:
    cli._signalled(signal.SIGTERM, sys._getframe())  # in the program's own code: at once
except KeyboardInterrupt as interrupt:
    print("at once", type(interrupt).__name__)
"""


def test_an_interrupt_inside_numbas_own_code_is_raised_after_it() -> None:
    # An exception raised in a compiled kernel's first callback into Python crashed the process
    # (segmentation fault) and in a later one came out as SystemError: the handlers put the
    # signal off while numba's code runs and raise it in the program's own code.
    done = subprocess.run(
        [sys.executable, "-c", PUT_OFF], capture_output=True, text=True, timeout=WAIT_S
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == ["put off []", "Terminated True", "at once Terminated"]


IN_IMPORT_OR_TEXT = """
import os, signal, sys, time, traceback
import testbed.cli.run as run

def interrupted_inside(args):  # Ctrl-C arrives inside {where}, then the program's own code
    text_globals = dict()
    try:
        {code}
        time.sleep(30)
    except KeyboardInterrupt as interrupt:  # the frames from here to where the handler raised it
        frames = " > ".join(frame.name for frame in traceback.extract_tb(interrupt.__traceback__))
        ran = getattr(sys.modules.get("signals_itself"), "done", text_globals.get("done", False))
        os.write(1, (frames + (", whole" if ran else ", half") + "\\n").encode())
        raise
    return 0

run._list_scenarios = interrupted_inside
from testbed.cli.main import main
sys.exit(main(["scenarios"]))
"""

SIGNALS_ITSELF = "import os, signal\nos.kill(os.getpid(), signal.SIGINT)\ndone = True\n"


@pytest.mark.parametrize(
    ("where", "code"),
    [
        ("an import", "import signals_itself"),  # a module that takes Ctrl-C while imported
        ("code exec compiled from text", f"exec({SIGNALS_ITSELF!r}, text_globals)"),  # dataclasses
    ],
)
def test_ctrl_c_in_an_import_or_in_code_from_text_ends_with_130(
    tmp_path: Path, where: str, code: str
) -> None:
    # Under load, `testbed link` took Ctrl-C while importing: inside numpy's random generator
    # registering its classes the interrupt was swallowed (the probe ran to its end, exit 0),
    # and inside a dataclass's methods, which `dataclasses` compiles from text with exec,
    # CPython marked it unhandled: the one line, then the process killed by SIGINT (-2), not
    # 130. The handler puts the signal off until the import or the text's code is done.
    # Run with -m, as `python -m testbed` is: CPython acts on that mark only for -m.
    # The put-off interrupt is sent again ≈ 1 ms later and may land on any line of the
    # program's own code (on a loaded host it landed inside a print, between its text and its
    # newline), so the program reports, in one write after it is raised, where the handler
    # raised it: in its own frame (`interrupted_inside > _signalled`), with the module or the
    # text run whole, not in a frame of the import or of the text.
    (tmp_path / "signals_itself.py").write_text(SIGNALS_ITSELF)
    (tmp_path / "interrupted_cli.py").write_text(IN_IMPORT_OR_TEXT.format(where=where, code=code))
    done = python_taking_ctrl_c(["-m", "interrupted_cli"], cwd=tmp_path)
    assert (done.returncode, done.stderr) == (130, "testbed: interrupted\n")
    assert done.stdout == "interrupted_inside > _signalled, whole\n"


MAIN_IN_AN_IMPORT = """
import os, signal, time
import testbed.cli.run as run

def interrupted(args):
    os.kill(os.getpid(), signal.SIGINT)
    time.sleep(30)
    return 0

run._list_scenarios = interrupted
from testbed.cli.main import main
print("code", main(["scenarios"]), flush=True)
"""


def test_a_program_calling_main_inside_its_own_import_still_takes_ctrl_c(tmp_path: Path) -> None:
    # Interrupts are put off while an import runs; only the imports the command itself makes
    # count, not one the whole program runs inside (it would never take Ctrl-C).
    (tmp_path / "study_import.py").write_text(MAIN_IN_AN_IMPORT)
    done = python_taking_ctrl_c(["-c", "import study_import"], cwd=tmp_path)
    assert (done.stdout, done.stderr) == ("code 130\n", "testbed: interrupted\n")


IN_A_CALLBACK = """
import importlib, signal, sys
import simpy
from numba.core import serialize
from testbed.vehicle.localization import KalmanLocalizer
from tests.interrupts import calling_back
cli = importlib.import_module("testbed.cli.main")
# a kernel calling back when the filter is built and every frame, as the filter's own did
KalmanLocalizer.__init__ = calling_back(KalmanLocalizer.__init__)
KalmanLocalizer.step = calling_back(KalmanLocalizer.step)
callback = serialize._numba_unpickle.__code__
in_run = sys.argv.pop(1) == "run"  # the first callback once the clock runs, else the first
arrived = []
started = [not in_run]
simulate = simpy.Environment.run

def run(env, until=None):
    started[0] = True
    return simulate(env, until)

simpy.Environment.run = run

def calls(frame, event, arg):
    if frame.f_code is callback and started[0] and not arrived:
        return inside
    return None

def inside(frame, event, arg):
    if event == "line" and not arrived:  # SIGTERM arrives here: Python calls its handler so
        arrived.append(1)
        signal.getsignal(signal.SIGTERM)(signal.SIGTERM, frame)
    return None

sys.settrace(calls)
sys.exit(cli.main(sys.argv[1:]))
"""


def test_sigterm_in_a_kernels_first_callback_ends_the_run_with_its_partial_result(
    tmp_path: Path,
) -> None:
    # Without putting it off, this ended in a segmentation fault (a compiled kernel calls back
    # into Python to hand back each new array; the first such call cannot take an exception).
    # The script adds such a kernel to the navigation filter (tests.interrupts.calling_back; the
    # filter's own kernels called back until they returned only a status), called while the
    # vehicle is built and every frame. A SIGTERM in the first callback: one line and 143, and
    # the put-off signal lands in the program's own code, still building (nothing to keep) or
    # just started (a marked partial set); in the first once the clock runs: what ran is kept.
    def sigterm_in_first_callback(mode: str, out: Path) -> str:
        """The one stderr line of a run that took SIGTERM in its first callback (``mode``:
        while the vehicle is built, or once the clock runs), after its exit code 143."""
        args = ["run", "s100-supervised-v1", "--set", "duration_s=20", "--no-plots", "--out"]
        done = subprocess.run(
            [sys.executable, "-c", IN_A_CALLBACK, mode, *args, str(out)],
            capture_output=True,
            text=True,
            timeout=WAIT_S,
        )
        assert done.returncode == 143, done.stderr
        lines = done.stderr.strip().splitlines()
        lines = [line for line in lines if "come after the run's end" not in line]  # goals
        assert len(lines) == 1 and lines[0].startswith("testbed: interrupted"), done.stderr
        return lines[0]

    out = tmp_path / "setup"
    line = sigterm_in_first_callback("setup", out)
    if line.startswith("testbed: interrupted at t = "):
        assert check_set(out)["complete"] is False
    else:  # still building: nothing written, and the --out the CLI made is removed again
        assert line == "testbed: interrupted" and not out.exists()
    out = tmp_path / "run"
    line = sigterm_in_first_callback("run", out)
    assert line.startswith("testbed: interrupted at t = "), line
    metrics = check_set(out)
    assert metrics["complete"] is False and 0.0 <= metrics["sim_s"] < 20.0


@pytest.mark.parametrize("gap_s", [0.05, 0.3])
def test_a_double_ctrl_c_ends_a_live_session_with_its_results(tmp_path: Path, gap_s: float) -> None:
    # A pilot's double Ctrl-C: the second came while the console server stopped (50 ms: only
    # 'testbed: interrupted', the folder removed) or while the results were written (0.3 s:
    # 'results in DIR' over an empty folder). Both end with the session's one line, its data.
    out = tmp_path / "live"
    proc = start(["live", "--port", "0", "--duration", "600", "--out", str(out)])
    assert proc.stdout is not None and proc.stdout.readline().startswith("testbed live: console")
    time.sleep(2.0)  # the session flies a while
    proc.send_signal(signal.SIGINT)
    time.sleep(gap_s)
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=WAIT_S)
    assert proc.returncode == 130, stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("testbed live: session ended at t = "), stderr
    assert lines[0].endswith(f" in {out}")
    metrics = check_set(out)
    assert metrics["complete"] is False
    assert {"events.csv", "series.csv"} <= set(metrics["files"])


def test_ctrl_c_while_a_scenarios_pilot_file_runs_at_import_ends_the_command_at_once(
    tmp_path: Path,
) -> None:
    """A pilot file named in a scenario is the user's own code: Ctrl-C lands in it as in the
    command's. Its import used to put the signal off (an import under way is code an interrupt
    must not be raised in), so a file that slept 60 s at import kept Ctrl-C waiting 60 s, and
    one that looped, for ever. Now: one line, exit 130, long before the sleep ends."""
    marker = tmp_path / "importing"
    (tmp_path / "sleepy.py").write_text(
        f"import time\nopen({str(marker)!r}, 'w').close()\ntime.sleep(60)\n"
        "def pilot():\n    raise AssertionError('never made')\n"
    )
    (tmp_path / "s.toml").write_text(
        'schema = 1\nid = "sleepy-v1"\ndescription = "d"\nduration_s = 20.0\n'
        '[pilot]\nkind = "python"\nfactory = "sleepy.py:pilot"\n'
    )
    proc = start(["run", str(tmp_path / "s.toml"), "--out", str(tmp_path / "out")])
    try:
        wait_for(marker.exists, "the pilot file's import", proc)
        sent = time.monotonic()
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=WAIT_S)
        took_s = time.monotonic() - sent
    finally:
        proc.kill()
    assert proc.returncode == 130 and err == "testbed: interrupted\n", err
    assert took_s < 50.0  # the import's own end is 60 s after the marker, later than this
