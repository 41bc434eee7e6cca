"""Runs across processes (``jaxais.distributed``): two CPU processes on localhost, joined by
``jax.distributed``, give the results of one process bit for bit.

The test starts three ``scripts/sweep.py`` runs (one alone, two joined over a loopback port) on
a tiny grid and three ``scripts/trials.py`` runs likewise, all at once, so the whole module costs
about one compile's wall time.
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from jaxais import distributed

ROOT = Path(__file__).resolve().parent.parent
ARGS = ["--grid", "k1=0.85,1.6", "--grid", "k2=1.1", "--trials", "3", "--tau-cap", "8"]
TRIALS = ["--system", "HDC", "--trials", "3", "--tau-cap", "8"]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _start(out: Path, *extra: str, script: str = "sweep.py") -> subprocess.Popen:
    env = {**os.environ, "JAXAIS_DEBUG": ""}
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
    for script, prefix, out in (("sweep.py", "", ""), ("trials.py", "trials_", ".json")):
        joined = ["--coordinator", f"127.0.0.1:{_free_port()}", "--num-processes", "2"]
        procs |= {
            f"{prefix}alone": _start(tmp / f"{prefix}alone{out}", script=script),
            f"{prefix}p0": _start(tmp / f"{prefix}p0{out}", *joined, "--process-id", "0",
                                  script=script),
            f"{prefix}p1": _start(tmp / f"{prefix}p1{out}", *joined, "--process-id", "1",
                                  script=script),
        }  # fmt: skip
    done = {name: p.communicate(timeout=480) for name, p in procs.items()}
    for name, p in procs.items():
        assert p.returncode == 0, (name, done[name][1][-3000:])
    return tmp


def test_two_processes_give_one_processs_results_bit_for_bit(runs):
    alone = json.loads((runs / "alone" / "sweep.json").read_text())
    joined = json.loads((runs / "p0" / "sweep.json").read_text())
    assert joined["config"]["processes"] == 2 and alone["config"]["processes"] == 1
    assert joined["config"]["devices"] == 2 * alone["config"]["devices"]
    assert joined["points"] == alone["points"]  # every mean and interval, exactly
    assert joined["robot_iterations"] == alone["robot_iterations"]


def test_only_process_0_writes(runs):
    assert (runs / "p0" / "sweep.json").is_file()
    assert not (runs / "p1" / "sweep.json").exists()
    assert (runs / "trials_p0.json").is_file()
    assert not (runs / "trials_p1.json").exists()


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
    ],
)
def test_inconsistent_flags_are_rejected(flags, message):
    parser = argparse.ArgumentParser()
    distributed.add_arguments(parser)
    with pytest.raises(ValueError, match=message.replace("[", r"\[").replace(")", r"\)")):
        distributed.check(parser.parse_args(flags))


def test_environment_variables_give_the_defaults(monkeypatch):
    monkeypatch.setenv("JAXAIS_COORDINATOR", "10.0.0.1:1234")
    monkeypatch.setenv("JAXAIS_NUM_PROCESSES", "4")
    monkeypatch.setenv("JAXAIS_PROCESS_ID", "3")
    parser = argparse.ArgumentParser()
    distributed.add_arguments(parser)
    args = parser.parse_args([])
    assert (args.coordinator, args.num_processes, args.process_id) == ("10.0.0.1:1234", 4, 3)
    distributed.check(args)  # consistent
    monkeypatch.setenv("JAXAIS_PROCESS_ID", "three")
    with pytest.raises(ValueError, match="JAXAIS_PROCESS_ID must be an integer"):
        distributed.add_arguments(argparse.ArgumentParser())
