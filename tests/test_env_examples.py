"""The gymnax examples run at tiny budgets, as a user runs them (``python examples/NAME.py
--tiny``): examples/gymnax_ppo.py (PureJaxRL's PPO), examples/evosax_policy.py (evosax's
OpenAI-ES through its GymnaxProblem) and examples/rejax_ppo.py (rejax's PPO), third-party training
code on ``gymnax.make("jaxais/world1")``.

All run in one fresh interpreter with the tests' XLA flags (tests/conftest.py): each compiles its
whole training run once, which is most of its time.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from _python import run_python

pytestmark = pytest.mark.slow  # each test reads the one run of all three
EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


@pytest.fixture(scope="module")
def output() -> str:
    code = (
        "import runpy, sys\n"
        "for name in ('gymnax_ppo', 'evosax_policy', 'rejax_ppo'):\n"
        "    sys.argv = [name, '--tiny']\n"
        f"    runpy.run_path(f'{EXAMPLES}/{{name}}.py', run_name='__main__')\n"
    )
    proc = run_python(code, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return proc.stdout


def test_purejaxrl_style_ppo_trains_on_gymnax_make(output):
    # 256 steps of 4 envs in 2 updates, episodes of at most 16 steps: at least 16 ended, and
    # gymnax's LogWrapper saw them through the auto-reset.
    found = re.search(
        r"^PPO on jaxais/world1: 2 updates, (\d+) episodes, mean return (\S+), last loss (\S+)$",
        output,
        re.MULTILINE,
    )
    assert found, output
    assert int(found[1]) >= 16 and np.isfinite(float(found[2])) and np.isfinite(float(found[3]))


def test_evosax_evolves_a_policy_on_gymnax_make(output):
    found = re.search(
        r"^OpenES on jaxais/world1: 3 generations of 4, mean return (\S+) -> (\S+)$",
        output,
        re.MULTILINE,
    )
    assert found, output
    assert np.isfinite(float(found[1])) and np.isfinite(float(found[2]))


def test_rejax_ppo_trains_on_gymnax_make(output):
    # 128 steps in 64-step evaluation periods: evaluations before, after 64 and after 128 steps.
    found = re.search(
        r"^rejax PPO on world1: 3 evaluations, mean return (\S+) -> (\S+)$", output, re.MULTILINE
    )
    assert found, output
    assert np.isfinite(float(found[1])) and np.isfinite(float(found[2]))
