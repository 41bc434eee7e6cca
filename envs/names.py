"""World names, free of JAX: which file a world's name means (SPEC section 3).

The built-in worlds are the files in this package's ``worlds/`` folder: ``worlds/NAME.toml`` is
the world ``NAME`` (a file added there is a built-in world, with no other edit). The user's own
worlds live in folders named by the environment variable ``JAXAIS_WORLDS`` (``os.pathsep``
separated, as ``PATH``): ``DIR/NAME.toml`` is the world ``NAME``, loaded by name as a built-in
is (``envs.load_world("NAME")``, ``envs.make("NAME")``, ``--world NAME``).

Precedence: built-ins first, then the folders in their order (the first holding a name wins, as
on ``PATH``). A built-in's name cannot be taken by a user's file: the paper's worlds must mean the
same arena in every session, so such a file is refused (a one-line :class:`WorldError` naming it)
rather than either world being used silently. Whenever a world is looked up by name the search
path is checked, so a wrong ``JAXAIS_WORLDS`` is reported, never ignored.

This module imports only the standard library and nothing relative: JAX-free callers
(``jaxais.baselines.config``, which checks flags before JAX starts) load it by its file, without
running ``jaxais.envs``'s ``__init__`` (which imports JAX).
"""

from __future__ import annotations

import difflib
import os
import re
from pathlib import Path

ENV_VAR = "JAXAIS_WORLDS"
"""The environment variable naming the user's world folders (``os.pathsep``-separated)."""
SUFFIX = ".toml"
BUILTIN_DIR = Path(__file__).resolve().parent / "worlds"
"""The built-in worlds' folder."""


class WorldError(ValueError):
    """A world file is missing, malformed or physically impossible (the message is one line)."""


NAME_PATTERN = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_-]{0,63}")
"""A world's name: letters, digits, ``_`` and ``-``, at most 64 (it names files and report
rows: no folder, no newline, nothing empty)."""


def is_plain_name(name: str) -> bool:
    """Whether ``name`` is a world's name as :data:`NAME_PATTERN` says (ASCII only)."""
    return name.isascii() and NAME_PATTERN.fullmatch(name) is not None


def scan(folder: str | os.PathLike[str]) -> tuple[str, ...]:
    """The world names in ``folder``: the stems of its ``*.toml`` files, sorted."""
    return tuple(sorted(p.stem for p in Path(folder).glob(f"*{SUFFIX}") if p.is_file()))


BUILTIN_WORLDS: tuple[str, ...] = scan(BUILTIN_DIR)
"""The built-in worlds: the files in ``worlds/`` (sorted; the paper's order of its test worlds
is ``jaxais.experiments.protocol.WORLDS``)."""


def search_path() -> tuple[Path, ...]:
    """The folders ``JAXAIS_WORLDS`` names, in order (empty entries skipped); WorldError when
    one is not an existing folder."""
    folders = []
    for entry in os.environ.get(ENV_VAR, "").split(os.pathsep):
        if not entry.strip():
            continue
        folder = Path(entry).expanduser()
        if not folder.is_dir():
            what = "is not a folder" if folder.exists() else "does not exist"
            raise WorldError(
                f"{ENV_VAR}: {entry!r} {what}: create it or remove it from {ENV_VAR} "
                f"(folders of world .toml files, separated by {os.pathsep!r})"
            )
        folders.append(folder)
    return tuple(folders)


def user_worlds() -> dict[str, Path]:
    """name -> file of each world on the search path (the first folder holding a name wins);
    WorldError for a bad folder or for a file that takes a built-in world's name."""
    found: dict[str, Path] = {}
    for folder in search_path():
        for name in scan(folder):
            path = folder / f"{name}{SUFFIX}"
            if name in BUILTIN_WORLDS:
                raise WorldError(
                    f"{path}: '{name}' is a built-in world's name, which a file in {ENV_VAR} "
                    "cannot take: rename the file (and its 'name' field)"
                )
            found.setdefault(name, path)
    return found


def world_names() -> tuple[str, ...]:
    """Every world loadable by name: the built-ins, then the search path's (sorted)."""
    return BUILTIN_WORLDS + tuple(sorted(user_worlds()))


def _listing() -> str:
    """The world names, for an error message (the built-ins alone if the search path is bad)."""
    try:
        return ", ".join(world_names())
    except WorldError:
        return ", ".join(BUILTIN_WORLDS)


def is_name(text: str) -> bool:
    """Whether ``text`` is a world's name rather than a file's path: a name has no folder
    separator and no ``.toml`` suffix (``./corridor`` or ``corridor.toml`` is a path)."""
    seps = {"/", os.sep, os.altsep} - {None}
    return bool(text) and not any(s in text for s in seps) and not text.endswith(SUFFIX)


def find_world(name: str) -> Path:
    """The file of the world called ``name``: ``worlds/NAME.toml`` for a built-in, else the
    first ``DIR/NAME.toml`` on the search path (WorldError, one line, if there is none)."""
    users = user_worlds()  # checked even for a built-in: a bad JAXAIS_WORLDS is never ignored
    if name in BUILTIN_WORLDS:
        return BUILTIN_DIR / f"{name}{SUFFIX}"
    if name in users:
        return users[name]
    close = difflib.get_close_matches(name, BUILTIN_WORLDS + tuple(users), n=1)
    hint = f"did you mean '{close[0]}'? " if close else ""
    where = os.environ.get(ENV_VAR, "")
    searched = f"{ENV_VAR}={where}" if where.strip() else f"{ENV_VAR} is not set"
    here = f"; a file {name!r} is here: give it as ./{name}" if Path(name).is_file() else ""
    raise WorldError(
        f"no built-in world or file {name!r} ({hint}worlds: {_listing()}; {searched}): put "
        f"{name}{SUFFIX} in a folder named by {ENV_VAR}, or give the file's path{here}"
    )


def resolve(name_or_path: str | os.PathLike[str]) -> tuple[Path, str | None]:
    """(the world's file, its name when given by name else None): a name (:func:`is_name`) is
    looked up by :func:`find_world`, anything else is a path to an existing file."""
    text = os.fspath(name_or_path)
    if is_name(text):
        return find_world(text), text
    path = Path(text)
    if not path.is_file():
        raise WorldError(f"{text}: no such world file (or a world's name: {_listing()})")
    return path, None
