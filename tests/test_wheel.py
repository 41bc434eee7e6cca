"""The package as a user installs it: a wheel in a fresh virtual environment, run from elsewhere.

The wheel is built from a copy of the working tree without build isolation (the test venv has
setuptools and wheel: the ``test`` extra) and installed with ``--no-deps`` into a new venv, which
borrows this venv's dependencies through a ``.pth`` file naming its site-packages: a plain path
line adds that folder without running its ``.pth`` files, so the checkout's editable jaxais there
stays out of the way. The console scripts then run from a temporary folder outside the checkout.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import sysconfig
import tomllib
import venv
from pathlib import Path

import pytest
from _python import script_env

ROOT = Path(__file__).resolve().parent.parent
CONSOLE = {"jaxais-evolve", "jaxais-trials", "jaxais-reproduce", "jaxais-sweep", "jaxais-ablate"}


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fresh venv with the wheel installed; returns its bin folder."""
    base = tmp_path_factory.mktemp("wheel")
    # A copy of the working tree: setuptools builds in the tree's build/, whose leftovers (a
    # module since deleted) would go into the wheel.
    skip = shutil.ignore_patterns(".*", "build", "dist", "*.egg-info", "__pycache__")
    shutil.copytree(ROOT, base / "src", ignore=skip)
    build = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
         "-w", str(base / "dist"), str(base / "src")],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert build.returncode == 0, build.stderr[-3000:]
    (wheel,) = (base / "dist").glob("jaxais-*.whl")
    venv.create(base / "venv", with_pip=False)
    bin_dir = base / "venv" / "bin"
    fresh = subprocess.run(
        [bin_dir / "python", "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
        capture_output=True, text=True, check=True,
    ).stdout.strip()  # fmt: skip
    Path(fresh, "deps.pth").write_text(sysconfig.get_path("purelib") + "\n")
    install = subprocess.run(
        [sys.executable, "-m", "pip", "--python", bin_dir / "python", "install", "--no-deps",
         "-q", str(wheel)],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert install.returncode == 0, install.stderr[-3000:]
    return bin_dir


def _start(bin_dir: Path, cwd: Path, *args: object) -> subprocess.Popen:
    env = {k: v for k, v in script_env().items() if k != "PYTHONPATH"}
    return subprocess.Popen(
        [str(a) for a in args], cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True, env={**env, "JAXAIS_CACHE_DIR": "off", "PATH": f"{bin_dir}:{env['PATH']}"},
    )  # fmt: skip


def _finish(proc: subprocess.Popen) -> subprocess.CompletedProcess:
    out, err = proc.communicate(timeout=300)
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


def test_console_scripts_are_the_packages_scripts():
    table = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert set(table) == CONSOLE
    for name, target in table.items():
        module, func = target.split(":")
        assert (module, func) == (f"jaxais.scripts.{name.removeprefix('jaxais-')}", "main")
        assert (ROOT / "scripts" / f"{module.rsplit('.', 1)[1]}.py").is_file()


@pytest.mark.slow
def test_the_wheels_console_scripts_run_outside_the_checkout(installed, tmp_path):
    # All at once: the tiny run's JAX start-up and compile take the time.
    trials = installed / "jaxais-trials"
    run = _start(installed, tmp_path, trials, "--system", "HDC", "--trials", 2, "--tau-cap", 2,
                 "--out", "r.json")  # fmt: skip
    code = "import jaxais, jaxais.scripts.trials as t; print(jaxais.__file__, t.__file__)"
    where = _start(installed, tmp_path, installed / "python", "-c", code)
    usage = {name: _start(installed, tmp_path, installed / name, "--help") for name in CONSOLE}
    bad = _start(installed, tmp_path, trials, "--system", "HDC", "--trials", 0, "--out", "x.json")
    where = _finish(where)
    assert where.returncode == 0, where.stderr
    assert all(str(installed.parent) in f for f in where.stdout.split()), where.stdout
    for name, proc in usage.items():
        done = _finish(proc)
        assert done.returncode == 0, (name, done.stderr)
        assert f"usage: {name.removeprefix('jaxais-')}.py" in done.stdout
    bad = _finish(bad)
    assert bad.returncode == 2 and bad.stderr == "trials.py: error: --trials must be >= 1, got 0\n"
    run = _finish(run)
    assert run.returncode == 0, run.stderr[-3000:]
    assert "HDC in world1: 2 trials" in run.stdout
    doc = json.loads((tmp_path / "r.json").read_text())
    assert (doc["label"], len(doc["trials"])) == ("HDC", 2)
    assert doc["config"]["episode"]["tau_cap"] == 2.0
