"""Python snippets run in a fresh interpreter: for what one test process cannot show (what an
import loads, how a process exits, what it leaves on stderr)."""

from __future__ import annotations

import contextlib
import importlib
import io
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
TEST_XLA_FLAGS = "--xla_backend_optimization_level=0"
"""What every test program compiles with (tests/conftest.py): LLVM's optimisations off."""
OPTIMISED = {"xla_backend_optimization_level": 3}
"""``jax.jit(f, compiler_options=OPTIMISED)``: LLVM's optimisations back on (XLA's default) for
a program a test runs so long that its unoptimised code would cost more than compiling saves."""


def script_env() -> dict[str, str]:
    """This process's environment with the tests' XLA flag alone in ``XLA_FLAGS``: a script adds
    its own flags to a user's."""
    return os.environ | {"XLA_FLAGS": TEST_XLA_FLAGS}


def shipped_env() -> dict[str, str]:
    """This process's environment without the tests' XLA flags (tests/conftest.py): a fresh
    interpreter then compiles as a user's session does (a script adds its own flags)."""
    return {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"} | {"JAX_PLATFORMS": "cpu"}


def run_python(
    code: str, env: dict[str, str] | None = None, timeout: float = 120
) -> subprocess.CompletedProcess:
    """Run ``code`` with this interpreter and capture its output as text.

    Args:
        env: the environment (default: this process's, with JAX on the CPU and the tests' XLA
            flags).
    """
    env = {**os.environ, "JAX_PLATFORMS": "cpu"} if env is None else env
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=timeout
    )


def call_main(script: str, *args: object) -> subprocess.CompletedProcess:
    """``jaxais.scripts.{script}``'s ``main(args)`` in this process, with its exit status, stdout
    and stderr as :func:`start_script`'s process would give them: for mistakes a script answers
    after JAX has loaded, which a fresh interpreter spends a second or two reaching. (The XLA
    flags the script adds to ``os.environ`` are undone after the test: tests/conftest.py.)"""
    module = importlib.import_module(f"jaxais.scripts.{script.removesuffix('.py')}")
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            module.main([str(a) for a in args])
            status = 0
        except SystemExit as exit:
            status = exit.code
    return subprocess.CompletedProcess([script, *args], status, out.getvalue(), err.getvalue())


def start_script(script: str, *args: object, **env: str) -> subprocess.Popen:
    """Start ``scripts/{script}`` with ``args`` from the repository root, its output captured as
    text, in this process's environment with ``env`` on top: the tests' XLA flag alone in
    ``XLA_FLAGS`` (a script adds its own to a user's), one-line errors (``JAXAIS_DEBUG`` off)."""
    base = script_env()
    return subprocess.Popen(
        [sys.executable, f"scripts/{script}", *map(str, args)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**base, "JAXAIS_DEBUG": "", **env},
    )
