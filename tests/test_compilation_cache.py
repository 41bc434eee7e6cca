"""Where the scripts' persistent compilation cache lives, and how it is turned off."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from _python import run_python

from jaxais import compilation_cache as cc


def test_default_is_under_the_user_cache_home(tmp_path: Path):
    assert cc.resolve({"XDG_CACHE_HOME": str(tmp_path)}) == tmp_path / "jaxais" / "xla"
    assert cc.resolve({}) == Path("~").expanduser() / ".cache" / "jaxais" / "xla"


def test_our_variable_names_the_directory_or_turns_it_off(tmp_path: Path):
    assert cc.resolve({cc.ENV: str(tmp_path / "c"), "XDG_CACHE_HOME": "/x"}) == tmp_path / "c"
    for off in ("off", "OFF", "", "0", "none"):
        assert cc.resolve({cc.ENV: off}) is None
        assert cc.enable({cc.ENV: off}) is None


def test_jax_own_setting_wins(tmp_path: Path):
    env = {cc.JAX_ENV: str(tmp_path / "jax"), cc.ENV: str(tmp_path / "ours")}
    assert cc.resolve(env) is None
    assert cc.enable(env) == str(tmp_path / "jax")
    assert not (tmp_path / "ours").exists()


def test_unwritable_directory_warns_and_runs_on(tmp_path: Path, capsys: pytest.CaptureFixture):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    assert cc.enable({cc.ENV: str(blocker / "cache")}) is None
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("warning: no compilation cache")
    assert cc.ENV in err[0]


def test_enable_stores_compiled_programs(tmp_path: Path):
    # A fresh process: JAX initialises its cache once, at the first compile.
    code = (
        "import jax, jax.numpy as jnp\n"
        "from jaxais import compilation_cache as cc\n"
        "print(cc.enable())\n"
        "jax.config.update('jax_persistent_cache_min_compile_time_secs', 0)\n"
        "jax.jit(lambda x: jnp.sin(x) * 2)(jnp.ones(3)).block_until_ready()\n"
    )
    env = {**os.environ, cc.ENV: str(tmp_path / "xla")}
    env.pop(cc.JAX_ENV, None)
    out = run_python(code, env)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == str(tmp_path / "xla")
    assert any(p.name.startswith("jit_") for p in (tmp_path / "xla").iterdir())
