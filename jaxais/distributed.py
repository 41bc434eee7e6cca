"""Runs across processes and machines with JAX's multi-process runtime (``jax.distributed``).

Every process runs the same script and flags (:func:`add_arguments`, or ``JAXAIS_*`` variables;
``--coordinator auto``: JAX's own cluster detection, :func:`detect`; gloo on CPUs);
:func:`initialize` joins them, and a batch of runs is sharded over a 1-D mesh of every device
(:func:`batch_sharding`) with the readouts replicated, so every process writes the same results,
bit for bit those of one process. Joining fails fast with one line (a ``ValueError``) naming the
cause and the fix: a process missing after the timeout, an id taken twice, or flags that differ
between processes; waiting is reported on stderr. A process that stops responding mid-run ends the
others with one line.
"""

from __future__ import annotations

import argparse
import atexit
import contextlib
import json
import os
import re
import select
import socket
import sys
import threading
import time
import warnings
from unittest import mock

from jaxais import io

ENV = {
    k: "JAXAIS_" + k.upper() for k in ("coordinator", "num_processes", "process_id", "timeout_s")
}
TIMEOUT_S = 60.0  # seconds a process waits for the others by default
PER_PROCESS = ("process_id", "timeout_s", "out", "plot")  # may differ (the others write nothing)
LAUNCHERS = {"slurm": "srun (inside an sbatch script too)", "ompi": "mpirun"}
"""What starts each process, by JAX's detector name (a hint in :func:`detect`'s errors)."""
ABANDONED: list = []
"""Runtimes of joins that timed out mid-way, or of runs that lost a process: :func:`jaxais.cli.fail`
then ends with ``os._exit``, as the teardown at exit would wait on them or abort."""
ON_LOST = [lambda message: io.abandon(f"error: {message}\n", 2)]
"""Ends the process with a line when :func:`_watch` finds a process gone (jaxais.cli sets it)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The flags of a multi-process run (each defaults to its environment variable)."""
    group = parser.add_argument_group("across processes (jax.distributed)")
    # fmt: off
    group.add_argument("--coordinator", default=os.environ.get(ENV["coordinator"]),
                       metavar="HOST:PORT", help="process 0's address: join a multi-process run "
                       "(or 'auto': JAX's cluster detection, as under srun; default "
                       f"${ENV['coordinator']}, unset: one process)")
    group.add_argument("--num-processes", type=int, default=_env("num_processes", int),
                       help=f"processes in the run (default ${ENV['num_processes']})")
    group.add_argument("--process-id", type=int, default=_env("process_id", int),
                       help=f"this process's index, 0 .. N-1 (default ${ENV['process_id']})")
    group.add_argument("--timeout-s", type=float, default=_env("timeout_s", float, TIMEOUT_S),
                       help="seconds to wait for every process to join (default "
                       f"${ENV['timeout_s']}, unset: {TIMEOUT_S:g})")
    # fmt: on


def _env(name: str, kind: type, default=None):
    value = os.environ.get(ENV[name])
    if not value:
        return default
    try:
        return kind(value)
    except ValueError:
        what = "an integer" if kind is int else "a number"
        raise ValueError(f"${ENV[name]} must be {what}, got {value!r}") from None


def check(args: argparse.Namespace) -> None:
    """Reject inconsistent flags before JAX starts (one-line ValueErrors)."""
    if not args.timeout_s > 0:
        raise ValueError(f"--timeout-s must be > 0, got {args.timeout_s}")
    if args.coordinator == "auto":
        detect()
        return
    if not args.coordinator:
        if args.num_processes or args.process_id is not None:
            raise ValueError("--num-processes and --process-id need --coordinator HOST:PORT")
        return
    host, _, port = args.coordinator.rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(
            f"--coordinator must be HOST:PORT with a port in 1..65535, got {args.coordinator!r}"
        )
    if args.num_processes is None or args.num_processes < 1:
        raise ValueError("--coordinator needs --num-processes N (N >= 1)")
    if args.process_id is None or not 0 <= args.process_id < args.num_processes:
        raise ValueError(
            f"--process-id must be in [0, {args.num_processes}), got {args.process_id}"
        )


def _detectors() -> list[type]:
    """The cluster environments ``jax.distributed.initialize()`` tries, in its order (abstract
    bases and opt-in ones left out)."""
    from jax._src import clusters

    kinds = [c for c in clusters.ClusterEnv._cluster_types if not c.opt_in_only_method]
    return [c for c in kinds if not any(o is not c and issubclass(o, c) for o in kinds)]


def _names(detector: type) -> list[str]:
    """The environment variables ``detector``'s module names in its constants (SLURM_*, ...)."""
    module = sys.modules[detector.__module__]
    return sorted(
        {v for k, v in vars(module).items()
         if k.startswith("_") and isinstance(v, str) and re.fullmatch(r"[A-Z]+_\w+", v)}
    )  # fmt: skip


def variables(detector: type) -> tuple[str, ...]:
    """The environment variables ``detector.is_env_present()`` needs, every one: of the names
    its module defines (SLURM's, Open MPI's), those without which it answers False; () for a
    detector that reads no variables alone (Kubernetes, Cloud TPU)."""
    names = _names(detector)

    def present(*unset: str) -> bool:
        with mock.patch.dict(os.environ, {name: "0" for name in names}):
            for name in unset:
                del os.environ[name]
            return detector.is_env_present()

    if not names or not present():
        return ()
    return tuple(name for name in names if not present(name))


def _label(detector: type) -> str:
    need = variables(detector)
    return detector.__name__ + (f" (${', $'.join(need)})" if need else "")


def detect() -> type:
    """JAX's cluster environment that ``--coordinator auto`` joins with (the first whose
    ``is_env_present()`` holds, as ``jax.distributed.initialize()`` picks it); otherwise a
    one-line ``ValueError`` naming the variables a partly set one lacks, or every detector."""
    fix = "or give --coordinator HOST:PORT --num-processes N --process-id I"
    with warnings.catch_warnings(record=True) as said:  # K8s warns over several lines
        warnings.simplefilter("always")
        detectors = _detectors()
        found = next((d for d in detectors if d.is_env_present()), None)
    if found is not None:
        return found

    def share(detector: type) -> float:  # of the variables its module names, those set
        names = _names(detector)
        return sum(name in os.environ for name in names) / max(len(names), 1)

    partial = [d for d in detectors if variables(d) and share(d) > 0]
    if partial:  # the most nearly set one: the variables it lacks
        detector = max(partial, key=share)
        need = variables(detector)
        missing = [name for name in need if name not in os.environ]
        launcher = LAUNCHERS.get(getattr(detector, "name", ""), "its launcher")
        raise ValueError(
            f"--coordinator auto: JAX's {detector.__name__} needs each of ${', $'.join(need)}; "
            f"${', $'.join(missing)} {'is' if len(missing) == 1 else 'are'} not set: start "
            f"each process with {launcher}, {fix}"
        )
    hint = " ".join(str(said[0].message).split()).split(". ")[0] if said else ""
    raise ValueError(
        "--coordinator auto: none of JAX's clusters is detected ("
        + ", ".join(map(_label, detectors))
        + (f") ({hint}" if hint else "")
        + f"): start the processes with srun or mpirun, {fix}"
    )


def initialize(args: argparse.Namespace) -> bool:
    """Join the run the flags describe (False, nothing done, for one process), before JAX
    computes anything: waits ``args.timeout_s`` at most, then compares every process's flags
    (but :data:`PER_PROCESS`). One-line ``ValueError`` on bad flags, a failed join or a mismatch."""
    check(args)
    if not args.coordinator:
        return False
    import jax
    from jax._src import distributed as state  # the runtime's client: its key-value store

    if jax.config.jax_platforms in (None, "", "cpu"):
        # CPU devices of different processes exchange data through gloo.
        jax.config.update("jax_cpu_collectives_implementation", "gloo")
    # Only process 0 writes the compilation cache, and programs over a process's own devices
    # differ between processes: with it, process 0 would start its first collective a whole
    # compile ahead of the others, and gloo gives up on a peer after 30 s.
    jax.config.update("jax_enable_compilation_cache", False)
    # Its C++ SIGTERM handler would replace the scripts' own: a scheduler's SIGTERM, logged and
    # ignored, would not stop the run.
    jax.config.update("jax_enable_preemption_service", False)
    auto, n, where = args.coordinator == "auto", args.num_processes, args.coordinator
    spec = {"coordinator_address": where, "num_processes": n, "process_id": args.process_id}
    if auto:  # JAX detects the cluster again, as detect() did
        spec, where = {}, f"{detect().__name__}'s coordinator"
    elif args.process_id == 0:  # a second process 0 would take the port over, and XLA abort
        try:
            server = socket.create_server(("", int(where.rpartition(":")[2])))
        except OSError as err:
            raise ValueError(
                f"cannot host the coordinator at {where}: {os.strerror(err.errno)} (another "
                "process 0 or another program holds the port): give each process its own "
                "--process-id, or choose another port"
            ) from None
    # XLA's own join timeout aborts the process (SIGABRT, a C++ trace): ours ends it first, and
    # the join runs in a thread so that this one can report progress and take Ctrl-C meanwhile.
    failed: list[Exception] = []
    silence = max(args.timeout_s, 10.0)  # seconds without a sign of life: a process stopped

    def join() -> None:
        try:
            if not auto:  # XLA aborts every process when a connected id connects again
                _claim(server, n) if args.process_id == 0 else _claim_id(args, where)
            jax.distributed.initialize(
                **spec, initialization_timeout=int(args.timeout_s) + 600,
                heartbeat_timeout_seconds=int(silence) + 90,  # _watch ends it first
            )  # fmt: skip
        except Exception as err:  # noqa: BLE001 (reported by the waiting thread)
            failed.append(err)

    joining = threading.Thread(target=join, daemon=True)
    joining.start()
    start, every = time.monotonic(), min(10.0, args.timeout_s / 2)
    while joining.is_alive() and (left := args.timeout_s - (time.monotonic() - start)) > 0:
        joining.join(min(every, left))
        if joining.is_alive():
            others = "the others" if auto else f"{n - 1} of {n} processes"
            waited = f"{time.monotonic() - start:.0f} s of {args.timeout_s:g}"
            print(f"waiting for {others} at {where} ({waited})", file=sys.stderr, flush=True)
    if failed:
        if isinstance(failed[0], ValueError) and not auto:
            raise failed[0]
        why = (str(failed[0]).strip().splitlines() or [type(failed[0]).__name__])[0]
        raise ValueError(f"could not join the run at {where}: {why}")
    if joining.is_alive():
        ABANDONED.append((state.global_state.client, state.global_state.service))
        state.global_state.client = state.global_state.service = None
        raise ValueError(_why_not_joined(args, where))
    runtime = state.global_state
    where = getattr(runtime, "coordinator_address", None) or where
    _agree(args, runtime)
    threading.Thread(target=_watch, args=(runtime, silence), daemon=True).start()
    print(f"joined the run at {where} as process {runtime.process_id} of "
          f"{runtime.num_processes}", file=sys.stderr, flush=True)  # fmt: skip
    return True


def _claim(server: socket.socket, n: int) -> None:
    """Process 0: grant ids 1 .. n-1 on the coordinator's port, each to one live process (one
    that ends frees its id), then close the claims and the port: the others then join."""
    held: dict[int, socket.socket] = {}
    with server:
        while len(held) < n - 1:
            for sock in select.select([server, *held.values()], [], [])[0]:
                if sock is not server:  # a claimer ended (it sends nothing more)
                    held = {i: s for i, s in held.items() if s is not sock}
                    sock.close()
                    continue
                conn = server.accept()[0]
                with contextlib.suppress(OSError, ValueError):
                    conn.settimeout(5)
                    i = int(conn.recv(16).decode())
                    if 0 < i < n and i not in held:
                        conn.sendall(b"ok")
                        held[i], conn = conn, None
                    else:
                        taken = "is already taken" if 0 < i < n else f"is not in 1..{n - 1}"
                        conn.sendall(
                            f"--process-id {i} {taken} in the run of {n} processes".encode()
                        )
                if conn is not None:
                    conn.close()
    for conn in held.values():
        conn.close()


def _claim_id(args: argparse.Namespace, where: str) -> None:
    """Claim ``--process-id`` from process 0 (retrying until it listens): ValueError if it
    refuses, or if the run has started (every id claimed: XLA's runtime holds the port)."""
    host, _, port = args.coordinator.rpartition(":")
    while True:
        try:
            with socket.create_connection((host.strip("[]"), int(port)), timeout=5) as conn:
                conn.sendall(str(args.process_id).encode())
                answer = conn.recv(200)
                if answer == b"ok":
                    conn.settimeout(None)
                    conn.recv(1)  # until process 0 has every id and closes the claims
                    return
        except OSError:
            time.sleep(0.5)
            continue
        why = f"--process-id {args.process_id} is already taken (the run at {where} has started)"
        why = answer.decode() if answer.startswith(b"--") else why
        raise ValueError(f"{why}: give each process its own --process-id, 0 .. --num-processes - 1")


def _watch(runtime, silence: float) -> None:
    """Beat every second in the key-value store; when another process's beats stop for
    ``silence`` seconds, end this one with one line (before XLA's own heartbeat check aborts it
    with a C++ trace), its writes in flight removed; one that ends says so (:func:`_leave`)."""
    me, n, beats, stop = runtime.process_id, runtime.num_processes, {}, threading.Event()
    atexit.register(_leave, runtime, stop, threading.current_thread())
    while not stop.wait(1):
        try:
            runtime.client.key_value_increment(f"jaxais/alive/{me}", 1)
            counts = dict(runtime.client.key_value_dir_get("jaxais/alive/"))
        except Exception:  # noqa: BLE001 (process 0, the store, is gone: XLA ends this one)
            return
        now = time.monotonic()
        for peer in set(range(n)) - {me}:
            count = counts.get(f"jaxais/alive/{peer}")
            if peer not in beats or beats[peer][0] != count:
                beats[peer] = (count, now)
            elif now - beats[peer][1] > silence and count != "ended":
                ON_LOST[0](lost(peer))


def _leave(runtime, stop: threading.Event, beating: threading.Thread) -> None:
    """At exit, before JAX's shutdown waits for every process (process 0 may still be writing):
    stop beating (a thread inside XLA's client when Python finalizes aborts the process) and
    tell the others that this process ended, not died."""
    stop.set()
    beating.join(5)
    with contextlib.suppress(Exception):
        runtime.client.key_value_set(f"jaxais/alive/{runtime.process_id}", "ended", True)


def lost_peer(err: BaseException) -> bool:
    """Whether ``err`` is a joined run's collective failing (gloo's error, a JaxRuntimeError or
    a ValueError), as it does when a process went away."""
    jax = sys.modules.get("jax")
    joined = jax is not None and jax._src.distributed.global_state.client is not None
    return joined and isinstance(err, Exception) and "gloo" in str(err).lower()


def lost(peer: int | None = None) -> str:
    """The one line for a run that lost process ``peer`` (None: the other, or unknown)."""
    from jax._src import distributed as state

    me, n = state.global_state.process_id, state.global_state.num_processes
    peer = (1 - me if n == 2 else None) if peer is None else peer
    who = "another process" if peer is None else f"process {peer}"
    ABANDONED.append(state.global_state.client)
    return (
        f"{who} of {n} stopped responding (killed, or its machine is unreachable); nothing "
        f"half-written is left: rerun all {n} processes"
    )


def _why_not_joined(args: argparse.Namespace, where: str) -> str:
    """The one line for a join that timed out: the cause where this process can see it."""
    if args.coordinator != "auto" and args.process_id != 0:
        host, _, port = args.coordinator.rpartition(":")
        try:
            socket.create_connection((host.strip("[]"), int(port)), timeout=5).close()
        except OSError as err:
            return (
                f"no coordinator answers at {where} ({os.strerror(err.errno) if err.errno else err}"
                f" after {args.timeout_s:g} s): start process 0 (it hosts the coordinator), or "
                "fix --coordinator"
            )
    return (
        f"not every process joined at {where} within {args.timeout_s:g} s: start all "
        f"{args.num_processes or ''} processes with the same --coordinator and --num-processes, "
        "each with its own --process-id (0 hosts the coordinator), or allow more --timeout-s"
    )


def _agree(args: argparse.Namespace, runtime) -> None:
    """Every process publishes its flags and compares all: one line names those that differ."""
    mine = {k: v for k, v in vars(args).items() if k not in PER_PROCESS}
    runtime.client.key_value_set(f"jaxais/flags/{runtime.process_id}", json.dumps(mine))
    runtime.client.wait_at_barrier("jaxais/flags", int(args.timeout_s * 1000))
    for key, value in sorted(runtime.client.key_value_dir_get("jaxais/flags/")):
        theirs = json.loads(value)
        differ = sorted(k for k in set(mine) | set(theirs) if mine.get(k) != theirs.get(k))
        if differ:
            flags = [("--" + k.replace("_", "-"), theirs.get(k), mine.get(k)) for k in differ]
            raise ValueError(
                f"process {key.rsplit('/', 1)[1]} was started with "
                + ", ".join(f"{flag} {there}" for flag, there, _ in flags)
                + f" and this one ({runtime.process_id}) with "
                + ", ".join(f"{flag} {here}" for flag, _, here in flags)
                + ": start every process with the same flags"
            )


def batch_sharding(devices=None):
    """A batch's first axis sharded over ``devices`` (default: every process's) on a 1-D
    ``("batch",)`` mesh; None with a single device."""
    import jax
    import numpy as np

    devices = jax.devices() if devices is None else list(devices)
    if len(devices) < 2:
        return None
    mesh = jax.sharding.Mesh(np.array(devices), ("batch",))
    return jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("batch"))


def replicated(sharding):
    """The replicated sharding on ``sharding``'s mesh (what every host reads back)."""
    import jax

    return jax.sharding.NamedSharding(sharding.mesh, jax.sharding.PartitionSpec())
