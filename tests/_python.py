"""Python snippets run in a fresh interpreter: for what one test process cannot show (what an
import loads, how a process exits, what it leaves on stderr)."""

from __future__ import annotations

import os
import subprocess
import sys


def run_python(
    code: str, env: dict[str, str] | None = None, timeout: float = 120
) -> subprocess.CompletedProcess:
    """Run ``code`` with this interpreter and capture its output as text.

    Args:
        env: the environment (default: this process's, with JAX on the CPU).
    """
    env = {**os.environ, "JAX_PLATFORMS": "cpu"} if env is None else env
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=timeout
    )
