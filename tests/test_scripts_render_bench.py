"""End-to-end tests of scripts/render.py and scripts/bench.py (run as subprocesses; mistakes
answered after JAX loads through the script's ``main``, ``_python.call_main``), and of the error
and atomic-write helpers in jaxais.cli that they share."""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from _python import call_main, run_python

from jaxais import cli
from jaxais.experiments import bench

REPO = Path(__file__).resolve().parent.parent
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def load_script(name: str):
    """scripts/{name}.py as a module (its ``main`` is not run)."""
    module_name = f"jaxais_scripts_{name}"
    if module_name not in sys.modules:  # registered: dataclasses look their module up
        spec = importlib.util.spec_from_file_location(module_name, REPO / "scripts" / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules[module_name] = module
        spec.loader.exec_module(module)
    return sys.modules[module_name]


def run_script(name: str, *args: object, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, str(REPO / "scripts" / name), *map(str, args)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def assert_user_error(proc: subprocess.CompletedProcess, prog: str, *words: str) -> None:
    """Exit status 2, exactly one line on stderr in the ``prog: error: ...`` form."""
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith(f"{prog}: error: "), lines[0]
    for word in words:
        assert word in lines[0]


# ---------------------------------------------------------------------------------- render.py


@pytest.mark.slow
def test_render_writes_png_and_gif(tmp_path):
    out, gif = tmp_path / "w.png", tmp_path / "w.gif"
    args = ("--world", "world1", "--steps", 20, "--robots", 2, "--seed", 3)
    proc = run_script("render.py", *args, "--out", out, "--gif", gif, "--every", 5)
    assert proc.returncode == 0, proc.stderr
    assert out.read_bytes()[:8] == PNG_MAGIC
    assert gif.read_bytes()[:6] in (b"GIF87a", b"GIF89a")
    assert proc.stdout.count("\n") == 1 and "wrote" in proc.stdout and "w.gif" in proc.stdout
    assert sorted(p.name for p in tmp_path.iterdir()) == ["w.gif", "w.png"]  # no temp files left


def test_render_bad_world_path(tmp_path):
    out = tmp_path / "w.png"
    out.write_bytes(b"old")
    proc = call_main("render.py", "--world", tmp_path / "nope.toml", "--steps", 5, "--out", out)
    assert_user_error(proc, "render.py", "nope.toml")
    assert out.read_bytes() == b"old"  # a failed run leaves an earlier output alone


SMALL_WORLD = """
name = "small"
[arena]
width = 1.0
height = 1.0
wall_height = 0.1
[robot]
start_region = [0.1, 0.1, 0.4, 0.4]
[goal]
shape = "box"
half_size = [0.05, 0.05]
height = 0.1
region = [0.6, 0.6, 0.9, 0.9]
"""
"""A valid world file: 7 surfaces (4 walls, a padding box and pillar, the goal)."""


def many_walls(n: int) -> str:
    """:data:`SMALL_WORLD` with ``n`` short walls more."""
    return SMALL_WORLD + "".join(
        f"[[walls]]\nfrom = [{0.05 + 0.004 * k:.3f}, 0.95]\nto = [{0.05 + 0.004 * k:.3f}, 1.0]\n"
        for k in range(n)
    )


@pytest.mark.parametrize(
    "text, words",
    [
        ("name = [unclosed\n", ["TOML"]),
        ('name = "x"\n[arena]\nwidth = 1.0\n', ["arena.height"]),
        # More surfaces than the ray caster tells apart (it asserted inside JAX before).
        (many_walls(200), ["has 207 surfaces", "at most 64 are supported", "remove at least 143"]),
        (SMALL_WORLD.replace("[robot]", "[[pilars]]\ncenter = [0.5, 0.5]\nradius = 0.05\n[robot]"),
         ["'pilars': unknown table (did you mean 'pillars'?)"]),
        (SMALL_WORLD.replace("width = 1.0", "width = 1e29"), ["arena.width", "(0, 100] m"]),
    ],
)  # fmt: skip
def test_render_malformed_world(tmp_path, text, words):
    world = tmp_path / "bad.toml"
    world.write_text(text)
    out = tmp_path / "w.png"
    out.write_bytes(b"old")
    proc = call_main("render.py", "--world", world, "--steps", 5, "--out", out)
    assert_user_error(proc, "render.py", *words)
    assert out.read_bytes() == b"old" and sorted(p.name for p in tmp_path.iterdir()) == [
        "bad.toml",
        "w.png",
    ]


@pytest.mark.slow
def test_render_world_just_within_the_surface_limit(tmp_path):
    world = tmp_path / "full.toml"
    world.write_text(many_walls(57))  # 64 surfaces: the most a world may have
    out = tmp_path / "w.png"
    proc = run_script("render.py", "--world", world, "--steps", 5, "--robots", 1, "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert out.read_bytes()[:8] == PNG_MAGIC


@pytest.mark.parametrize(
    "args, word",
    [
        (("--steps", 0), "--steps"),
        (("--robots", -2), "--robots"),
        (("--every", 0, "--gif", "x.gif"), "--every"),
        (("--fps", 5), "--fps applies to --gif only"),  # ignored before
        (("--robots", 10**9), "--robots x --steps 5000000000 needs about"),  # grew, unbounded
        (("--out", "no/such/dir/w.png"), "does not exist"),
        (("--out", "w.txt"), ".png"),
        (("--gif", "w.mp4"), ".gif"),
    ],
)
def test_render_bad_values(tmp_path, args, word):
    base = ["--steps", 5, "--out", tmp_path / "w.png"]
    proc = call_main("render.py", *base, *args)
    assert_user_error(proc, "render.py", word)


def test_render_bad_flag_is_one_line():
    proc = run_script("render.py", "--out", "x.png", "--no-such-flag", timeout=60)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("render.py: error:"), proc.stderr
    assert "--no-such-flag" in lines[0] and "Traceback" not in proc.stderr


# ---------------------------------------------------------------------------------- bench.py


@pytest.mark.slow
def test_bench_quick_json(tmp_path):
    out = tmp_path / "bench.json"
    proc = run_script(
        "bench.py",
        *("--quick", "--devices", 2, "--batches", 2, "--steps", 3, "--repeats", 1),
        *("--numpy-robots", 2, "--numpy-steps", 2, "--matmul", 64, "--out", out),
        # 3 robots do not split over 2 devices: the controller's sharded layout is skipped
        *("--controller-batches", 3, "--controller-steps", 5, "--loop-trials", 0),
    )
    assert proc.returncode == 0, proc.stderr
    r = json.loads(out.read_text())
    for key in (
        "machine",
        "config",
        "jax_steps_per_s",
        "compile_s",
        "numpy_steps_per_s",
        "speedup_vs_numpy",
        "flops_per_step",
        "peak_flops",
        "fraction_of_peak",
        "jax_steps_per_s_sharded",
    ):
        assert key in r, key
    assert set(r["jax_steps_per_s"]) == {"2"} and r["jax_steps_per_s"]["2"] > 0
    assert r["machine"]["device_count"] == 2  # --devices took effect before JAX was imported
    assert set(r["jax_steps_per_s_sharded"]) == {"2"}
    assert set(r["controller_iterations_per_s"]) == {"3"} and not r["controller_compile_s_sharded"]
    assert set(r["env_steps_per_s"]) == {"step", "step_env", "step_refresh"}
    assert r["flops_per_step"] > 0 and 0 < r["fraction_of_peak"] < 1
    assert {"platform", "cpu_count", "jax", "backend", "device_kinds", "date"} <= set(r["machine"])
    assert "wrote" in proc.stdout


@pytest.mark.slow
def test_bench_sets_the_stl_loop_beside_the_gas(monkeypatch):
    """``loop_rates``: each loop in a child process set up as its script sets it up, and the
    STL's CPU cost per robot-iteration over the GA's (``stl_over_ga``)."""
    monkeypatch.setattr(bench, "GA_ROBOTS", 2)
    environ = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}  # as the scripts start
    b = bench.Bench(config=bench.bench_config(loop_trials="2"), world=None, params=None,
                    environ=environ)  # fmt: skip
    bench.bench_loops(b)
    loops = b.results["loop_rates"]
    ga, stl = loops["ga"], loops["stl"]["2"]
    assert ga["robots"] == 2 and ga["robot_iterations"] % 2 == 0 and ga["per_cpu_s"] > 0
    assert stl["robot_iterations"] > 0 and stl["per_wall_s"] > 0
    assert loops["stl_over_ga"]["2"] == pytest.approx(ga["per_cpu_s"] / stl["per_cpu_s"])
    b.results["load_average_end"] = [0.0]
    assert "loops, robot-iterations per CPU-s: GA" in bench.summary(b, "b.json", 1.0)


def test_bench_bad_values(tmp_path):
    proc = run_script("bench.py", "--batches", "1,x", "--out", tmp_path / "b.json", timeout=60)
    assert_user_error(proc, "bench.py", "--batches")
    proc = run_script("bench.py", "--scripts", -1, "--out", tmp_path / "b.json", timeout=60)
    assert_user_error(proc, "bench.py", "--scripts", "-1")
    proc = run_script("bench.py", "--world", tmp_path / "nope.toml", "--out", tmp_path / "b.json")
    assert_user_error(proc, "bench.py", "nope.toml")
    assert not (tmp_path / "b.json").exists()


PROBE = """
import os, sys
args = sys.argv[1:]
out = args[args.index("--out") + 1]
open(out, "w").close()  # its folder exists
with open(os.environ["PROBE_LOG"], "a") as log:
    log.write(" ".join([os.environ.get("JAXAIS_CACHE_DIR", "-"), os.environ.get("XLA_FLAGS", "-"),
                        *args[:-2]]) + "\\n")
if "--fail" in args:
    sys.exit("probe.py: error: it broke")
"""


def test_bench_scripts_times_each_command_in_turn(tmp_path, monkeypatch):
    probe, log = tmp_path / "probe.py", tmp_path / "log"
    probe.write_text(PROBE)
    runs = (
        bench.ScriptRun("a", (str(probe), "--x", "1"), "a.json", 60.0),
        bench.ScriptRun("b", (str(probe),), "b", 0.0),
    )
    monkeypatch.setattr(bench, "SCRIPT_RUNS", runs)
    # The scripts get the environment the benchmark started with, not the benchmark's own.
    monkeypatch.setenv("XLA_FLAGS", "--xla_force_host_platform_device_count=7")
    environ = {"PROBE_LOG": str(log), "PATH": "/usr/bin:/bin"}
    config = bench.BenchConfig(scripts=0, repeats=1, steps=1)
    b = bench.Bench(config=config, world=None, params=None, environ=environ)
    bench.bench_scripts(b)
    assert "scripts" not in b.results and not log.exists()  # 0 runs: skipped

    b.config = dataclasses.replace(config, scripts=2)
    bench.bench_scripts(b)
    assert log.read_text().splitlines() == ["off - --x 1", "off -", "off - --x 1", "off -"]
    a, bb = b.results["scripts"]["a"], b.results["scripts"]["b"]
    assert a["command"] == f"{probe} --x 1 --out a.json" and a["target_s"] == 60.0
    assert len(a["times_s"]) == len(bb["times_s"]) == 2
    assert a["min_s"] == min(a["times_s"]) and a["max_s"] == max(a["times_s"]) > 0
    assert a["min_s"] <= a["median_s"] <= a["max_s"]
    assert (a["within_target"], bb["within_target"]) == (2, 0)
    b.results["load_average_end"] = [0.0]
    text = bench.summary(b, "b.json", 1.0)
    assert "--x 1 --out a.json: 2 runs" in text and "(target 60 s: 2 of 2 within)" in text
    assert "(target 0 s: 0 of 2 within)" in text

    monkeypatch.setattr(
        bench, "SCRIPT_RUNS", (bench.ScriptRun("c", (str(probe), "--fail"), "c", 1),)
    )
    with pytest.raises(ChildProcessError, match="probe.py exited with status 1: .*it broke"):
        bench.bench_scripts(b)


def test_bench_script_commands_parse():
    """The commands ``--scripts`` times are valid for the scripts they run."""
    assert [run.name for run in bench.SCRIPT_RUNS] == ["evolve", "trials"]
    evolve, trials = (
        load_script(run.argv[0].removesuffix(".py")).parse_args([*run.argv[1:], "--out", "x"])
        for run in bench.SCRIPT_RUNS
    )
    assert evolve.out == trials.out == "x"
    assert (evolve.populations, evolve.robots, evolve.generations) == (5, 10, 200)
    assert (trials.system, trials.world, trials.trials) == ("SIE", "world1", 30)


# ---------------------------------------------------------------------------------- jaxais.cli


def test_main_wrapper_exit_codes(capsys):
    @cli.main_wrapper("prog.py")
    def bad(exc: BaseException) -> None:
        raise exc

    for exc, code, text in [
        (cli.UserError("bad\nthing"), 2, "prog.py: error: bad thing\n"),
        (ValueError("nope"), 2, "prog.py: error: nope\n"),
        (FileNotFoundError(2, "No such file or directory", "a.toml"), 2, "a.toml: No such"),
        (KeyboardInterrupt(), 130, "prog.py: error: interrupted\n"),
    ]:
        with pytest.raises(SystemExit) as info:
            bad(exc)
        assert info.value.code == code
        assert text in capsys.readouterr().err
    with pytest.raises(ZeroDivisionError):  # bugs keep their traceback
        bad(ZeroDivisionError())


def test_atomic_write_leaves_nothing_on_failure(tmp_path):
    path = tmp_path / "x.json"
    cli.atomic_write_json(path, {"a": 1})
    assert json.loads(path.read_text()) == {"a": 1}

    def broken(tmp: Path) -> None:
        tmp.write_text("half")
        raise RuntimeError("disk on fire")

    with pytest.raises(RuntimeError):
        cli.atomic_write(path, broken)
    assert json.loads(path.read_text()) == {"a": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["x.json"]
    with pytest.raises(cli.UserError):
        cli.check_writable_dir(tmp_path / "missing")


@pytest.mark.parametrize(
    "body, status, out, err",
    [
        ("print('done', end='')", 0, "done", ""),  # unflushed output still comes out
        ("return {'summary': 1}", 0, "", ""),  # a result for in-process callers is not a status
        ("raise SystemExit(2)", 2, "", ""),
        ("sys.exit('stopped')", 1, "", "stopped"),
        ("1 / 0", 1, "", "ZeroDivisionError"),  # a bug keeps its traceback
    ],
)
def test_run_script_exits_with_mains_status(body, status, out, err):
    code = (
        "import atexit, sys\n"
        "from jaxais.cli import run_script\n"
        "atexit.register(lambda: print('teardown ran', file=sys.stderr))\n"
        f"def main():\n    {body}\n"
        "run_script(main)\n"
    )
    proc = run_python(code, timeout=60)
    assert proc.returncode == status
    assert proc.stdout == out
    assert err in proc.stderr
    # The process ends the usual way: atexit handlers run (jax.distributed's shutdown is one).
    assert "teardown ran" in proc.stderr


# ---------------------------------------------------------------------------------- plotting


def test_world_figure_without_state(tmp_path):
    import numpy as np

    from jaxais import envs
    from jaxais.experiments import plotting

    world = envs.load_world("real")
    traj = np.stack([np.linspace(0.2, 1.0, 50), np.full(50, 0.5)], axis=1)
    fig = plotting.world_figure(world, trajectories=[traj], title="real")
    path = tmp_path / "real.png"
    plotting.save_figure(fig, path)
    assert path.read_bytes()[:8] == PNG_MAGIC
    ax = fig.axes[0]
    assert ax.get_aspect() == 1.0
    assert [t.get_text() for t in ax.get_legend().get_texts()][-1] == "robot 0"


def test_figures_show_in_a_notebook_as_png(monkeypatch, tmp_path):
    from IPython.core.formatters import DisplayFormatter
    from IPython.core.interactiveshell import InteractiveShell
    from IPython.utils.capture import capture_output
    from matplotlib.figure import Figure
    from traitlets.config import Config

    import jaxais.experiments as x
    from jaxais import envs
    from jaxais.experiments import plotting

    # IPython's own formatter: a PNG for ours, only text for a plain pyplot-free Figure.
    fig = plotting.world_figure(envs.load_world("world1"))
    assert DisplayFormatter().format(fig)[0]["image/png"][:8] == PNG_MAGIC
    assert "image/png" not in DisplayFormatter().format(Figure())[0]
    # plot=True shows the plot in a notebook: outside one it is refused before anything runs.
    with pytest.raises(ValueError, match="^plot=True shows the plot in a notebook") as info:
        x.trials("HDC", plot=True, trials=1)
    assert "\n" not in str(info.value)
    with pytest.raises(ValueError, match="no notebook"):
        plotting.show(fig)
    # Inside one (a running IPython shell), the figure is the cell's PNG output.
    monkeypatch.setenv("IPYTHONDIR", str(tmp_path))
    config = Config()
    config.HistoryManager.enabled = False
    InteractiveShell.instance(config=config)
    try:
        with capture_output() as cell:
            plotting.show(fig)
    finally:
        InteractiveShell.clear_instance()
    assert [o.data["image/png"][:8] for o in cell.outputs] == [PNG_MAGIC]


def _patch_centres(ax) -> dict[str, list[tuple[float, float]]]:
    """Centres of the drawn rectangles and circles, by kind."""
    from matplotlib.patches import Circle, Rectangle

    out: dict[str, list[tuple[float, float]]] = {"rect": [], "circle": []}
    for p in ax.patches:
        if isinstance(p, Rectangle) and p.get_fill():
            out["rect"].append((p.get_x() + p.get_width() / 2, p.get_y() + p.get_height() / 2))
        elif isinstance(p, Circle):
            out["circle"].append(tuple(p.center))
    return out


def test_figures_draw_boxes_and_goal_where_the_trial_had_them(tmp_path):
    """``real`` places its 4 boxes and its goal ball at random: a trial's placement, not the
    regions' centres (where they would all sit on one spot)."""
    import numpy as np
    from matplotlib.colors import to_rgb
    from matplotlib.figure import Figure

    from jaxais import envs
    from jaxais.experiments import plotting, report
    from jaxais.trials import Placement

    world = envs.load_world("real")
    valid = np.asarray(world.box_valid)
    n_boxes = int(valid.sum())
    boxes = np.asarray(world.box_region)[:, :2].copy()
    boxes[valid] = [[0.3 + 0.15 * k, 0.4 + 0.1 * k] for k in range(n_boxes)]
    placement = Placement(boxes=boxes, goal=np.array([0.9, 1.0]))

    ax = Figure().add_subplot()
    plotting.draw_world(ax, world, placement)
    drawn = _patch_centres(ax)
    for b in boxes[valid]:
        assert any(np.allclose(b, c) for c in drawn["rect"]), (b, drawn["rect"])
    assert any(np.allclose([0.9, 1.0], c) for c in drawn["circle"])
    centre = np.asarray(world.box_region)[valid][0]
    assert not any(np.allclose(0.5 * (centre[:2] + centre[2:]), c) for c in drawn["rect"])

    # world_figure: one placement per trajectory, each outlined in its trajectory's colour.
    other = Placement(boxes=boxes + 0.05, goal=np.array([0.3, 1.0]))
    traj = np.stack([np.linspace(0.2, 1.0, 20), np.full(20, 0.5)], axis=1)
    fig = plotting.world_figure(world, states=[placement, other], trajectories=[traj, traj + 0.1])
    drawn = _patch_centres(fig.axes[0])
    for goal in ([0.9, 1.0], [0.3, 1.0]):
        assert any(np.allclose(goal, c) for c in drawn["circle"])
    edges = {tuple(p.get_edgecolor()[:3]) for p in fig.axes[0].patches if p.get_fill()}
    assert {to_rgb(plotting.ROBOT_COLOURS[0]), to_rgb(plotting.ROBOT_COLOURS[1])} <= edges
    plotting.save_figure(fig, tmp_path / "two.png")
    assert (tmp_path / "two.png").read_bytes()[:8] == PNG_MAGIC

    # The report's trajectory figure hands each system's placement to the world drawer.
    calls = []
    report._trajectory_figure(
        "real",
        {"SIE": traj, "HDC": traj},
        lambda ax, name, placement=None: calls.append((name, placement)),
        tmp_path / "traj.png",
        {"SIE": placement},
    )
    assert sorted(calls, key=lambda c: c[1] is None) == [("real", placement), ("real", None)]
    assert (tmp_path / "traj.png").read_bytes()[:8] == PNG_MAGIC
