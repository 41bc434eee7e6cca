"""Bad input and interruptions end a script with one line, a non-zero status and no traceback,
and leave what is already written alone: Ctrl-C and SIGTERM wherever they land (jaxais.cli's
handlers), and ``reproduce.py --evolve`` into a folder an earlier run left.

World files (tests/test_worlds.py), trial seeds (tests/test_trials.py) and the scripts' own
flags (tests/test_scripts_*.py) are tested beside what they check.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from _python import run_python

ROOT = Path(__file__).resolve().parent.parent
EMPTY_WORLD = ROOT / "tests" / "worlds" / "empty.toml"
"""No visible goal: a run lasts until its time cap, so a signal always finds it running."""


def _error_lines(stderr: str) -> list[str]:
    """stderr's lines, progress bars (tqdm's carriage returns) split apart, blanks dropped."""
    return [line.strip() for line in re.split(r"[\r\n]+", stderr) if line.strip()]


def _assert_one_line_exit(proc, prog: str, status: int, message: str) -> None:
    lines = _error_lines(proc.stderr)
    assert proc.returncode == status, proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr and "Exception ignored" not in proc.stderr, proc.stderr
    assert [line for line in lines if "error:" in line] == [f"{prog}: error: {message}"], lines
    assert lines[-1] == f"{prog}: error: {message}", lines


# ---------------------------------------------------------------------------------- signals


def _wait_for_our_handlers(proc: subprocess.Popen, timeout: float = 60) -> None:
    """Until ``proc`` catches SIGTERM: jaxais.cli's handlers are in place (it installs SIGINT's
    and SIGTERM's together; Python catches SIGINT from its start), read from /proc."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and proc.poll() is None:
        with open(f"/proc/{proc.pid}/status") as status:
            caught = next(int(line.split()[1], 16) for line in status if line.startswith("SigCgt"))
        if caught >> (signal.SIGTERM - 1) & 1:
            return
        time.sleep(0.005)
    raise AssertionError(f"no signal handler in {proc.args} after {timeout} s")


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="reads /proc")
@pytest.mark.parametrize("delay", [0.0, 0.3, 1.0, 2.0, 3.0])
def test_trials_script_interrupted_at_any_moment_says_one_line(tmp_path: Path, delay: float):
    """SIGINT and SIGTERM (two runs side by side), ``delay`` after the script's handlers are in
    place: at once (its checks), 0.3 s (JAX's imports), 1-2 s (the world, the compile) and 3 s
    (the trials): status 130 or 143, one line, no traceback, and an earlier results file is left
    as it was, with no temporary files. (The signal is timed from the handlers, not from the
    start: before them, in Python's own start-up, a signal ends the process as by default, before
    it has written anything.)"""
    procs = {}
    for signum in (signal.SIGINT, signal.SIGTERM):
        out_dir = tmp_path / signum.name
        out_dir.mkdir()
        (out_dir / "r.json").write_text("earlier results\n")
        args = ["--system", "HDC", "--world", EMPTY_WORLD, "--trials", 2, "--tau-cap", 4000]
        procs[signum] = subprocess.Popen(
            [sys.executable, "scripts/trials.py", *map(str, args), "--out", out_dir / "r.json"],
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env={**os.environ, "JAXAIS_DEBUG": "", "JAXAIS_CACHE_DIR": "off"},
        )
    for proc in procs.values():
        _wait_for_our_handlers(proc)
    time.sleep(delay)
    for signum, proc in procs.items():
        proc.send_signal(signum)
    for signum, proc in procs.items():
        try:
            out, err = proc.communicate(timeout=60)
        finally:
            proc.kill()
        done = subprocess.CompletedProcess(proc.args, proc.returncode, out, err)
        status, message = {
            signal.SIGINT: (130, "interrupted"),
            signal.SIGTERM: (143, "terminated"),
        }[signum]
        _assert_one_line_exit(done, "trials.py", status, message)
        out_dir = tmp_path / signum.name
        assert [p.name for p in out_dir.iterdir()] == ["r.json"]
        assert (out_dir / "r.json").read_text() == "earlier results\n"


def _script(body: str, prelude: str = "") -> str:
    """A script whose main (under main_wrapper, run by run_script) runs ``body``."""
    return textwrap.dedent(
        """
        import gc, os, signal, sys, time, weakref
        from jaxais.cli import main_wrapper, run_script
        {prelude}

        @main_wrapper("demo.py")
        def main():
        {body}

        run_script(main)
        """
    ).format(prelude=prelude, body=textwrap.indent(textwrap.dedent(body), "    "))


def _wait_loop(n: int = 200) -> str:
    return f"for _ in range({n}):\n    time.sleep(0.01)\nprint('never interrupted')\n"


CASES = {
    "sigint": ("signal.raise_signal(signal.SIGINT)\n" + _wait_loop(), 130, "interrupted"),
    "sigterm": ("signal.raise_signal(signal.SIGTERM)\n" + _wait_loop(), 143, "terminated"),
    # The interrupt turned into another exception where it landed (jaxlib's import turns it
    # into "ImportError: Encountered an error while initializing the extension").
    "converted": (
        "try:\n    signal.raise_signal(signal.SIGINT)\nexcept KeyboardInterrupt:\n"
        "    raise ImportError('Encountered an error while initializing the extension')"
        " from None\n",
        130,
        "interrupted",
    ),
    # Raised in a __del__, a KeyboardInterrupt would be printed and dropped by Python.
    "in __del__": (
        "class Late:\n    def __del__(self):\n        signal.raise_signal(signal.SIGINT)\n"
        "Late()\n" + _wait_loop(),
        130,
        "interrupted",
    ),
    # Raised in a weakref callback (JAX's gc callback is one), likewise.
    "in a callback": (
        "class Thing:\n    pass\n"
        "t = Thing()\nr = weakref.ref(t, lambda ref: os.kill(os.getpid(), signal.SIGINT) or "
        "[time.sleep(0.001) for _ in range(100)])\n"
        "del t\n" + _wait_loop(),
        130,
        "interrupted",
    ),
    # Nothing unwinds: a finally block does not run, and a second signal changes nothing.
    # A write in flight leaves neither a half-written file nor its temporary file.
    "mid-write": (
        "from pathlib import Path\nfrom jaxais.io import atomic_write\n"
        "def slow(tmp):\n    tmp.write_text('half')\n    signal.raise_signal(signal.SIGINT)\n"
        "atomic_write(Path(os.environ['OUT_DIR']) / 'r.json', slow)\n" + _wait_loop(),
        130,
        "interrupted",
    ),
    "twice": (
        "try:\n    signal.raise_signal(signal.SIGTERM)\nfinally:\n"
        "    signal.raise_signal(signal.SIGTERM)\n    time.sleep(2)\n    print('cleanup ran')\n",
        143,
        "terminated",
    ),
}


@pytest.mark.parametrize("case", list(CASES))
def test_interrupt_anywhere_in_main_is_one_line(case: str, tmp_path: Path):
    body, status, message = CASES[case]
    (tmp_path / "r.json").write_text("earlier\n")
    proc = run_python(_script(body), timeout=60, env={**os.environ, "OUT_DIR": str(tmp_path)})
    _assert_one_line_exit(proc, "demo.py", status, message)
    assert "never interrupted" not in proc.stdout and "cleanup ran" not in proc.stdout
    assert [p.name for p in tmp_path.iterdir()] == ["r.json"]
    assert (tmp_path / "r.json").read_text() == "earlier\n"


def test_a_signal_runs_the_librarys_last_steps_first():
    """jaxais.io.ON_SIGNAL (the seed ledger stops its child processes there) runs, newest
    first, before the process ends with the signal's line."""
    body = (
        "from jaxais import io\n"
        "io.ON_SIGNAL.append(lambda: print('first registered', flush=True))\n"
        "io.ON_SIGNAL.append(lambda: print('second registered', flush=True))\n"
        "signal.raise_signal(signal.SIGTERM)\n" + _wait_loop()
    )
    proc = run_python(_script(body), timeout=60)
    _assert_one_line_exit(proc, "demo.py", 143, "terminated")
    assert proc.stdout == "second registered\nfirst registered\n"


def test_interrupt_during_an_import_is_one_line(tmp_path: Path):
    """A signal in the middle of an import ends the run at once with its line (a
    KeyboardInterrupt inside a C extension's initialisation printed tracebacks or crashed the
    interpreter)."""
    (tmp_path / "slow_module.py").write_text(
        "import signal, time\n"
        "signal.raise_signal(signal.SIGINT)\n"
        "for _ in range(10):\n    time.sleep(0.01)\n"
        "print('import finished', flush=True)\n"
    )
    body = "import slow_module\nprint('after the import', flush=True)\n" + _wait_loop()
    prelude = f"sys.path.insert(0, {str(tmp_path)!r})"
    proc = run_python(_script(body, prelude), timeout=60)
    _assert_one_line_exit(proc, "demo.py", 130, "interrupted")
    assert "import finished" not in proc.stdout and "never interrupted" not in proc.stdout


def test_handlers_are_ours_only_while_a_wrapper_runs():
    code = textwrap.dedent(
        """
        import signal, sys
        from jaxais import cli
        before = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
        with cli.main_wrapper("demo.py"):
            inside = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
            assert all(callable(h) and h not in before for h in inside), inside
        assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == before
        # A signal the process was started with ignored (nohup, a background job) stays so.
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        with cli.main_wrapper("demo.py"):
            assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
            assert signal.getsignal(signal.SIGTERM) not in before
            signal.raise_signal(signal.SIGINT)  # ignored
        print("ok")
        """
    )
    proc = run_python(code, timeout=60)
    assert proc.returncode == 0 and proc.stdout == "ok\n", proc.stderr


def test_error_while_a_progress_bar_is_open_starts_its_own_line():
    """A signal that ends the process at once (no unwinding) finds the bar still open: the
    error line must not be glued to it, and without a bar no blank line is added."""
    code = textwrap.dedent(
        """
        import sys
        from tqdm.auto import tqdm
        from jaxais import cli
        import os
        assert cli._error_line("demo.py", "interrupted") == "demo.py: error: interrupted\\n"
        bar = tqdm(total=10, file=sys.stderr, desc="run")
        bar.update(1)
        try:
            cli.fail("demo.py", "interrupted", status=130)
        except SystemExit as stop:
            os._exit(stop.code)  # as run_script and a signal's exit do: the bar is not closed
        """
    )
    proc = run_python(code, timeout=60)
    assert proc.returncode == 130, proc.stderr
    assert proc.stderr.splitlines()[-1] == "demo.py: error: interrupted", proc.stderr


# ---------------------------------------------------------------------------------- reproduce.py


def _reproduce(*args: object) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "scripts/reproduce.py", *map(str, args)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "JAXAIS_DEBUG": ""},
    )


def _tree(path: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(path)): p.read_bytes() if p.is_file() else b"" for p in path.rglob("*")
    }


def test_reproduce_evolve_into_an_earlier_ltl_folder_says_what_to_do(tmp_path: Path):
    """A folder an earlier run (or a user) left, without a run manifest, is refused before any
    work, and nothing in it is touched (evolve.py would refuse it with advice for its own
    --resume); a partial reproduce.py run is finished with reproduce.py --resume."""
    finished, unfinished = tmp_path / "finished", tmp_path / "unfinished"
    (finished / "ltl" / "seed").mkdir(parents=True)
    (finished / "ltl" / "seed" / "meta.json").write_text("{}")
    (finished / "tables.json").write_text("earlier tables\n")
    (unfinished / "ltl" / "checkpoints").mkdir(parents=True)
    tiny = ("--trials", 2, "--tau-cap", 5, "--worlds", "world1", "--generations", 1)
    before = _tree(tmp_path)
    for out in (finished, unfinished):
        proc = _reproduce("--evolve", "--out", out, *tiny)
        message = f"{out} is not empty and holds no run: give a fresh or empty --out"
        _assert_one_line_exit(proc, "reproduce.py", 2, message)
    assert _tree(tmp_path) == before


# ---------------------------------------------------------------------------------- memory


def test_a_run_beyond_memory_is_refused_with_the_estimate(monkeypatch):
    """A run whose host arrays would pass half the machine's memory is refused before any work
    (``trials.py --trials 100000000`` grew to 24 GB and was killed with no message)."""
    from jaxais import io

    pages = {"SC_PHYS_PAGES": 4 * 2**20, "SC_PAGE_SIZE": 4096}  # 16 GiB
    monkeypatch.setattr(io.os, "sysconf", pages.__getitem__)
    io.check_memory(10**6, io.RUN_BYTES, "--trials")  # 8.2 of 17.2 GB: fits
    with pytest.raises(io.UserError) as info:
        io.check_memory(10**8, io.RUN_BYTES, "--trials")
    assert str(info.value) == (
        "--trials 100000000 needs about 819 GB of memory; this machine has 17 GB; "
        "use --trials <= 1048576"
    )


SIZES = {  # script -> its size flags at 10**9 (each refused before any work)
    "ablate": ["--trials"],
    "seeds": ["--trials", "--seeds"],
    "train_baseline": ["--pairs", "--episodes", "--hidden", "--generations"],
    "evolve": ["--populations", "--robots", "--starts", "--success-starts", "--crossing-starts"],
    "bench": ["--batches", "--controller-batches", "--numpy-robots", "--matmul"],
}


@pytest.mark.slow
def test_every_size_flag_beyond_memory_is_refused_by_the_library(tmp_path: Path):
    """Each script's size flags at 10**9 (which grew until the kernel's kill, or an XLA abort):
    one line from the library driver's check with the estimate and the largest value that
    fits, exit 2, nothing written. One interpreter runs every case (imports, no compiles)."""
    code = textwrap.dedent(f"""
        import contextlib, importlib, io, sys
        for name, flags in {SIZES!r}.items():
            main = importlib.import_module("jaxais.scripts." + name).main
            for flag in flags:
                err = io.StringIO()
                with contextlib.redirect_stderr(err), contextlib.suppress(SystemExit):
                    main(["--out", {str(tmp_path / "out")!r} + (".json" * (name == "bench")),
                          flag, str(10**9)])
                print(name, flag, "|", err.getvalue().strip())
    """)
    proc = run_python(code, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    lines = proc.stdout.splitlines()
    assert len(lines) == sum(map(len, SIZES.values())), proc.stdout
    for line in lines:
        name, flag, message = re.fullmatch(r"(\S+) (\S+) \| (.*)", line).groups()
        assert re.fullmatch(
            rf"{name}.py: error: (--\S+ x )*{flag}( x --\S+)*( squared)? \d+ needs about [\d.e+]+ "
            rf"GB of memory; this machine has \d+ GB; use (--\S+ x )*{flag}( x --\S+)*"
            rf"( squared)? <= \d+",
            message,
        ), line
    assert not list(tmp_path.iterdir())


def test_a_collision_cap_beyond_the_int32_counters_is_refused():
    """``trials.py --collision-cap 99999999999`` ended in JAX's OverflowError (a traceback)."""
    from jaxais.loop import EpisodeConfig

    EpisodeConfig(collision_cap=2**31 - 1)
    with pytest.raises(ValueError, match=r"collision_cap must be below 2\*\*31, got 99999999999"):
        EpisodeConfig(collision_cap=99999999999)
