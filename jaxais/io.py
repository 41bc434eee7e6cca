"""Writing files: atomic writes (a temporary file beside the target, then :func:`os.replace`),
output checks made before any work, and results folders that say what they hold
(:func:`open_run`). :mod:`jaxais.cli` removes :data:`IN_FLIGHT` files on a signal."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import tempfile
import typing
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np


class UserError(ValueError):
    """A mistake by the user: one line and exit status 2 from a script (:mod:`jaxais.cli`)."""


class ArgumentTypeError(UserError, TypeError):
    """An argument of the wrong type: a TypeError, and a UserError (one line) too."""


def check_type(value: Any, kind: Any, name: str, what: str, hint: str = "") -> None:
    """:class:`ArgumentTypeError` "``name`` must be ``what``, got <type> <value>``hint``" unless
    ``value`` is a ``kind``. A bool is a bool: it is no int or float unless ``kind`` names bool.
    The one type check of the public calls: made before any range check, any work."""
    ok = isinstance(value, kind)
    if ok and isinstance(value, bool | np.bool_):
        kinds = typing.get_args(kind) or (kind if isinstance(kind, tuple) else (kind,))
        ok = any(k in (bool, np.bool_, object) for k in kinds)
    if not ok:
        got = type(value).__name__
        if isinstance(value, str | int | float):
            got += f" {value!r:.40}"
        raise ArgumentTypeError(f"{name} must be {what}, got {got}{hint}")


INTEGER = int | np.integer
NUMBER = int | float | np.integer | np.floating
PATH = str | os.PathLike


def check_int(value: Any, name: str, low: int | None = None, high: int | None = None) -> int:
    """``value`` as an int (NumPy ints are ints; bools and 2.0 are not), in [low, high]."""
    check_type(value, INTEGER, name, "an integer")
    if (low is not None and value < low) or (high is not None and value > high):
        rule = f"in [{low}, {high}]" if low is not None and high is not None else (
            f">= {low}" if low is not None else f"<= {high}")  # fmt: skip
        raise UserError(f"{name} must be {rule}, got {value}")
    return int(value)


def check_number(value: Any, name: str) -> float:
    """``value`` as a float (an int, a float or a NumPy scalar; not a bool or a string)."""
    check_type(value, NUMBER, name, "a number")
    return float(value)


def check_bool(value: Any, name: str) -> bool:
    """``value`` unless it is not a bool (NumPy's too): "no" and 1 are not switches."""
    check_type(value, bool | np.bool_, name, "True or False")
    return bool(value)


def check_path(value: Any, name: str, what: str = "a path") -> None:
    """ArgumentTypeError unless ``value`` is a path (a str or an os.PathLike)."""
    check_type(value, PATH, name, what)


def check_names(value: Any, name: str, items: Any = str) -> list[Any]:
    """A list of names given as a sequence of ``items`` (strings) or one comma-separated string
    (``"world1,world2"``: two; ``"real"``: one; empty parts dropped)."""
    if isinstance(value, str):
        return [part.strip() for part in value.split(",") if part.strip()]
    check_type(value, list | tuple, name, "a list of names or one comma-separated string")
    for item in value:
        check_type(item, items, f"each of {name}", "a name (a string)")
    return list(value)


def load_module_file(name: str, path: str | os.PathLike[str]) -> Any:
    """The Python file ``path`` executed as the module ``name`` (in ``sys.modules`` once it
    loaded; removed again if it raised)."""
    import importlib.util
    import sys

    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[name]
        raise
    return module


IN_FLIGHT: set[Path] = set()  # temporary files being written (the signal handler removes them)
ON_SIGNAL: list[Callable[[], object]] = []  # run on a signal, newest first; removed by its adder


def abandon(line: str, status: int) -> None:
    """End the process at once, from any thread: run :data:`ON_SIGNAL`, remove the temp files
    of writes in flight, write ``line`` to stderr, ``os._exit(status)`` (nothing unwinds)."""
    for cleanup in reversed(list(ON_SIGNAL)):
        with contextlib.suppress(Exception):
            cleanup()
    for tmp in list(IN_FLIGHT):
        with contextlib.suppress(OSError):
            tmp.unlink()
    with contextlib.suppress(OSError):
        os.write(2, line.encode())
    os._exit(status)


def python_scalars(config: Any) -> None:
    """Store a frozen dataclass's NumPy scalar fields (a grid's values) as the Python numbers
    they are, for its type checks and for JSON."""
    for name, value in vars(config).items():
        if isinstance(value, np.generic):
            object.__setattr__(config, name, value.item())


def atomic_write(path: str | os.PathLike[str], write_fn: Callable[[Path], Any]) -> Path:
    """``write_fn(tmp)`` fills a temporary file in ``path``'s directory (same suffix:
    matplotlib reads the format from it), which then replaces ``path`` (0666 less the umask);
    if it raises, ``path`` is untouched. Returns ``Path(path)``."""
    dest = Path(path)
    fd, tmp_name = tempfile.mkstemp(dir=dest.parent, prefix=f".{dest.name}.", suffix=dest.suffix)
    os.close(fd)
    tmp = Path(tmp_name)
    IN_FLIGHT.add(tmp)
    try:
        write_fn(tmp)
        with open(tmp, "rb+") as f:  # the data is on disk before the rename makes it visible
            os.fsync(f.fileno())
        mask = os.umask(0)  # read it: os has no getter
        os.umask(mask)
        os.chmod(tmp, 0o666 & ~mask)
        os.replace(tmp, dest)
    except BaseException as err:
        with contextlib.suppress(OSError):
            tmp.unlink()
        if isinstance(err, OSError) and err.filename in (None, str(tmp), tmp):
            # A full disk or a file size limit (ENOSPC, EFBIG) names no file: name the target.
            raise OSError(err.errno, err.strerror or str(err), str(dest)) from err
        raise
    finally:
        IN_FLIGHT.discard(tmp)
    return dest


def atomic_write_text(path: str | os.PathLike[str], text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_write`)."""
    return atomic_write(path, lambda tmp: tmp.write_text(text, encoding=encoding))


def atomic_write_json(path: str | os.PathLike[str], obj: Any, indent: int | None = 2) -> Path:
    """Write ``obj`` as JSON plus a newline atomically (serialised first; NaN refused)."""
    text = json.dumps(obj, indent=indent, allow_nan=False) + "\n"
    return atomic_write_text(path, text)


def read_json_object(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The JSON object in ``path``, or a one-line UserError naming the file and the fault."""
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
    """``path`` ("": the current directory) as a Path, or a UserError unless it is an existing
    directory this process can create files in."""
    d = Path(path)  # Path("") is Path(".")
    if not d.exists():
        raise UserError(f"{d}: directory does not exist")
    if not d.is_dir():
        raise UserError(f"{d}: not a directory")
    if not os.access(d, os.W_OK | os.X_OK):
        raise UserError(f"{d}: directory is not writable")
    return d


RUN_BYTES = 8192  # host memory a pooled run keeps, measured: params (twice), keys, its record


def check_memory(count: int, each: int, flag: str) -> None:
    """UserError if ``count`` items of ``each`` bytes pass half the memory (the kernel's kill
    says nothing and loses everything)."""
    total = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    if count * each > total // 2:
        raise UserError(
            f"{flag} {count} needs about {count * each / 1e9:.3g} GB of memory; this machine has "
            f"{total / 1e9:.0f} GB; use {flag} <= {total // 2 // each}"
        )


def check_output_file(
    path: str | os.PathLike[str], suffixes: tuple[str, ...] | None = None
) -> Path:
    """``path`` as a Path, or a UserError unless it can be written later: not a directory, a
    lower-case suffix in ``suffixes`` (None: any), a writable directory."""
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
_FIELDS = [str, str, dict, dict]  # the types of kind, status, config, units


def manifest_checksum(doc: dict[str, Any]) -> str:
    """sha256 of a manifest's kind, status, config and units as canonical JSON (sorted keys)."""
    import hashlib

    body = {k: doc.get(k) for k in ("kind", "status", "config", "units")}
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()


@dataclasses.dataclass
class Run:
    """A results folder: ``manifest.json`` holds kind, config, status ("partial"/"complete")
    and finished units (name -> what reusing it needs), rewritten after every unit. ``write``
    is False on a multi-process run's non-writing processes."""

    out: Path
    kind: str
    config: dict[str, Any]
    units: dict[str, Any]
    write: bool = True
    lock: Any = dataclasses.field(default=None, repr=False, compare=False)  # a jaxais.lock's

    def finish(self, unit: str, info: Any = None) -> None:
        """Record ``unit`` (its files written) as finished."""
        self.units[unit] = info
        self._save("partial")

    def complete(self) -> None:
        """Record the run as complete (every output written); its folder's lock goes."""
        self._save("complete")
        if self.lock is not None:
            self.lock.release()

    def _save(self, status: str) -> None:
        if self.write:
            doc = {"kind": self.kind, "status": status, "config": self.config,
                   "units": self.units}  # fmt: skip
            doc["checksum"] = manifest_checksum(doc)
            atomic_write_json(self.out / MANIFEST, doc)


def open_run(
    out: str | os.PathLike[str], kind: str, config: dict[str, Any], *, resume: bool = False,
    write: bool = True,
) -> Run:  # fmt: skip
    """Start a run of ``kind`` in a missing or empty ``out``, or ``resume`` the same kind and
    config there. ``write=False`` checks and writes nothing. A UserError says what is in the way
    and how to go on, or names the first setting that differs. Writing, it holds the folder's
    lock (:mod:`jaxais.lock`: refused while another live process writes there) until
    :meth:`Run.complete` or the process ends. A manifest's checksum must match its contents (one
    written before manifests had one is taken as it is, and gets one when next saved)."""
    from jaxais import lock

    out = Path(out)
    held = lock.acquire(check_writable_dir(out)) if write and out.is_dir() else None
    try:
        return _open_run(out, kind, config, resume, write, held)
    except BaseException:
        if held is not None:
            held.release()
        raise


def _open_run(out: Path, kind: str, config: dict[str, Any], resume: bool, write: bool,
              held: Any) -> Run:  # fmt: skip
    from jaxais import lock

    config = json.loads(json.dumps(config))  # as it reads back: tuples as lists
    path, old = out / MANIFEST, None
    if path.is_file():
        try:
            old = json.loads(path.read_text())
            if [type(old.get(k)) for k in ("kind", "status", "config", "units")] != _FIELDS:
                raise ValueError("no kind, status, config and units")
        except (OSError, ValueError, AttributeError) as err:
            raise UserError(f"{path}: not a run manifest ({err}); use a fresh --out") from None
        if "checksum" in old and old["checksum"] != manifest_checksum(old):
            raise UserError(
                f"{path}: its checksum does not match its contents (edited by hand or damaged), "
                "so the run there cannot be trusted to resume: start it again with a fresh --out"
            )
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
    elif out.is_dir() and any(p.name != lock.NAME for p in out.iterdir()):
        raise UserError(f"{out} is not empty and holds no run: give a fresh or empty --out")
    elif out.exists() and not out.is_dir():
        raise UserError(f"{out}: not a directory")
    out.mkdir(parents=True, exist_ok=True)
    check_writable_dir(out)
    for tmp in [*out.glob(".*"), *out.glob("*/.*")] if old else ():
        if tmp.is_file() and tmp.name.count(".") >= 2:  # an atomic write that a SIGKILL cut
            tmp.unlink()
    run = Run(out, kind, config, dict(old["units"]) if old else {}, lock=held)
    if old is None:
        run.lock = held or lock.acquire(out)  # a folder this call made: before its first file
        try:
            run._save("partial")  # the folder says at once what it holds
        except BaseException:
            run.lock.release()
            raise
    return run
