"""GA checkpoints with orbax-checkpoint: save after every generation, resume exactly.

A directory holds ``run.json`` (the run's identity: a resume with another is refused) and an orbax
checkpoint ``<generation>/`` per generation: ``state`` (the GAState's arrays, the key as its data)
and ``meta`` (JSON). Orbax renames a complete save into place and the last two are kept, so an
interruption leaves the last complete one valid. Every failure is a one-line
:class:`CheckpointError`.
"""

from __future__ import annotations

import contextlib
import json
import math
from pathlib import Path
from typing import Any

import jax
import numpy as np

from jaxais import lock
from jaxais.ga.config import GAConfig
from jaxais.ga.core import GAState, abstract_state
from jaxais.immune.antibodies import within_limits
from jaxais.io import atomic_write_json
from jaxais.orbax_reads import forget_abandoned_reads

__all__ = ["CheckpointError", "GACheckpointer", "abstract_tree", "state_from_tree", "state_to_tree"]

RUN_JSON = "run.json"
FORMAT = "jaxais-ga-checkpoint/1"  # in run.json and every checkpoint's meta
_SEP = "__"  # joins pytree path names into flat, filesystem-safe array names


class CheckpointError(ValueError):
    """No checkpoint to resume, a different run, or a corrupt checkpoint (one-line message)."""


def _is_key(x: Any) -> bool:
    return jax.dtypes.issubdtype(getattr(x, "dtype", None), jax.dtypes.prng_key)


def _name(path: tuple[Any, ...]) -> str:
    return _SEP.join(str(getattr(p, "name", getattr(p, "key", p))) for p in path)


def _flat(state: GAState) -> dict[str, Any]:
    leaves = jax.tree_util.tree_flatten_with_path(state)[0]
    return {_name(path): jax.random.key_data(x) if _is_key(x) else x for path, x in leaves}


def state_to_tree(state: GAState) -> dict[str, np.ndarray]:
    """The state as flat NumPy arrays, keys as their data (``"population__type"``, ``"key"``)."""
    return {name: np.asarray(x) for name, x in _flat(state).items()}


def abstract_tree(config: GAConfig) -> dict[str, jax.ShapeDtypeStruct]:
    """Shapes and dtypes of :func:`state_to_tree` for ``config`` (orbax's restore target)."""
    flat = jax.eval_shape(_flat, abstract_state(config))
    return {name: jax.ShapeDtypeStruct(x.shape, x.dtype) for name, x in flat.items()}


def state_from_tree(
    tree: dict[str, np.ndarray], config: GAConfig, key_impl: str | None = None
) -> GAState:
    """Inverse of :func:`state_to_tree` (the key rewrapped with ``jax.random.wrap_key_data``)."""

    def leaf(path, x):
        value = np.asarray(tree[_name(path)])
        return jax.random.wrap_key_data(value, impl=key_impl) if _is_key(x) else value

    return jax.tree_util.tree_map_with_path(leaf, abstract_state(config))


def _first_line(err: BaseException, limit: int = 200) -> str:
    text = str(err).strip().splitlines()
    msg = text[0] if text else type(err).__name__
    return msg if len(msg) <= limit else msg[: limit - 3] + "..."


def _write_failure(err: BaseException) -> str:
    """The reason a write failed, short: the OS's words for a full disk, else the first line."""
    text = str(err)
    if "No space left on device" in text or "os_error_code='28'" in text:
        return "No space left on device"
    return _first_line(err)


def _describe_difference(stored: dict[str, Any], given: dict[str, Any], where: str = "") -> str:
    """The first differing entry, e.g. ``"config.mutation was 0.05, now 0.1"``."""
    for k in sorted(set(stored) | set(given)):
        a, b = stored.get(k), given.get(k)
        if a != b:
            if isinstance(a, dict) and isinstance(b, dict):
                return _describe_difference(a, b, f"{where}{k}.")
            return f"{where}{k} was {a!r}, now {b!r}"
    return "identical"


class GACheckpointer:
    """Saves and restores the GA's state each generation; a context manager.

    ``run_info`` (JSON) must match on ``resume``, which needs a complete checkpoint; without
    ``resume`` the directory must hold none.
    """

    def __init__(self, directory: str | Path, run_info: dict[str, Any], resume: bool):
        import orbax.checkpoint as ocp

        self.directory = Path(directory).absolute()
        self._ocp = ocp
        self._lock = None  # the directory's (jaxais.lock): one GA writes it
        if self.directory.is_dir() or not resume:
            self.directory.mkdir(parents=True, exist_ok=True)
            self._lock = lock.acquire(self.directory)
        try:
            self._open(run_info, resume)
        except BaseException:
            self._release()
            raise

    def _release(self) -> None:
        if self._lock is not None:
            self._lock.release()

    def _open(self, run_info: dict[str, Any], resume: bool) -> None:
        ocp = self._ocp
        run_file = self.directory / RUN_JSON
        info = {"format": FORMAT, **json.loads(json.dumps(run_info))}
        # Orbax names complete checkpoints by their step; temporary ones carry a suffix.
        has_steps = self.directory.is_dir() and any(
            p.is_dir() and p.name.isdigit() for p in self.directory.iterdir()
        )
        if resume:
            if not has_steps:
                raise CheckpointError(
                    f"{self.directory}: no complete checkpoint to resume (start without --resume)"
                )
            try:
                stored = json.loads(run_file.read_text())
                if not isinstance(stored, dict):
                    raise ValueError("not a JSON object")
            except (OSError, ValueError) as err:
                raise CheckpointError(
                    f"{run_file}: missing or corrupt ({_first_line(err)}); cannot check that"
                    " the resumed run has the same arguments"
                ) from None
            if stored != info:
                raise CheckpointError(
                    f"{self.directory}: cannot resume with different arguments"
                    f" ({_describe_difference(stored, info)})"
                )
        else:
            if has_steps:
                raise CheckpointError(
                    f"{self.directory} already holds checkpoints of a run: pass --resume to"
                    " continue it, or choose another output directory"
                )
            self.directory.mkdir(parents=True, exist_ok=True)
            atomic_write_json(run_file, info)
        options = ocp.CheckpointManagerOptions(
            max_to_keep=2,  # a corrupt newest one can be deleted to resume from the one before
            create=True,
            # A save is complete when it returns: a signal ends a script at once (jaxais.cli),
            # and must not take the newest checkpoint with it.
            enable_async_checkpointing=False,
            cleanup_tmp_directories=True,  # what an interrupted save left (never a complete one)
        )
        self._manager = ocp.CheckpointManager(self.directory, options=options)

    def __enter__(self) -> GACheckpointer:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        # Already failing (e.g. Ctrl-C during a save): report that error, not a cleanup one.
        with contextlib.suppress(Exception) if exc is not None else contextlib.nullcontext():
            self.close()

    @contextlib.contextmanager
    def _writing(self):
        """A failed write (e.g. a full disk) as one line naming the checkpoint directory."""
        try:
            yield
        except Exception as err:  # noqa: BLE001 (orbax and tensorstore raise many kinds)
            raise CheckpointError(
                f"{self.directory}: could not write a checkpoint ({_write_failure(err)}); free "
                "some space or choose another --out, then resume with --resume"
            ) from None

    def close(self) -> None:
        """Wait for pending writes and release orbax's manager and the directory's lock."""
        try:
            with self._writing():
                self._manager.wait_until_finished()
            self._manager.close()
        finally:
            self._release()

    def latest_generation(self) -> int | None:
        """The generation of the newest complete checkpoint (None if there is none)."""
        self._manager.wait_until_finished()
        self._manager.reload()
        return self._manager.latest_step()

    def save(self, state: GAState, config: GAConfig, extra: dict[str, Any] | None = None) -> None:
        """Save ``state`` as checkpoint ``state.generation``, with ``config`` and ``extra``."""
        ocp = self._ocp
        generation = int(state.generation)
        meta = {
            "format": FORMAT,
            "generation": generation,
            "key_impl": str(jax.random.key_impl(state.key)),
            "config": config.to_dict(),
            "extra": extra or {},
        }
        with self._writing():
            self._manager.save(
                generation,
                args=ocp.args.Composite(
                    state=ocp.args.StandardSave(state_to_tree(state)),
                    meta=ocp.args.JsonSave(meta),
                ),
            )

    def restore(
        self, config: GAConfig, generation: int | None = None
    ) -> tuple[GAState, dict[str, Any]]:
        """(state, its ``extra``) of checkpoint ``generation`` (default: the newest complete
        one), shaped by ``config``; CheckpointError if none, corrupt or not fitting."""
        ocp = self._ocp
        self._manager.wait_until_finished()
        step = self.latest_generation() if generation is None else generation
        if step is None:
            raise CheckpointError(f"{self.directory}: no complete checkpoint to resume")
        where = self.directory / str(step)
        hint = f"delete {where} to resume from an earlier checkpoint, or start again"
        forget_abandoned_reads()  # a failed read must end with our one-line error alone
        try:
            restored = self._manager.restore(
                step,
                args=ocp.args.Composite(
                    state=ocp.args.StandardRestore(abstract_tree(config)),
                    meta=ocp.args.JsonRestore(),
                ),
            )
            meta = restored.meta
            if not isinstance(meta, dict) or meta.get("format") != FORMAT:
                raise ValueError("unknown checkpoint format")
            state = state_from_tree(restored.state, config, meta.get("key_impl"))
            _check_state(state, config, step, meta)
        except Exception as err:  # noqa: BLE001 (any failure to read is a corrupt checkpoint)
            raise CheckpointError(
                f"{where}: corrupt checkpoint ({_first_line(err)}); {hint}"
            ) from None
        return state, meta.get("extra", {})


def _check_state(state: GAState, config: GAConfig, step: int, meta: dict[str, Any]) -> None:
    """ValueError saying what is wrong with a restored state."""
    if int(state.generation) != step or meta.get("generation") != step:
        raise ValueError(f"it holds generation {int(state.generation)}, not {step}")
    stored = meta.get("config", {})
    for name in ("populations", "robots"):
        if stored.get(name) != getattr(config, name):
            raise ValueError(f"{name} = {stored.get(name)!r}, expected {getattr(config, name)!r}")
    for name, ab in (
        ("population", state.population),
        ("evaluated", state.evaluated),
        ("best", state.best.antibodies),
    ):
        if not bool(np.all(np.asarray(within_limits(ab)))):
            raise ValueError(f"{name} antibodies break Table 1's limits")
    if step > 0:
        for name in ("fitness", "tau"):
            values = np.asarray(getattr(state, name))
            if not np.all(np.isfinite(values)) or np.any(values < 0):
                raise ValueError(f"{name} holds invalid values")
        if not math.isfinite(float(np.max(np.asarray(state.best.fitness)))):
            raise ValueError("best fitness holds invalid values")
