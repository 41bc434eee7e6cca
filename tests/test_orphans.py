"""Child processes end with their parent (``jaxais.children``): ``kill -9`` of ``seeds.py`` ends
its ``evolve.py`` child at once; without ``prctl`` the child's own watch ends it; every child a
script starts goes through ``jaxais.children``."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from _python import ROOT, start_script

from jaxais import children, lock

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")


def _stat(pid: int) -> tuple[str, int] | None:
    """(state, parent PID) of ``pid``, or None once it is gone (a zombie is gone)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None
    return None if fields[0] in "ZX" else (fields[0], int(fields[1]))


def _children_of(pid: int, word: str) -> list[int]:
    """The live children of ``pid`` whose command line holds ``word``."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit() and (_stat(int(entry.name)) or ("", 0))[1] == pid:
            try:
                if word in (entry / "cmdline").read_bytes().decode(errors="replace"):
                    found.append(int(entry.name))
            except OSError:
                pass
    return found


def _gone_within(pid: int, seconds: float) -> bool:
    deadline = time.monotonic() + seconds
    while _stat(pid) is not None:
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)
    return True


def test_kill_9_of_seeds_py_ends_its_evolve_child(tmp_path):
    out = tmp_path / "ledger"
    proc = start_script("seeds.py", "--out", out, "--seeds", 1, "--trials", 2, "--jobs", 1)
    deadline, evolve = time.monotonic() + 60, []
    try:
        while not evolve:
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "no evolve.py child"
            evolve = _children_of(proc.pid, "jaxais.scripts.evolve")
            time.sleep(0.05)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
        assert _gone_within(evolve[0], 5), "the evolve.py child outlived its parent's kill -9"
    finally:
        for pid in evolve:
            if _stat(pid) is not None:
                os.kill(pid, signal.SIGKILL)
        proc.kill()
        proc.communicate()
    # The ledger's lock names a dead PID of this host: a --resume takes it over at once.
    held = json.loads((out / lock.NAME).read_text())
    assert held["pid"] == proc.pid and lock.holder(out / lock.NAME, held) is None


CHILD = """
import time
from jaxais.cli import main_wrapper
with main_wrapper("child.py"):
    time.sleep(60)
"""
PARENT = """
import subprocess, sys
from jaxais import children
children._PRCTL = None  # as off Linux: only the child's own watch of its parent is left
child = children.popen([sys.executable, "-c", sys.argv[1]], stdout=subprocess.DEVNULL,
                       stderr=open(sys.argv[2], "w"))
print(child.pid, flush=True)
"""


def test_without_prctl_the_child_ends_itself_when_its_parent_is_gone(tmp_path):
    err = tmp_path / "child.err"
    parent = subprocess.run([sys.executable, "-c", PARENT, CHILD, str(err)], capture_output=True,
                            text=True, timeout=60, cwd=ROOT)  # fmt: skip
    assert parent.returncode == 0, parent.stderr
    pid = int(parent.stdout)
    try:
        assert _gone_within(pid, 10 + children.POLL_S), "the orphan kept running"
    finally:
        if _stat(pid) is not None:
            os.kill(pid, signal.SIGKILL)
    assert err.read_text() == "child.py: error: its parent process ended; stopped\n"


def test_watch_parent_watches_only_a_parent_that_named_itself(monkeypatch):
    monkeypatch.delenv(children.PARENT_ENV, raising=False)
    assert children.watch_parent(lambda: None) is None
    monkeypatch.setenv(children.PARENT_ENV, "not a pid")
    assert children.watch_parent(lambda: None) is None
    with subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"]) as other:
        monkeypatch.setenv(children.PARENT_ENV, str(other.pid))  # alive, not our parent:
        assert children.watch_parent(lambda: None) is None  # inherited from a grandparent
        other.kill()


def test_every_child_process_is_started_through_jaxais_children():
    """No module but jaxais.children starts a process itself (it would outlive a kill -9)."""
    starts = re.compile(r"subprocess\.(Popen|run|call|check_call|check_output)\(|os\.(fork|spawn)")
    sources = [*(ROOT / "jaxais").rglob("*.py"), *(ROOT / "scripts").glob("*.py")]
    offenders = [
        f"{p.relative_to(ROOT)}:{i}"
        for p in sources
        if p.name != "children.py"
        for i, line in enumerate(p.read_text().splitlines(), 1)
        if starts.search(line)
    ]
    assert len(sources) > 40 and offenders == []
