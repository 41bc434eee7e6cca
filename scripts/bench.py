"""Benchmark the simulator on this machine and write the figures to a JSON file.

    python scripts/bench.py --out bench.json [--world world1] [--steps 200] [--quick]
        [--batches 1,30,1000,10000] [--repeats 5] [--numpy-robots 30] [--numpy-steps 20]
        [--matmul 2048] [--devices N] [--scripts 3]

Measures the simulator's robot-steps per second per batch size (one device and sharded), the
NumPy reference's, the STL controller's iterations per second, the GA's and the STL's loops side
by side (loop_rates, stl_over_ga), flops per step against the
matmul peak, and with --scripts N the wall time of evolve.py's default run and 30 SIE trials
end to end (jaxais.experiments.bench.run_bench). --quick uses fewer steps, repeats and batch
sizes (explicit flags still win).
"""

from __future__ import annotations

import argparse
import os
import time

from jaxais.cli import ArgumentParser, check_output_file, main_wrapper, run_script
from jaxais.experiments import bench

FLAGS = (
    ("--steps", int, "scan length per timed call (200; quick 50)"),
    ("--batches", str, "comma-separated batch sizes (1,30,1000,10000; quick 1,30,1000)"),
    ("--repeats", int, "timed calls per batch size (5; quick 2)"),
    ("--numpy-robots", int, "robots for the NumPy reference (30; quick 4)"),
    ("--numpy-steps", int, "steps per NumPy robot (20; quick 5)"),
    ("--matmul", int, "matrix size of the peak benchmark (2048; quick 512)"),
    ("--controller-batches", str, "STL controller batch sizes (30,1000; quick 30)"),
    ("--controller-steps", int, "iterations per timed call (500; quick 50)"),
    ("--loop-trials", str, "STL loop rates' SIE trial counts (30,300,1000; quick 30; 0: none)"),
)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = ArgumentParser(prog="bench.py", description="Benchmark the JAX e-puck simulator.")
    p.add_argument("--out", default="bench.json", help="output JSON file (default bench.json)")
    p.add_argument("--world", default="world1", help="built-in world name or .toml path")
    p.add_argument("--quick", action="store_true", help="fewer steps, repeats and batch sizes")
    for flag, kind, text in FLAGS:
        p.add_argument(flag, type=kind, help=text)
    p.add_argument(
        "--devices", type=int, help=f"N host devices ({bench.DEVICE_FLAG}=N; default: one per core)"
    )
    p.add_argument(
        "--scripts", type=int, default=0,
        help="also time evolve.py's default run and 30 SIE trials with trials.py end to end, "
        "N runs each (default 0: skipped)",
    )  # fmt: skip
    return p.parse_args(argv)


@main_wrapper("bench.py")
def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    names = [flag[2:].replace("-", "_") for flag, _, _ in FLAGS]
    config = bench.bench_config(
        args.quick, world=args.world, scripts=args.scripts, **{n: getattr(args, n) for n in names}
    )
    check_output_file(args.out, (".json",))
    environ = dict(os.environ)
    # One CPU device per core by default, so the sharded figures (every core busy) are measured
    # beside the one-device ones; --devices 1 measures one device only.
    cores = len(os.sched_getaffinity(0))
    bench.force_host_devices(cores if args.devices is None else args.devices)
    from jaxais import _speed

    _speed.setup(cache=False)  # the scripts' XLA flags; no cache, since compile time is measured
    t0 = time.perf_counter()
    b = bench.run_bench(config, args.out, environ)
    print("bench.py: " + bench.summary(b, args.out, time.perf_counter() - t0))


if __name__ == "__main__":
    run_script(main)
