"""I/O errors name their file in one line (``jaxais.io.atomic_write``, ``jaxais.cli``), and JAX's
persistent-cache warnings are one line (``jaxais._speed``)."""

from __future__ import annotations

import errno
import os

import pytest
from _python import run_python

from jaxais import _speed
from jaxais.cli import error_message
from jaxais.io import atomic_write

FILE_TOO_LARGE = """
import resource, signal, sys
from jaxais.cli import main_wrapper, run_script
from jaxais.io import atomic_write_text

signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG instead
resource.setrlimit(resource.RLIMIT_FSIZE, (1000, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))

@main_wrapper("t.py")
def main():
    atomic_write_text(sys.argv[1], "x" * 5000)

run_script(main)
"""


def test_a_file_too_large_names_the_file_in_one_line_and_leaves_nothing(tmp_path):
    out = tmp_path / "results.json"
    proc = run_python(FILE_TOO_LARGE.replace("sys.argv[1]", repr(str(out))))
    assert (proc.returncode, proc.stderr) == (2, f"t.py: error: {out}: File too large\n")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EFBIG, errno.EIO])
def test_a_write_error_without_a_file_names_the_target(tmp_path, code):
    dest = tmp_path / "out.npz"

    def full(tmp):
        tmp.write_bytes(b"partial")
        raise OSError(code, os.strerror(code))  # as os.write on a full disk: no file named

    with pytest.raises(OSError) as err:
        atomic_write(dest, full)
    assert err.value.errno == code and error_message(err.value) == f"{dest}: {os.strerror(code)}"
    assert list(tmp_path.iterdir()) == []
    dest.write_text("kept")  # a file already there survives a failed rewrite
    with pytest.raises(OSError, match=f"{os.strerror(code)}: '{dest}'"):
        atomic_write(dest, full)
    assert dest.read_text() == "kept"


def test_an_unusable_cache_folder_turns_the_cache_off_in_one_line(tmp_path, capsys):
    (tmp_path / "file").write_text("")
    assert not _speed._usable(str(tmp_path / "file" / "xla"))
    assert capsys.readouterr().err == (
        f"jaxais: warning: compilation cache off: {tmp_path / 'file' / 'xla'}: Not a directory "
        f"(set {_speed.CACHE_ENV} to a writable folder, or to off)\n"
    )
    assert _speed._usable(str(tmp_path / "made" / "xla")) and (tmp_path / "made" / "xla").is_dir()
    assert capsys.readouterr().err == ""


LOST_CACHE = """
import os, shutil, sys
os.environ["JAXAIS_CACHE_DIR"] = sys.argv[1]
from jaxais import _speed
_speed.setup()
shutil.rmtree(sys.argv[1]); open(sys.argv[1], "w").close()  # the folder is gone mid-run
import jax, jax.numpy as jnp
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0)
print(jax.jit(lambda x: x * 2)(jnp.ones(2)), jax.jit(lambda x: x * 3)(jnp.ones(2)))
"""


def test_jaxs_cache_warnings_are_one_line_once(tmp_path):
    cache = tmp_path / "cache"
    proc = run_python(LOST_CACHE.replace("sys.argv[1]", repr(str(cache))))
    assert proc.returncode == 0 and proc.stdout == "[2. 2.] [3. 3.]\n", proc.stderr
    line = "jaxais: warning: Error reading persistent compilation cache entry for "
    assert proc.stderr.startswith(line) and proc.stderr.count("\n") == 1, proc.stderr
    assert proc.stderr.endswith(f"{_speed.CACHE_ENV}=off turns it off)\n"), proc.stderr
    # Other warnings pass as they were.
    show = _speed._one_line_cache_warnings(lambda *a: seen.append(str(a[0])))
    seen: list[str] = []
    show(UserWarning("another warning"), UserWarning, "f.py", 1)
    assert seen == ["another warning"]
