"""Writing files: atomic writes (a file is either its earlier complete self or its new
complete self) and the checks that an output can be written, made before any work.

Every file jaxais writes goes through :func:`atomic_write`: the contents fill a temporary file in
the target's directory, which then replaces the target with :func:`os.replace`. A failed or
interrupted write leaves the earlier file (if any) as it was. The command-line layer
(:mod:`jaxais.cli`) removes the temporary files still in flight when a signal ends a script, after
running :data:`ON_SIGNAL`.

A results folder says what it holds (:func:`open_run`): a complete run, or a partial one whose
finished units ``--resume`` keeps; a run never starts over another one or a user's files.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any


class UserError(ValueError):
    """A mistake by the user (a bad path, flag or argument): one line, exit status 2, from a
    script (:mod:`jaxais.cli`); a ``ValueError`` for a library caller."""


class ArgumentTypeError(UserError, TypeError):
    """An argument of the wrong type: a TypeError, and a UserError like every other bad
    argument, so callers catching ValueError and the scripts see one line too."""


def check_type(value: Any, kind: Any, name: str, what: str, hint: str = "") -> None:
    """:class:`ArgumentTypeError` naming the argument ``name`` unless ``value`` is a ``kind``:
    "``name`` must be ``what``, got <its type> (<a short value>)``hint``"."""
    if not isinstance(value, kind):
        got = type(value).__name__
        if isinstance(value, str | int | float):
            got += f" {value!r:.40}"
        raise ArgumentTypeError(f"{name} must be {what}, got {got}{hint}")


IN_FLIGHT: set[Path] = set()
"""Temporary files being written right now (removed by the CLI's signal handler)."""
ON_SIGNAL: list[Callable[[], object]] = []
"""What must still happen when a signal ends a script at once, newest first (the seed ledger
stops its child processes here); each entry is removed by whoever added it."""


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write(path: str | os.PathLike[str], write_fn: Callable[[Path], Any]) -> Path:
    """Write a file atomically: ``write_fn`` fills a temporary file, which then replaces ``path``.

    The temporary file lies in ``path``'s directory (so the replace is atomic) and keeps
    ``path``'s suffix (matplotlib picks a format from the name). If ``write_fn`` raises, the
    temporary file is removed and ``path`` is untouched. The new file gets the usual permissions
    (0666 less the umask).

    Args:
        path: the destination.
        write_fn: called with the temporary file's path; must write the complete contents there.

    Returns:
        ``path`` as a ``Path``.
    """
    dest = Path(path)
    directory = dest.parent if str(dest.parent) else Path(".")
    fd, tmp_name = tempfile.mkstemp(dir=directory, prefix=f".{dest.name}.", suffix=dest.suffix)
    os.close(fd)
    tmp = Path(tmp_name)
    IN_FLIGHT.add(tmp)
    try:
        write_fn(tmp)
        with open(tmp, "rb+") as f:  # the data is on disk before the rename makes it visible
            os.fsync(f.fileno())
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, dest)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    finally:
        IN_FLIGHT.discard(tmp)
    return dest


def atomic_write_text(path: str | os.PathLike[str], text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_write`)."""
    return atomic_write(path, lambda tmp: tmp.write_text(text, encoding=encoding))


def atomic_write_json(path: str | os.PathLike[str], obj: Any, indent: int | None = 2) -> Path:
    """Write ``obj`` as JSON (plus a final newline) to ``path`` atomically.

    The object is serialised before anything is written, so an unserialisable object leaves no
    file behind. NaN and infinities are refused (they are not JSON): use None instead.
    """
    text = json.dumps(obj, indent=indent, allow_nan=False) + "\n"
    return atomic_write_text(path, text)


def read_json_object(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The JSON object (a dict) in ``path``.

    Raises:
        UserError: one line naming the file: missing, unreadable, not JSON, or not an object.
    """
    p = Path(path)
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except OSError as err:
        raise UserError(f"{p}: {err.strerror or err}") from None
    except ValueError as err:  # UnicodeDecodeError is one
        raise UserError(f"{p}: not JSON ({str(err).splitlines()[0][:100]})") from None
    if not isinstance(doc, dict):
        raise UserError(f"{p}: holds a JSON {type(doc).__name__}, expected an object {{...}}")
    return doc


def check_writable_dir(path: str | os.PathLike[str]) -> Path:
    """Check that ``path`` is an existing directory this process can create files in.

    Args:
        path: the directory ("" means the current directory).

    Returns:
        The directory as a ``Path``.

    Raises:
        UserError: it does not exist, is not a directory, or is not writable.
    """
    d = Path(path) if str(path) else Path(".")
    if not d.exists():
        raise UserError(f"{d}: directory does not exist")
    if not d.is_dir():
        raise UserError(f"{d}: not a directory")
    if not os.access(d, os.W_OK | os.X_OK):
        raise UserError(f"{d}: directory is not writable")
    return d


RUN_BYTES = 8192
"""Host memory a run of the pool keeps until its call ends, about: its parameters (a System,
1.4 kB, held twice while assembled), keys, outcome and trial record with its JSON (measured)."""


def check_memory(count: int, each: int, flag: str) -> None:
    """Refuse, before any work, ``count`` items of ``each`` bytes beyond half this machine's
    memory (a run killed by the kernel says nothing and loses everything).

    Raises:
        UserError: ``"{flag} {count} needs about N GB of memory; this machine has M GB; use
            {flag} <= K"``.
    """
    total = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    if count * each > total // 2:
        raise UserError(
            f"{flag} {count} needs about {count * each / 1e9:.3g} GB of memory; this machine has "
            f"{total / 1e9:.0f} GB; use {flag} <= {total // 2 // each}"
        )


def check_output_file(
    path: str | os.PathLike[str], suffixes: tuple[str, ...] | None = None
) -> Path:
    """Check, before any work is done, that an output file can be written later.

    Args:
        path: the output file.
        suffixes: allowed lower-case suffixes (e.g. ``(".png", ".pdf")``), or None for any.

    Returns:
        The path as a ``Path``.

    Raises:
        UserError: the path is a directory, its suffix is not allowed, or its directory is
            missing or not writable.
    """
    p = Path(path)
    if not p.name or p.is_dir():
        raise UserError(f"{p}: is a directory, expected a file name")
    if suffixes is not None and p.suffix.lower() not in suffixes:
        raise UserError(f"{p}: expected a file name ending in {' or '.join(suffixes)}")
    check_writable_dir(p.parent)
    if p.exists() and not os.access(p, os.W_OK):
        # os.replace would succeed anyway (it needs only the directory); refuse to be surprising.
        raise UserError(f"{p}: file exists and is not writable")
    return p


MANIFEST = "manifest.json"
"""A results folder's manifest (:class:`Run`)."""
_FIELDS = [str, str, dict, dict]


@dataclasses.dataclass
class Run:
    """A results folder that says what it holds: ``DIR/manifest.json`` records the driver
    (``kind``), the settings that decide its results (``config``), its status ("partial" or
    "complete") and its finished units (name -> what the driver needs to use the unit again).
    It is rewritten atomically after every unit, so a folder a kill left is a partial run that
    ``resume`` finishes. Made by :func:`open_run`; ``write`` is False on the processes of a
    multi-process run that do not write."""

    out: Path
    kind: str
    config: dict[str, Any]
    units: dict[str, Any]
    write: bool = True

    def finish(self, unit: str, info: Any = None) -> None:
        """Record ``unit`` (its files already written) as finished, with ``info``."""
        self.units[unit] = info
        self._save("partial")

    def complete(self) -> None:
        """Record the run as complete (every output written)."""
        self._save("complete")

    def _save(self, status: str) -> None:
        if self.write:
            doc = {"kind": self.kind, "status": status, "config": self.config,
                   "units": self.units}  # fmt: skip
            atomic_write_json(self.out / MANIFEST, doc)


def open_run(
    out: str | os.PathLike[str], kind: str, config: dict[str, Any], *, resume: bool = False,
    write: bool = True,
) -> Run:  # fmt: skip
    """Start a run of ``kind`` into ``out`` (created if missing), or resume the one there.

    A fresh run needs a missing or empty folder; ``resume`` needs a run of the same kind and
    ``config`` there (its finished units are kept). On a process that does not write
    (``write=False``) nothing is checked or written; with ``resume`` its units are read.

    Raises:
        UserError: one line saying what is in the way and how to go on (``--resume``, a fresh
            ``--out``), or naming the first setting that differs from the run being resumed.
    """
    out = Path(out)
    config = json.loads(json.dumps(config))  # as it reads back: tuples as lists
    path, old = out / MANIFEST, None
    if path.is_file():
        try:
            old = json.loads(path.read_text())
            if [type(old.get(k)) for k in ("kind", "status", "config", "units")] != _FIELDS:
                raise ValueError("no kind, status, config and units")
        except (OSError, ValueError, AttributeError) as err:
            raise UserError(f"{path}: not a run manifest ({err}); use a fresh --out") from None
    if not write:
        return Run(out, kind, config, dict(old["units"]) if resume and old else {}, False)
    if resume and old is None:
        raise UserError(f"{out}: no run to resume (no {MANIFEST}); start it without --resume")
    if old is not None and not resume:
        how = "finish it with --resume, or" if old["status"] == "partial" else "remove it or"
        raise UserError(
            f"{out} holds a {old['status']} {old['kind']} run: {how} give a fresh --out"
        )
    if old is not None and old["kind"] != kind:
        raise UserError(f"{out} holds a {old['kind']} run, not a {kind} run: give its --out")
    if old is not None:
        for key in sorted(config.keys() | old["config"].keys()):
            was, now = old["config"].get(key), config.get(key)
            if was != now:
                raise UserError(
                    f"--{key.replace('_', '-')}: the run in {out} has {json.dumps(was)}, not "
                    f"{json.dumps(now)}; resume it with the same settings, or give a fresh --out"
                )
    elif out.is_dir() and any(out.iterdir()):
        raise UserError(f"{out} is not empty and holds no run: give a fresh or empty --out")
    elif out.exists() and not out.is_dir():
        raise UserError(f"{out}: not a directory")
    out.mkdir(parents=True, exist_ok=True)
    check_writable_dir(out)
    for tmp in [*out.glob(".*"), *out.glob("*/.*")] if old else ():
        if tmp.is_file() and tmp.name.count(".") >= 2:  # an atomic write that a SIGKILL cut
            tmp.unlink()
    run = Run(out, kind, config, dict(old["units"]) if old else {})
    if old is None:
        run._save("partial")  # the folder says at once what it holds
    return run
