"""The package's public face and its import discipline."""

from __future__ import annotations

import subprocess
import sys

import pytest

import jaxais


@pytest.mark.parametrize("name", sorted(set(jaxais.__all__) - {"__version__"}))
def test_public_names_resolve(name):
    assert getattr(jaxais, name) is not None


def test_unknown_attribute_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'no_such_thing'"):
        _ = jaxais.no_such_thing


def test_cli_and_package_import_leave_jax_unloaded():
    # Scripts parse flags and may set XLA_FLAGS before JAX starts: importing jaxais.cli must not
    # import JAX.
    code = "import sys, jaxais, jaxais.cli; print('jax' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
