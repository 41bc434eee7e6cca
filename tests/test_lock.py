"""One writer per output folder (``jaxais.lock``): a live lock refuses in one line and nothing is
written; a stale one (an old heartbeat, or a dead PID on this host) is taken over; the lock goes
when the run completes or the process ends."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from _python import call_main, run_python

from jaxais import io, lock
from jaxais.io import MANIFEST, UserError, open_run

HOST = socket.gethostname()


@pytest.fixture
def sleeper():
    """A live process of this host that is not this one (another writer)."""
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    yield proc.pid
    proc.kill()
    proc.wait()


def dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", ""])
    proc.wait()
    return proc.pid


def plant(folder: Path, **record) -> dict:
    """Write another process's lock into ``folder``."""
    record = {"host": HOST, "pid": 1, "heartbeat": time.time(), "token": "theirs"} | record
    (folder / lock.NAME).write_text(json.dumps(record))
    return record


def partial_run(out: Path) -> bytes:
    """A partial seeds run in ``out`` that its process left (its lock released)."""
    run = open_run(out, "seeds", {"seeds": [0], "trials": 2, "extra_args": []})
    run.lock.release()
    return (out / MANIFEST).read_bytes()


def test_a_live_lock_refuses_the_folder_in_one_line_and_nothing_is_written(tmp_path, sleeper):
    out = tmp_path / "out"
    manifest = partial_run(out)
    for record in ({"pid": sleeper}, {"host": "node-7", "pid": 12, "heartbeat": time.time() - 30}):
        planted = plant(out, **record)
        proc = call_main("seeds.py", "--out", out, "--resume", "--seeds", 1, "--trials", 2)
        assert proc.returncode == 2 and proc.stdout == "", proc
        who = f"PID {planted['pid']} on {planted['host']}, last heartbeat"
        assert proc.stderr.count("\n") == 1, proc.stderr
        assert proc.stderr.startswith(f"seeds.py: error: {out}: another process is writing here "
                                      f"({who}"), proc.stderr  # fmt: skip
        assert f"stale {lock.STALE_S:.0f} s after its last heartbeat" in proc.stderr
        assert sorted(p.name for p in out.iterdir()) == sorted([lock.NAME, MANIFEST])
        assert (out / MANIFEST).read_bytes() == manifest
        assert json.loads((out / lock.NAME).read_text()) == planted  # still theirs
    # A fresh run into a folder another process has just made (no manifest yet) is refused too.
    (out / MANIFEST).unlink()
    with pytest.raises(UserError, match="another process is writing here"):
        open_run(out, "seeds", {})


@pytest.mark.parametrize(
    "record",
    [
        {"host": "node-7", "heartbeat": time.time() - lock.STALE_S - 5},  # preempted elsewhere
        {"pid": "dead"},  # killed on this host: at once, whatever its heartbeat
        {"pid": "mine", "token": "an earlier run of this process that raised"},
        None,  # unreadable (damaged) and old
    ],
    ids=["old heartbeat", "dead pid", "this process", "unreadable"],
)
def test_a_stale_lock_is_taken_over_and_released_when_the_run_completes(tmp_path, record):
    out = tmp_path / "out"
    partial_run(out)
    if record is None:
        (out / lock.NAME).write_text("{")
        old = time.time() - lock.STALE_S - 5
        os.utime(out / lock.NAME, (old, old))
    else:
        if "pid" in record:
            record = record | {"pid": dead_pid() if record["pid"] == "dead" else os.getpid()}
        plant(out, **record)
    run = open_run(out, "seeds", {"seeds": [0], "trials": 2, "extra_args": []}, resume=True)
    held = json.loads((out / lock.NAME).read_text())
    assert (held["host"], held["pid"], held["token"]) == (HOST, os.getpid(), run.lock.token)
    assert held["stale_after_s"] == lock.STALE_S == 3 * lock.HEARTBEAT_S
    assert not [p for p in out.iterdir() if ".stale." in p.name]
    run.complete()
    assert not (out / lock.NAME).exists()


def test_the_heartbeat_refreshes_the_lock_and_stops_when_it_was_taken_over(
    tmp_path, monkeypatch, capsys
):
    monkeypatch.setattr(lock, "HEARTBEAT_S", 0.05)
    held = lock.acquire(tmp_path)
    first = json.loads(held.path.read_text())["heartbeat"]
    deadline = time.monotonic() + 10
    while json.loads(held.path.read_text())["heartbeat"] == first:
        assert time.monotonic() < deadline, "no heartbeat"
        time.sleep(0.02)
    assert held.path in io.IN_FLIGHT  # what the scripts' signal handler removes
    plant(tmp_path)  # another process judged it stale (this one was stopped) and took it
    held._thread.join(timeout=10)
    assert not held._thread.is_alive() and held.path not in io.IN_FLIGHT
    assert "lock taken over by another process" in capsys.readouterr().err
    held.release()  # leaves the new holder's lock alone
    assert json.loads(held.path.read_text())["token"] == "theirs"


def test_the_lock_goes_when_the_process_exits(tmp_path):
    code = f"from jaxais.io import open_run; open_run({str(tmp_path)!r}, 'sweep', {{}})"
    proc = run_python(code)
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == [MANIFEST]


def test_evolves_checkpoints_are_locked_by_their_writer(tmp_path, sleeper):
    from jaxais.checkpointing import GACheckpointer

    ck = tmp_path / "checkpoints"
    ck.mkdir()
    plant(ck, pid=sleeper)
    for resume in (True, False):
        with pytest.raises(UserError, match=f"{ck}: another process is writing here"):
            GACheckpointer(ck, {"seed": 0}, resume=resume)
    assert sorted(p.name for p in ck.iterdir()) == [lock.NAME]
    (ck / lock.NAME).unlink()
    with GACheckpointer(ck, {"seed": 0}, resume=False):
        assert json.loads((ck / lock.NAME).read_text())["pid"] == os.getpid()
    assert not (ck / lock.NAME).exists()


def test_a_driver_that_raises_gives_up_its_folders_lock(tmp_path):
    """A notebook's failed or interrupted call does not keep the folder from a later --resume."""
    from jaxais.experiments.seeds import ltl_ledger

    def fails(cmd, log):
        raise RuntimeError("the LTL broke")

    with pytest.raises(RuntimeError, match="the LTL broke"):
        ltl_ledger(tmp_path, [0], trials=2, jobs=1, runner=fails, progress=False)
    assert (tmp_path / MANIFEST).exists() and not (tmp_path / lock.NAME).exists()
    (tmp_path / "ltl").mkdir()
    outer = lock.acquire(tmp_path / "ltl")  # a lock taken before the call is the caller's
    with pytest.raises(RuntimeError):
        ltl_ledger(tmp_path, [0], trials=2, jobs=1, runner=fails, progress=False, resume=True)
    assert outer.ours()
    outer.release()
