"""Runs across processes (``jaxais.distributed``): two CPU processes on localhost, joined by
``jax.distributed``, give the results of one process bit for bit, and a run that cannot start
fails fast with one line.

The slow test starts three ``scripts/sweep.py`` runs (one alone, two joined over a loopback port)
on a tiny grid and three ``scripts/trials.py`` runs likewise, all at once, so it costs about one
compile's wall time. The failures (nobody at the coordinator's address, process 0 alone, flags
that differ, a port taken, Ctrl-C while waiting) start together too, with a 4 s timeout, and end
before any compile.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from jaxais import distributed

ROOT = Path(__file__).resolve().parent.parent
EMPTY_WORLD = str(ROOT / "tests" / "worlds" / "empty.toml")
"""No visible goal: a run lasts until its time cap, so a signal always finds it running."""
ARGS = ["--grid", "k1=0.85,1.6", "--grid", "k2=1.1", "--trials", "3", "--tau-cap", "8"]
TRIALS = ["--system", "HDC", "--trials", "3", "--tau-cap", "8"]


def _free_ports(n: int) -> list[int]:
    """``n`` distinct free ports (each socket held until all are chosen: no port twice)."""
    sockets = [socket.create_server(("127.0.0.1", 0)) for _ in range(n)]
    ports = [s.getsockname()[1] for s in sockets]
    for s in sockets:
        s.close()
    return ports


def _start(out: Path, *extra: str, script: str = "sweep.py") -> subprocess.Popen:
    env = {**os.environ, "JAXAIS_DEBUG": "", "JAXAIS_CACHE_DIR": "off"}
    for name in distributed.ENV.values():
        env.pop(name, None)
    args = ARGS if script == "sweep.py" else TRIALS
    return subprocess.Popen(
        [sys.executable, f"scripts/{script}", *args, "--out", str(out), *extra],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("dist")
    procs = {}
    ports = iter(_free_ports(2))
    for script, prefix, out in (("sweep.py", "", ""), ("trials.py", "trials_", ".json")):
        joined = ["--coordinator", f"127.0.0.1:{next(ports)}", "--num-processes", "2"]
        procs |= {
            f"{prefix}alone": _start(tmp / f"{prefix}alone{out}", script=script),
            f"{prefix}p0": _start(tmp / f"{prefix}p0{out}", *joined, "--process-id", "0",
                                  script=script),
            f"{prefix}p1": _start(tmp / f"{prefix}p1{out}", *joined, "--process-id", "1",
                                  script=script),
        }  # fmt: skip
    done = {name: p.communicate(timeout=900) for name, p in procs.items()}
    for name, p in procs.items():  # both processes of a joined run exit 0 too
        assert p.returncode == 0, (name, done[name][1][-3000:])
    return tmp


@pytest.mark.slow
def test_two_processes_give_one_processs_results_bit_for_bit(runs):
    alone = json.loads((runs / "alone" / "sweep.json").read_text())
    joined = json.loads((runs / "p0" / "sweep.json").read_text())
    assert joined["config"]["processes"] == 2 and alone["config"]["processes"] == 1
    assert joined["config"]["devices"] == 2 * alone["config"]["devices"]
    assert joined["points"] == alone["points"]  # every mean and interval, exactly
    assert joined["robot_iterations"] == alone["robot_iterations"]


@pytest.mark.slow
def test_only_process_0_writes(runs):
    assert (runs / "p0" / "sweep.json").is_file()
    assert not (runs / "p1" / "sweep.json").exists()
    assert (runs / "trials_p0.json").is_file()
    assert not (runs / "trials_p1.json").exists()


@pytest.mark.slow
def test_two_processes_give_one_processs_trials_bit_for_bit(runs):
    alone = json.loads((runs / "trials_alone.json").read_text())
    joined = json.loads((runs / "trials_p0.json").read_text())
    assert len(alone["trials"]) == 3
    assert joined["trials"] == alone["trials"] and joined["summary"] == alone["summary"]


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--coordinator", "localhost"], "HOST:PORT"),
        (["--coordinator", "localhost:99"], "--num-processes"),
        (["--coordinator", "h:1", "--num-processes", "2", "--process-id", "2"], "[0, 2)"),
        (["--num-processes", "2"], "need --coordinator"),
        (["--coordinator", "localhost:99999", "--num-processes", "2"], "port in 1..65535"),
        (["--coordinator", "localhost:0", "--num-processes", "2"], "port in 1..65535"),
        (
            [
                "--coordinator",
                "h:1",
                "--num-processes",
                "1",
                "--process-id",
                "0",
                "--timeout-s",
                "0",
            ],
            "--timeout-s must be > 0",
        ),
        (["--coordinator", "auto"], "neither is set: start the processes with srun or mpirun"),
    ],
)
def test_inconsistent_flags_are_rejected(flags, message, monkeypatch):
    for name in [v for v in os.environ if v.startswith(("SLURM_", "OMPI_"))]:
        monkeypatch.delenv(name)
    parser = argparse.ArgumentParser()
    distributed.add_arguments(parser)
    with pytest.raises(ValueError, match=message.replace("[", r"\[").replace(")", r"\)")):
        distributed.check(parser.parse_args(flags))


def test_environment_variables_give_the_defaults(monkeypatch):
    monkeypatch.setenv("JAXAIS_COORDINATOR", "10.0.0.1:1234")
    monkeypatch.setenv("JAXAIS_NUM_PROCESSES", "4")
    monkeypatch.setenv("JAXAIS_PROCESS_ID", "3")
    monkeypatch.setenv("JAXAIS_TIMEOUT_S", "7.5")
    parser = argparse.ArgumentParser()
    distributed.add_arguments(parser)
    args = parser.parse_args([])
    assert (args.coordinator, args.num_processes, args.process_id) == ("10.0.0.1:1234", 4, 3)
    assert args.timeout_s == 7.5
    assert parser.parse_args(["--timeout-s", "2"]).timeout_s == 2
    distributed.check(args)  # consistent
    monkeypatch.setenv("JAXAIS_PROCESS_ID", "three")
    with pytest.raises(ValueError, match="JAXAIS_PROCESS_ID must be an integer"):
        distributed.add_arguments(argparse.ArgumentParser())
    monkeypatch.setenv("JAXAIS_PROCESS_ID", "3")
    monkeypatch.setenv("JAXAIS_TIMEOUT_S", "soon")
    with pytest.raises(ValueError, match="JAXAIS_TIMEOUT_S must be a number"):
        distributed.add_arguments(argparse.ArgumentParser())


# ------------------------------------------------------------------------ runs that cannot start


def _trials(tmp: Path, name: str, port: int, n: int, pid: int, *more: str) -> subprocess.Popen:
    where = ["--coordinator", f"127.0.0.1:{port}", "--num-processes", str(n)]
    return _start(tmp / f"{name}.json", *where, "--process-id", str(pid), "--timeout-s", "4",
                  *more, script="trials.py")  # fmt: skip


@pytest.fixture(scope="module")
def failures(tmp_path_factory):
    """Every failing start at once: {name: (returncode, stderr)}."""
    tmp = tmp_path_factory.mktemp("fail")
    nobody, alone, pair, taken, interrupted, running = _free_ports(6)
    holder = socket.create_server(("", taken))  # another program holds process 0's port
    procs = {
        "unreachable": _trials(tmp, "unreachable", nobody, 2, 1),
        "alone": _trials(tmp, "alone", alone, 2, 0),
        "mismatch0": _trials(tmp, "mismatch0", pair, 2, 0, "--trials", "4", "--timeout-s", "60"),
        "mismatch1": _trials(tmp, "mismatch1", pair, 3, 1, "--trials", "6", "--timeout-s", "60"),
        "taken": _trials(tmp, "taken", taken, 2, 0),
        "interrupted": _trials(tmp, "interrupted", interrupted, 2, 1, "--timeout-s", "60"),
    }
    # Ctrl-C once the process says it is waiting (no sooner: the line proves where it was).
    first = ""
    while not first.startswith("waiting for") and procs["interrupted"].poll() is None:
        first = procs["interrupted"].stderr.readline()
    procs["interrupted"].send_signal(signal.SIGINT)
    joined = [_start(tmp / f"joined{i}.json", "--coordinator", f"127.0.0.1:{running}",
                     "--num-processes", "2", "--process-id", str(i), "--world", EMPTY_WORLD,
                     "--tau-cap", "4000", script="trials.py") for i in (0, 1)]  # fmt: skip
    # SIGTERM once they run (process 0's bar is up): JAX's own SIGTERM handler must not be.
    seen = ""
    while "%|" not in seen and joined[0].poll() is None:
        seen += joined[0].stderr.read(1)
    for p in joined:
        p.send_signal(signal.SIGTERM)
    procs |= {"joined0": joined[0], "joined1": joined[1]}
    done = {name: p.communicate(timeout=300) for name, p in procs.items()}
    holder.close()
    return {name: (p.returncode, first * (name == "interrupted") + done[name][1])
            for name, p in procs.items()}  # fmt: skip


def _one_line(failures, name: str, status: int = 2) -> str:
    """The error line of run ``name``: its only one, the last on stderr, and no traceback."""
    code, err = failures[name]
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == status and "Traceback" not in err, (name, code, err[-3000:])
    assert [line for line in lines if "error:" in line] == lines[-1:], (name, err[-3000:])
    return lines[-1]


@pytest.mark.slow
def test_an_unreachable_coordinator_is_one_line_after_the_timeout(failures):
    line = _one_line(failures, "unreachable")
    assert line.startswith("trials.py: error: no coordinator answers at 127.0.0.1:")
    assert "Connection refused" in line and "start process 0" in line
    assert re.search(r"^waiting for 1 of 2 processes at 127\.0\.0\.1:\d+ \(\d+ s of 4\)$",
                     failures["unreachable"][1], re.M)  # fmt: skip


@pytest.mark.slow
def test_process_0_alone_says_who_is_missing(failures):
    line = _one_line(failures, "alone")
    assert "not every process joined at 127.0.0.1:" in line and "within 4 s" in line
    assert "each with its own --process-id" in line


@pytest.mark.slow
def test_processes_started_with_different_flags_name_them(failures):
    zero, one = _one_line(failures, "mismatch0"), _one_line(failures, "mismatch1")
    assert zero == (
        "trials.py: error: process 1 was started with --num-processes 3, --trials 6 and this "
        "one (0) with --num-processes 2, --trials 4: start every process with the same flags"
    )
    assert "process 0 was started with --num-processes 2, --trials 4 and this one (1)" in one


@pytest.mark.slow
def test_a_taken_coordinator_port_is_one_line(failures):
    line = _one_line(failures, "taken")
    assert "cannot host the coordinator at 127.0.0.1:" in line and "holds the port" in line


@pytest.mark.slow
def test_sigterm_stops_a_joined_run(failures):
    for name in ("joined0", "joined1"):
        assert _one_line(failures, name, 143) == "trials.py: error: terminated"


@pytest.mark.slow
def test_ctrl_c_while_waiting_is_honoured(failures):
    assert failures["interrupted"][1].startswith("waiting for 1 of 2 processes")
    assert _one_line(failures, "interrupted", 130) == "trials.py: error: interrupted"
