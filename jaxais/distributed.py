"""Runs across processes and machines with JAX's own multi-process runtime (``jax.distributed``).

Every process runs the same script with the same arguments; :func:`initialize` joins them into
one JAX runtime, after which ``jax.devices()`` lists every process's devices. A batch of runs is
then sharded over a 1-D mesh of all of them (:func:`batch_sharding`): each device runs its share
of the runs, and the readouts every host needs come back replicated, so every process follows
the same host logic and writes the same results. A run's numbers do not depend on where it ran:
the results are those of one process, bit for bit.

Tell a process where it stands by flags (:func:`add_arguments`: ``--coordinator HOST:PORT
--num-processes N --process-id I``) or by environment variables (``JAXAIS_COORDINATOR``,
``JAXAIS_NUM_PROCESSES``, ``JAXAIS_PROCESS_ID``). Under SLURM or Open MPI, ``--coordinator auto``
lets JAX read the cluster's own variables. On CPUs the processes exchange data through gloo.
"""

from __future__ import annotations

import argparse
import os

ENV = {
    "coordinator": "JAXAIS_COORDINATOR",
    "num_processes": "JAXAIS_NUM_PROCESSES",
    "process_id": "JAXAIS_PROCESS_ID",
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The flags of a multi-process run (each defaults to its environment variable)."""
    group = parser.add_argument_group("across processes (jax.distributed)")
    group.add_argument(
        "--coordinator",
        default=os.environ.get(ENV["coordinator"]),
        metavar="HOST:PORT",
        help="process 0's address: join a multi-process run (or 'auto' under SLURM/Open MPI; "
        f"default ${ENV['coordinator']}, unset: one process)",
    )
    group.add_argument(
        "--num-processes",
        type=int,
        default=_env_int("num_processes"),
        help=f"processes in the run (default ${ENV['num_processes']})",
    )
    group.add_argument(
        "--process-id",
        type=int,
        default=_env_int("process_id"),
        help=f"this process's index, 0 .. N-1 (default ${ENV['process_id']})",
    )


def _env_int(name: str) -> int | None:
    value = os.environ.get(ENV[name])
    if value is None or value == "":
        return None
    try:
        return int(value)
    except ValueError:
        raise ValueError(f"${ENV[name]} must be an integer, got {value!r}") from None


def check(args: argparse.Namespace) -> None:
    """Reject inconsistent flags before JAX starts (one-line ValueErrors)."""
    if args.coordinator in (None, "", "auto"):
        if args.coordinator != "auto" and (args.num_processes or args.process_id is not None):
            raise ValueError("--num-processes and --process-id need --coordinator HOST:PORT")
        return
    host, _, port = args.coordinator.rpartition(":")
    if not host or not port.isdigit():
        raise ValueError(f"--coordinator must be HOST:PORT, got {args.coordinator!r}")
    if args.num_processes is None or args.num_processes < 1:
        raise ValueError("--coordinator needs --num-processes N (N >= 1)")
    if args.process_id is None or not 0 <= args.process_id < args.num_processes:
        raise ValueError(
            f"--process-id must be in [0, {args.num_processes}), got {args.process_id}"
        )


def initialize(args: argparse.Namespace) -> bool:
    """Join the multi-process run the flags describe; False (and nothing done) for one process.

    Must run before JAX computes anything.
    """
    check(args)
    if args.coordinator in (None, ""):
        return False
    import jax

    if jax.config.jax_platforms in (None, "", "cpu"):
        # CPU devices of different processes exchange data through gloo.
        jax.config.update("jax_cpu_collectives_implementation", "gloo")
    if args.coordinator == "auto":
        jax.distributed.initialize()
    else:
        jax.distributed.initialize(
            args.coordinator, num_processes=args.num_processes, process_id=args.process_id
        )
    return True


def batch_sharding(devices=None):
    """The sharding of a batch of runs along its first axis over ``devices`` (default: every
    process's), a ``NamedSharding`` over a 1-D ``("batch",)`` mesh; None with a single device."""
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
