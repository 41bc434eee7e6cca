"""Runs across processes (``jaxais.distributed``): two CPU processes on localhost, joined by
``jax.distributed``, give the results of one process bit for bit and both exit 0, and a run that
cannot start, or loses a process, fails fast with one line.

Every process of the file starts at once in one module fixture (:func:`runs`), so the file costs
about one compile's wall time: ``scripts/trials.py`` alone and as a joined pair on a tiny run
(the only processes that compile), small joined runs that compile nothing (:data:`JOIN`: a
process that ends first, processes killed mid-run, seen by the heartbeats or by gloo), and the
failures (nobody at the coordinator's address, process 0 alone, flags that differ, a port taken,
an id taken twice, Ctrl-C while waiting).
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
import time
from pathlib import Path

import pytest

from jaxais import distributed

ROOT = Path(__file__).resolve().parent.parent
TRIALS = ["--system", "HDC", "--trials", "3", "--tau-cap", "8"]
LONG = ("--timeout-s", "60")  # for processes that must not time out (the others wait 4 s)
CLUSTER_VARS = ("SLURM_", "OMPI_", "JAX_COORDINATOR_PORT")


def _free_ports(n: int) -> list[int]:
    """``n`` distinct free ports (each socket held until all are chosen: no port twice)."""
    sockets = [socket.create_server(("127.0.0.1", 0)) for _ in range(n)]
    ports = [s.getsockname()[1] for s in sockets]
    for s in sockets:
        s.close()
    return ports


def _python(*args: str, cluster: dict[str, str] | None = None) -> subprocess.Popen:
    """``python ARGS`` in the repository, with ``cluster``'s variables in place of any
    SLURM or Open MPI ones."""
    env = {**os.environ, "JAXAIS_DEBUG": "", "JAXAIS_CACHE_DIR": "off"}
    for name in [*distributed.ENV.values(), *(v for v in env if v.startswith(CLUSTER_VARS))]:
        env.pop(name, None)
    env.update(cluster or {})
    return subprocess.Popen([sys.executable, *args], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)  # fmt: skip


def _start(out: Path, *extra: str) -> subprocess.Popen:
    return _python("scripts/trials.py", *TRIALS, "--out", str(out), *extra)


JOIN = """
import sys, time
from jaxais import cli, distributed

@cli.main_wrapper("join.py")
def main():
    parser = cli.ArgumentParser(prog="join.py")
    parser.add_argument("--then", choices=("end", "sleep", "gather"))
    distributed.add_arguments(parser)
    args = parser.parse_args()
    distributed.initialize(args)
    if args.then == "end":  # process 0 (writing, say) ends 12 s after the others (at exit)
        time.sleep(12 if args.process_id == 0 else 0)
    while args.then != "end":  # until a process is lost
        if args.then == "gather":
            import jax.numpy as jnp
            from jax.experimental import multihost_utils

            multihost_utils.process_allgather(jnp.zeros(1))
            print("gathered", file=sys.stderr, flush=True)
        time.sleep(0.1)

cli.run_script(main)
"""
"""A joined run without a compile of the task loop: ``--then end``, ``sleep`` or ``gather``."""


def _join(port: int, n: int, pid: int, then: str, timeout: str = "60") -> subprocess.Popen:
    where = ["--coordinator", f"127.0.0.1:{port}", "--num-processes", str(n)]
    return _python("-c", JOIN, "--then", then, *where, "--process-id", str(pid), "--timeout-s",
                   timeout)  # fmt: skip


def _srun(port: int, tasks: int, task: int, **only: str) -> subprocess.Popen:
    """A JOIN process with ``--coordinator auto`` and the variables srun gives task ``task`` of
    ``tasks`` on one node (or ``only`` those), JAX's coordinator at ``port``."""
    env = dict(
        SLURM_JOB_ID="4242",
        SLURM_STEP_NODELIST="localhost",
        SLURM_NTASKS=str(tasks),
        SLURM_PROCID=str(task),
        SLURM_LOCALID=str(task),
        JAX_COORDINATOR_PORT=str(port),
    )
    return _python("-c", JOIN, "--then", "end", "--coordinator", "auto", *LONG,
                   cluster=only or env)  # fmt: skip


def _joined(tmp: Path, name: str, port: int, n: int, pid: int, *more: str) -> subprocess.Popen:
    where = ["--coordinator", f"127.0.0.1:{port}", "--num-processes", str(n)]
    return _start(tmp / f"{name}.json", *where, "--process-id", str(pid), "--timeout-s", "4",
                  *more)  # fmt: skip


def _read_until(proc: subprocess.Popen, text: str) -> str:
    """``proc``'s stderr up to the first line holding ``text`` (or its end)."""
    seen = ""
    for line in iter(proc.stderr.readline, ""):
        seen += line
        if text in line:
            break
    return seen


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Every process of the file at once: ``(tmp, {name: (returncode, stderr)})``."""
    tmp = tmp_path_factory.mktemp("dist")
    pair, late, quiet, gloo, nobody, alone, mismatch, taken, twice, stop, srun = _free_ports(11)
    holder = socket.create_server(("", taken))  # another program holds process 0's port
    procs = {
        "alone": _start(tmp / "alone.json"),
        "p0": _joined(tmp, "p0", pair, 2, 0, *LONG),
        "p1": _joined(tmp, "p1", pair, 2, 1, *LONG),
        # Process 0 waits 8 s at most for the others (they wait 60), so it judges a process
        # lost after 10 s of silence (its watchdog); with 60 s, only gloo's error comes in time.
        "late0": _join(late, 2, 0, "end", "8"),
        "late1": _join(late, 2, 1, "end"),
        **{f"quiet{i}": _join(quiet, 3, i, "sleep", "8" if i == 0 else "60") for i in range(3)},
        **{f"gloo{i}": _join(gloo, 2, i, "gather") for i in range(2)},
        # Two tasks of one srun step, and a process with the job's id alone (no srun).
        **{f"srun{i}": _srun(srun, 2, i) for i in range(2)},
        "no_srun": _srun(srun, 2, 0, SLURM_JOB_ID="4242"),
        "unreachable": _joined(tmp, "unreachable", nobody, 2, 1),
        "alone0": _joined(tmp, "alone0", alone, 2, 0),
        "mismatch0": _joined(tmp, "mismatch0", mismatch, 2, 0, "--trials", "4", *LONG),
        "mismatch1": _joined(tmp, "mismatch1", mismatch, 3, 1, "--trials", "6", *LONG),
        "taken": _joined(tmp, "taken", taken, 2, 0),
        "interrupted": _joined(tmp, "interrupted", stop, 2, 1, *LONG),
        # Two processes say they are process 0 of 3 and two claim id 1: one of each is refused,
        # and Ctrl-C ends the two that wait for id 2.
        **{f"twice{i}": _joined(tmp, f"twice{i}", twice, 3, pid, *LONG)
           for i, pid in enumerate((0, 0, 1, 1))},
    }  # fmt: skip
    # Once joined, quiet1 gets SIGTERM (JAX's own handler must not be installed) and quiet2
    # SIGKILL; gloo1 SIGKILL once it has gathered: their processes 0 must notice.
    said = {
        name: _read_until(procs[name], text)
        for name, text in (
            ("quiet1", "joined the run"),
            ("quiet2", "joined the run"),
            ("gloo1", "gathered"),
        )
    }
    procs["quiet1"].send_signal(signal.SIGTERM)
    procs["quiet2"].kill()
    procs["gloo1"].kill()
    # Ctrl-C once the process says it is waiting (no sooner: the line proves where it was).
    said["interrupted"] = _read_until(procs["interrupted"], "waiting for")
    procs["interrupted"].send_signal(signal.SIGINT)
    waiting = [f"twice{i}" for i in range(4)]
    deadline = time.monotonic() + 120
    while sum(procs[n].poll() is None for n in waiting) > 2 and time.monotonic() < deadline:
        time.sleep(0.2)
    for name in waiting:
        if procs[name].poll() is None:
            procs[name].send_signal(signal.SIGINT)
    done = {name: p.communicate(timeout=600) for name, p in procs.items()}
    holder.close()
    return tmp, {name: (p.returncode, said.get(name, "") + done[name][1])
                 for name, p in procs.items()}  # fmt: skip


def _one_line(runs, name: str, status: int = 2) -> str:
    """The error line of run ``name``: its only one, the last on stderr, and no traceback."""
    code, err = runs[1][name]
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == status and "Traceback" not in err, (name, code, err[-3000:])
    assert [line for line in lines if "error:" in line] == lines[-1:], (name, err[-3000:])
    return lines[-1]


@pytest.mark.slow
def test_two_processes_give_one_processs_trials_bit_for_bit(runs):
    alone = json.loads((runs[0] / "alone.json").read_text())
    joined = json.loads((runs[0] / "p0.json").read_text())
    assert len(alone["trials"]) == 3
    assert joined["trials"] == alone["trials"] and joined["summary"] == alone["summary"]


@pytest.mark.slow
def test_both_processes_of_a_joined_run_exit_0_without_an_abort(runs):
    for name in ("alone", "p0", "p1"):
        code, err = runs[1][name]
        assert code == 0 and "Traceback" not in err and "Check failure" not in err, (name, err)
    assert "joined the run at 127.0.0.1:" in runs[1]["p1"][1]


@pytest.mark.slow
def test_a_process_that_ends_first_waits_for_the_others_without_a_loss(runs):
    for name in ("late0", "late1"):
        code, err = runs[1][name]
        assert code == 0 and "error" not in err and "Check failure" not in err, (name, err)


@pytest.mark.slow
def test_srun_tasks_join_with_coordinator_auto(runs):
    # Two tasks on one node as srun starts them: JAX's SlurmCluster gives the address
    # (the first node, JAX_COORDINATOR_PORT), the count and the ids.
    for i in range(2):
        code, err = runs[1][f"srun{i}"]
        assert code == 0 and "Check failure" not in err, (i, err)
        assert re.search(rf"^joined the run at localhost:\d+ as process {i} of 2$", err, re.M), err
    line = _one_line(runs, "no_srun")
    assert "SlurmCluster needs each of" in line and "$SLURM_STEP_NODELIST are not set" in line


@pytest.mark.slow
def test_only_process_0_writes(runs):
    assert (runs[0] / "p0.json").is_file()
    assert not (runs[0] / "p1.json").exists()


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
        (["--coordinator", "auto"], "none of JAX's clusters is detected"),
    ],
)
def test_inconsistent_flags_are_rejected(flags, message, monkeypatch):
    for name in [v for v in os.environ if v.startswith(CLUSTER_VARS)]:
        monkeypatch.delenv(name)
    parser = argparse.ArgumentParser()
    distributed.add_arguments(parser)
    with pytest.raises(ValueError, match=message.replace("[", r"\[").replace(")", r"\)")):
        distributed.check(parser.parse_args(flags))


SLURM = ("SLURM_JOB_ID", "SLURM_LOCALID", "SLURM_NTASKS", "SLURM_PROCID", "SLURM_STEP_NODELIST")
"""What JAX's SlurmCluster.is_env_present reads (jax/_src/clusters/slurm_cluster.py)."""


def test_coordinator_auto_is_jaxs_own_detection(monkeypatch):
    from jax._src import clusters

    for name in [v for v in os.environ if v.startswith(CLUSTER_VARS)]:
        monkeypatch.delenv(name)
    assert distributed.variables(clusters.SlurmCluster) == SLURM
    assert distributed.variables(clusters.OmpiCluster) == ("OMPI_MCA_orte_hnp_uri",)
    assert distributed.variables(clusters.K8sCluster) == ()  # it asks Kubernetes' API
    assert not any(v in os.environ for v in SLURM)  # the probe left the environment as it was
    args = argparse.Namespace(coordinator="auto", timeout_s=60.0)
    # Only the job's id (a script run by sbatch without srun): JAX would wait, then fail with
    # "coordinator_address should be defined."; here one line names what is missing, at once.
    monkeypatch.setenv("SLURM_JOB_ID", "7")
    with pytest.raises(ValueError) as info:
        distributed.check(args)
    assert str(info.value) == (
        "--coordinator auto: JAX's SlurmCluster needs each of $SLURM_JOB_ID, $SLURM_LOCALID, "
        "$SLURM_NTASKS, $SLURM_PROCID, $SLURM_STEP_NODELIST; $SLURM_LOCALID, $SLURM_NTASKS, "
        "$SLURM_PROCID, $SLURM_STEP_NODELIST are not set: start each process with srun (inside "
        "an sbatch script too), or give --coordinator HOST:PORT --num-processes N --process-id I"
    )
    for name in SLURM:
        monkeypatch.setenv(name, "0")
    assert distributed.detect() is clusters.SlurmCluster and clusters.SlurmCluster.is_env_present()
    distributed.check(args)
    monkeypatch.delenv("SLURM_JOB_ID")
    monkeypatch.setenv("OMPI_COMM_WORLD_SIZE", "2")  # the more nearly set cluster is named
    with pytest.raises(ValueError, match=r"SlurmCluster .*; \$SLURM_JOB_ID is not set"):
        distributed.check(args)
    # Kubernetes without the kubernetes package: JAX's multi-line warning, as one clause.
    for name in SLURM[1:]:
        monkeypatch.delenv(name)
    monkeypatch.setenv("KUBERNETES_SERVICE_HOST", "10.0.0.1")
    with pytest.raises(ValueError, match="OmpiCluster needs each of") as info:
        distributed.check(args)
    monkeypatch.delenv("OMPI_COMM_WORLD_SIZE")
    with pytest.raises(ValueError, match=r"\(Kubernetes environment detected, but the") as info:
        distributed.check(args)
    assert "\n" not in str(info.value)


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


@pytest.mark.slow
def test_an_unreachable_coordinator_is_one_line_after_the_timeout(runs):
    line = _one_line(runs, "unreachable")
    assert line.startswith("trials.py: error: no coordinator answers at 127.0.0.1:")
    assert "Connection refused" in line and "start process 0" in line
    assert re.search(r"^waiting for 1 of 2 processes at 127\.0\.0\.1:\d+ \(\d+ s of 4\)$",
                     runs[1]["unreachable"][1], re.M)  # fmt: skip


@pytest.mark.slow
def test_process_0_alone_says_who_is_missing(runs):
    line = _one_line(runs, "alone0")
    assert "not every process joined at 127.0.0.1:" in line and "within 4 s" in line
    assert "each with its own --process-id" in line


@pytest.mark.slow
def test_processes_started_with_different_flags_name_them(runs):
    zero, one = _one_line(runs, "mismatch0"), _one_line(runs, "mismatch1")
    assert zero == (
        "trials.py: error: process 1 was started with --num-processes 3, --trials 6 and this "
        "one (0) with --num-processes 2, --trials 4: start every process with the same flags"
    )
    assert "process 0 was started with --num-processes 2, --trials 4 and this one (1)" in one


@pytest.mark.slow
def test_a_taken_coordinator_port_is_one_line(runs):
    line = _one_line(runs, "taken")
    assert "cannot host the coordinator at 127.0.0.1:" in line and "holds the port" in line


@pytest.mark.slow
def test_an_id_taken_twice_is_one_line_for_each_process(runs):
    """Two processes 0 and two processes 1 (of 3): one of each is refused at once, without the
    abort XLA gives a second connection of one id; the others wait until Ctrl-C."""
    results = {name: runs[1][name] for name in ("twice0", "twice1", "twice2", "twice3")}
    refused = sorted(name for name, (code, _) in results.items() if code == 2)
    assert len(refused) == 2 and refused[0] in ("twice0", "twice1"), results
    assert "cannot host the coordinator" in _one_line(runs, refused[0])
    assert _one_line(runs, refused[1]) == (
        "trials.py: error: --process-id 1 is already taken in the run of 3 processes: give "
        "each process its own --process-id, 0 .. --num-processes - 1"
    )
    for name in sorted(set(results) - set(refused)):
        assert _one_line(runs, name, 130) == "trials.py: error: interrupted"


@pytest.mark.slow
def test_sigterm_stops_a_joined_process(runs):
    assert _one_line(runs, "quiet1", 143) == "join.py: error: terminated"


@pytest.mark.slow
def test_a_process_killed_mid_run_ends_the_others_with_one_line(runs):
    """kill -9 (and SIGTERM) of processes 1 and 2 of 3: process 0 says so within 10 s of
    silence, or at once from gloo's error in a collective, instead of XLA's abort. Which comes
    first in the collective depends on the machine's load: either is the one line."""
    assert re.fullmatch(
        r"join\.py: error: process [12] of 3 stopped responding \(killed, or its machine is "
        r"unreachable\); nothing half-written is left: rerun all 3 processes",
        _one_line(runs, "quiet0"),
    )
    assert runs[1]["quiet2"][0] == -signal.SIGKILL and runs[1]["gloo1"][0] == -signal.SIGKILL
    assert re.fullmatch(
        r"join\.py: error: process 1 of 2 stopped responding \(killed, or its machine is "
        r"unreachable\); nothing half-written is left: rerun all 2 processes( \(.*gloo.*\))?",
        _one_line(runs, "gloo0"),
        re.IGNORECASE,
    )


@pytest.mark.slow
def test_ctrl_c_while_waiting_is_honoured(runs):
    assert runs[1]["interrupted"][1].startswith("waiting for 1 of 2 processes")
    assert _one_line(runs, "interrupted", 130) == "trials.py: error: interrupted"
