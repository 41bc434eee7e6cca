"""World files: the built-in worlds load and reset sensibly; malformed files fail clearly."""

from __future__ import annotations

import os
import re
from pathlib import Path

import jax
import numpy as np
import pytest
import reference_sim as ref
from _python import run_python, script_env

from jaxais import envs
from jaxais.envs import names
from jaxais.envs.sim import PLACEMENT_CLEARANCE
from jaxais.experiments import protocol

PARAMS_NP = ref.params_to_numpy(envs.default_params())

# The paper's worlds (the LTL's and the three test worlds), which the built-ins must include:
# name: (wanderers, goal shape, noisy). Other files in envs/worlds/ are built-ins too.
PAPER_WORLDS = {
    "ga_maze": (0, "box", False),
    "world1": (1, "box", False),
    "world2": (1, "box", False),
    "real": (2, "ball", True),
}


def test_the_papers_worlds_are_built_in() -> None:
    assert set(PAPER_WORLDS) <= set(envs.BUILTIN_WORLDS)
    assert set(protocol.WORLDS) <= set(PAPER_WORLDS)


@pytest.mark.parametrize("name", envs.BUILTIN_WORLDS)
def test_builtin_world_loads(name: str) -> None:
    world = envs.load_world(name)
    assert world.name == name
    assert envs.world_path(name).is_file()
    extra = (world.ir_noise, world.camera_miss, world.camera_shift, world.wheel_noise)
    if name in PAPER_WORLDS:
        n_wanderers, shape, noisy = PAPER_WORLDS[name]
        assert world.n_wanderers == n_wanderers
        assert world.goal_shape == shape
        assert all(v > 0 for v in extra) == noisy
        assert not noisy or extra == (0.05, 0.05, 0.1, 0.05)
    assert int(world.seg_valid.sum()) >= 4  # the outer walls come first
    arena = np.asarray(world.arena)
    np.testing.assert_allclose(np.asarray(world.seg[:4]).reshape(4, 2, 2).min(axis=(0, 1)), 0.0)
    np.testing.assert_allclose(
        np.asarray(world.seg[:4]).reshape(4, 2, 2).max(axis=(0, 1)), arena[2:], rtol=1e-6
    )
    for leaf in jax.tree.leaves(world):
        assert leaf.dtype in (np.float32, np.int32, np.bool_)
    if name == "ga_maze":  # a stripe behind each of doorways 1-2 (two segments each)
        assert int((np.asarray(world.seg_material) == envs.MARKER).sum()) == 4
    if name == "real":
        np.testing.assert_allclose(arena, [0, 0, 1.26, 1.26], rtol=1e-6)
        np.testing.assert_allclose(world.seg_height[:4], 0.165, rtol=1e-6)


def _overlaps(a: ref.Surface, b: ref.Surface, tol: float = 1e-6) -> bool:
    """Whether a box or circle ``a`` overlaps surface ``b`` by more than ``tol``."""
    if a.kind == "circle":
        gap = ref.disc_gap(a.geom[:2], a.geom[2], b)[0]
        return gap < -tol
    lo, hi = np.array(a.geom[:2]) + tol, np.array(a.geom[2:]) - tol  # shrunk a little
    if b.kind == "box":
        return bool(np.all(lo < np.array(b.geom[2:])) and np.all(np.array(b.geom[:2]) < hi))
    if b.kind == "circle":
        return _overlaps(b, a, tol)
    # A segment crosses the box when a ray along it hits the box before its end.
    start, end = np.array(b.geom[:2]), np.array(b.geom[2:])
    length = float(np.linalg.norm(end - start))
    d = (end - start) / length
    shrunk = ref.Surface("box", (*lo, *hi), a.material, a.height)
    return ref.ray_hit(tuple(start), tuple(d), shrunk) <= length


def _inside(p, region, tol: float = 1e-6) -> bool:
    return bool(np.all(p >= region[:2] - tol) and np.all(p <= region[2:] + tol))


@pytest.mark.parametrize("name", envs.BUILTIN_WORLDS)
def test_reset_places_everything_clear_and_in_its_region(sim, name: str) -> None:
    world = sim.world(name)
    wnp = ref.world_to_numpy(world)
    n_seg, n_box, n_pillar = (int(wnp[f"{k}_valid"].sum()) for k in ("seg", "box", "pillar"))
    for seed in range(3):
        state, gaps = sim.reset(world, sim.keys(seed))
        # Robot and wanderers: clear of everything, with the placement clearance.
        assert gaps.min() >= PLACEMENT_CLEARANCE - 1e-5, (seed, gaps.min(axis=0))
        batch = ref.state_to_numpy(state)
        for i in range(sim.batch):
            s = ref.unbatch(batch, i)
            assert _inside(s["pose"][:2], wnp["start_region"])
            lo, hi = wnp["start_heading"]
            assert lo - 1e-6 <= s["pose"][2] <= hi + 1e-6
            for k in range(world.n_wanderers):
                assert _inside(s["wanderers"][k, :2], wnp["wanderer_region"][k])
            assert _inside(s["goal"], wnp["goal_region"])
            for b in np.flatnonzero(wnp["box_valid"]):
                assert _inside(s["boxes"][b], wnp["box_region"][b])
            np.testing.assert_array_equal(s["wander_timer"], 0)
            assert int(s["t"]) == 0
            # Boxes, goal and robots overlap nothing (walls, pillars, boxes, each other) and
            # stay inside the arena. The scene lists walls, boxes (+ goal block), pillars,
            # robots (+ goal ball): everything but the walls and pillars was placed by reset.
            scene = ref.build_scene(s, wnp, PARAMS_NP, exclude=-1)
            first_pillar = n_seg + n_box + (world.goal_shape == "box")
            fixed = set(range(n_seg)) | set(range(first_pillar, first_pillar + n_pillar))
            for j, a in enumerate(scene):
                if j in fixed:
                    continue
                lo, hi = np.array(a.geom[:2]), np.array(a.geom[2:])
                if a.kind == "circle":
                    lo, hi = lo - a.geom[2], lo + a.geom[2]
                assert np.all(lo >= -1e-6) and np.all(hi <= wnp["arena"][2:] + 1e-6), a
                for k, b in enumerate(scene):
                    assert k == j or not _overlaps(a, b), (name, seed, i, a, b)


@pytest.mark.parametrize("name", envs.BUILTIN_WORLDS)
def test_reset_is_reproducible(sim, name: str) -> None:
    world = sim.world(name)
    a, _ = sim.reset(world, sim.keys(9))
    b, _ = sim.reset(world, sim.keys(9))
    c, _ = sim.reset(world, sim.keys(10))
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
        np.testing.assert_array_equal(x, y)
    assert not np.array_equal(a.pose, c.pose)
    assert not np.array_equal(a.pose[0], a.pose[1])  # each key its own draw


def test_capacity_pads_to_common_shapes() -> None:
    cap = envs.Capacity(segments=20, boxes=8, pillars=6)
    for name in envs.BUILTIN_WORLDS:
        plain, padded = envs.load_world(name), envs.load_world(name, cap)
        assert padded.seg.shape == (20, 4) and padded.seg_valid.shape == (20,)
        assert padded.box_half.shape == (8, 2) and padded.box_region.shape == (8, 4)
        assert padded.pillar.shape == (6, 3) and padded.pillar_valid.shape == (6,)
        for field in ("seg", "box", "pillar"):
            valid = np.asarray(getattr(plain, f"{field}_valid"))
            assert int(np.asarray(getattr(padded, f"{field}_valid")).sum()) == int(valid.sum())
        n = int(plain.seg_valid.sum())
        np.testing.assert_array_equal(padded.seg[:n], plain.seg[:n])
    w1, w2 = envs.load_world("world1", cap), envs.load_world("world2", cap)
    shapes = lambda w: [x.shape for x in jax.tree.leaves(w)]
    assert shapes(w1) == shapes(w2)


def test_capacity_worlds_share_compiled_functions() -> None:
    """Equal shapes from one Capacity; with the static fields matched, one compilation."""
    cap = envs.Capacity(segments=8, boxes=6, pillars=6)
    w1, w2 = envs.load_world("world1", cap), envs.load_world("world2", cap)
    assert jax.tree.structure(w1) != jax.tree.structure(w2)  # the names differ
    w2 = w2.replace(name=w1.name)
    assert jax.tree.structure(w1) == jax.tree.structure(w2)
    f = jax.jit(lambda w: w.seg.sum())
    f(w1)
    f(w2)
    assert f._cache_size() == 1


def test_padding_changes_no_reading() -> None:
    """The reference ignores padding; sensing at the same pose is the same padded or not."""
    cap = envs.Capacity(segments=20, boxes=8, pillars=6)
    plain, padded = envs.load_world("world2"), envs.load_world("world2", cap)
    n_box = plain.box_half.shape[0]
    state = {
        "pose": np.array([0.7, 0.2, 1.2]),
        "wanderers": np.array([[0.8, 0.9, 0.0]]),
        "wander_timer": np.zeros(1, np.int64),
        "wander_dir": np.ones(1),
        "goal": np.array([0.7, 1.35]),
        "boxes": np.asarray(plain.box_region)[:, :2].astype(np.float64),
    }
    state["t"] = np.int64(0)
    a = ref.ref_sense(state, None, plain, PARAMS_NP)
    padded_state = dict(
        state, boxes=np.concatenate([state["boxes"], np.full((8 - n_box, 2), -100.0)])
    )
    b = ref.ref_sense(padded_state, None, padded, PARAMS_NP)
    for key in ref.OBS_FIELDS:
        np.testing.assert_array_equal(a[key], b[key])


# ---------------------------------------------------------------------------------- errors

VALID = """
name = "tiny"

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

[[walls]]
from = [0.5, 0.0]
to = [0.5, 0.3]
material = "marker"

[[pillars]]
center = [0.7, 0.2]
radius = 0.04

[[wanderers]]
region = [0.1, 0.6, 0.4, 0.9]
"""


def test_valid_tiny_world_loads(tmp_path) -> None:
    path = tmp_path / "tiny.toml"
    path.write_text(VALID)
    world = envs.load_world(path)
    assert world.name == "tiny" and world.n_wanderers == 1
    assert int(world.seg_material[4]) == envs.MARKER


@pytest.mark.parametrize(
    ("old", "new", "field"),
    [
        ("height = 1.0\n", "", "arena.height"),  # missing field
        ("[goal]", "[goalx]", "goal"),  # missing table
        ("width = 1.0", 'width = "wide"', "arena.width"),  # wrong type
        ("width = 1.0", "width = true", "arena.width"),  # a bool is not a number
        ("[0.1, 0.1, 0.4, 0.4]", "[0.1, 0.1, 0.4]", "robot.start_region"),  # wrong length
        ("[0.1, 0.1, 0.4, 0.4]", "[0.0, 0.1, 0.4, 0.4]", "robot.start_region"),  # off the arena
        ("[0.1, 0.1, 0.4, 0.4]", "[0.1, 0.1, 1.4, 0.4]", "robot.start_region"),
        ("[0.1, 0.6, 0.4, 0.9]", "[0.1, 0.6, 0.4, 2.0]", "wanderers[0].region"),
        ("radius = 0.04", "radius = -0.04", "pillars[0].radius"),  # negative radius
        ('material = "marker"', 'material = "glass"', "walls[0].material"),  # unknown material
        ("half_size = [0.05, 0.05]", "half_size = [0.05, -0.05]", "goal.half_size"),
        ('shape = "box"', 'shape = "cone"', "goal.shape"),
        ("to = [0.5, 0.3]", "to = [0.5, 1.3]", "walls[0].to"),
        (
            'name = "tiny"',
            'name = "tiny"\n[noise]\ncamera_miss_prob = 2.0',
            "noise.camera_miss_prob",
        ),
        ('name = "tiny"', 'name = "tiny"\n[noise]\npixel_flip_prob = 0.1', "noise.pixel_flip_prob"),
        # A start region filled by a pillar: reset could never place the robot clear of it.
        (
            "center = [0.7, 0.2]\nradius = 0.04",
            "center = [0.25, 0.25]\nradius = 0.3",
            "robot.start_region",
        ),
        # A wall through the goal region: the goal could be placed on it.
        (
            "to = [0.5, 0.3]",
            "to = [0.5, 0.3]\n[[walls]]\nfrom = [0.75, 0.5]\nto = [0.75, 0.95]",
            "walls[1]",
        ),  # fmt: skip
        # A start region inside the goal's: wherever the goal lands, the robot starts on it.
        ("[0.1, 0.1, 0.4, 0.4]", "[0.74, 0.74, 0.76, 0.76]", "robot.start_region"),
        # A world's name names files and report rows: a plain name only.
        ('name = "tiny"', 'name = "../../etc/evil"', "name"),
        ('name = "tiny"', 'name = ""', "name"),
        ('name = "tiny"', 'name = "a\\nb"', "name"),
    ],
)
def test_malformed_world_fails_naming_file_and_field(tmp_path, old, new, field) -> None:
    assert old in VALID
    path = tmp_path / "bad.toml"
    path.write_text(VALID.replace(old, new, 1))
    with pytest.raises(envs.WorldError) as err:
        envs.load_world(path)
    message = str(err.value)
    assert "\n" not in message
    assert str(path) in message and f"'{field}'" in message, message


def test_a_byte_order_mark_is_read_and_the_regions_may_share_room(tmp_path) -> None:
    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf" + VALID.encode())  # as Windows' Notepad saves UTF-8
    assert envs.load_world(path).name == "tiny"
    # A start region inside the goal's with room beside any goal (the real world's are one).
    path.write_text(VALID.replace("[0.1, 0.1, 0.4, 0.4]", "[0.6, 0.6, 0.9, 0.9]"))
    assert envs.load_world(path).name == "tiny"


def test_bad_toml_fails_naming_the_file(tmp_path) -> None:
    path = tmp_path / "broken.toml"
    path.write_text(VALID.replace("width = 1.0", "width = = 1.0"))
    with pytest.raises(envs.WorldError, match="TOML") as err:
        envs.load_world(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


def test_missing_file_fails_naming_it(tmp_path) -> None:
    path = tmp_path / "nowhere.toml"
    with pytest.raises(envs.WorldError) as err:
        envs.load_world(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)
    with pytest.raises(envs.WorldError, match="world3"):
        envs.load_world("world3")


# ------------------------------------------------------ worlds by name: worlds/ and JAXAIS_WORLDS

ROOT = Path(__file__).resolve().parent.parent


def _user_world(folder: Path, name: str, field: str | None = None) -> Path:
    """world1.toml copied to ``folder/name.toml``, its name field set to ``field`` (``name``)."""
    folder.mkdir(parents=True, exist_ok=True)
    text = envs.world_path("world1").read_text()
    path = folder / f"{name}.toml"
    path.write_text(text.replace('name = "world1"', f'name = "{field or name}"', 1))
    return path


def _one_line(err: pytest.ExceptionInfo) -> str:
    message = str(err.value)
    assert "\n" not in message, message
    return message


def test_builtin_worlds_are_the_files_in_the_folder(tmp_path) -> None:
    assert names.scan(names.BUILTIN_DIR) == envs.BUILTIN_WORLDS
    assert all(envs.world_path(n).parent == names.BUILTIN_DIR for n in envs.BUILTIN_WORLDS)
    # A file dropped into the folder is a world (scanned here on a copy, not the package's).
    for name in envs.BUILTIN_WORLDS:
        _user_world(tmp_path, name)
    _user_world(tmp_path, "aaa_extra")
    (tmp_path / "notes.txt").write_text("not a world")
    (tmp_path / "sub.toml").mkdir()  # a folder, not a file
    assert names.scan(tmp_path) == tuple(sorted((*envs.BUILTIN_WORLDS, "aaa_extra")))


def test_a_users_world_loads_by_name_through_jaxais_worlds(tmp_path, monkeypatch) -> None:
    first, second = tmp_path / "first", tmp_path / "second"
    path = _user_world(first, "myworld")
    _user_world(second, "myworld", "elsewhere")  # shadowed: the first folder wins, as on PATH
    _user_world(second, "other")
    monkeypatch.setenv(names.ENV_VAR, os.pathsep.join(["", str(first), str(second)]))
    assert envs.world_names() == (*envs.BUILTIN_WORLDS, "myworld", "other")
    assert envs.world_path("myworld") == path
    world = envs.load_world("myworld")
    assert world.name == "myworld"
    builtin = envs.load_world("world1")
    np.testing.assert_array_equal(world.seg, builtin.seg)  # the same layout, by another name
    assert envs.load_world("other").name == "other"
    env = envs.make("myworld", max_steps_in_episode=10)
    assert env.default_params.world.name == "myworld"
    # A path still means a file, whatever the search path holds.
    assert envs.load_world(second / "myworld.toml").name == "elsewhere"


@pytest.mark.parametrize(
    ("setup", "words"),
    [
        ("missing", ["JAXAIS_WORLDS", "does not exist", "create it or remove it"]),
        ("file", ["JAXAIS_WORLDS", "is not a folder"]),
        ("builtin", ["world1.toml", "built-in world's name", "rename the file"]),
        ("misnamed", ["myworld.toml", "'name'", "'world1' differs", 'name = "myworld"']),
        ("malformed", ["myworld.toml", "not valid TOML"]),
        ("unknown", ["no built-in world or file 'nowhere'", "myworld", "JAXAIS_WORLDS="]),
    ],
)
def test_bad_search_path_or_user_world_is_one_line(tmp_path, monkeypatch, setup, words) -> None:
    folder = tmp_path / "worlds"
    path = _user_world(folder, "myworld")
    entry = {"missing": tmp_path / "gone", "file": path}.get(setup, folder)
    monkeypatch.setenv(names.ENV_VAR, str(entry))
    if setup == "builtin":
        _user_world(folder, "world1")
    elif setup == "misnamed":
        _user_world(folder, "myworld", "world1")
    elif setup == "malformed":
        path.write_text(path.read_text().replace("width = 1.5", "width = = 1.5"))
    name = "nowhere" if setup == "unknown" else "myworld"
    with pytest.raises(envs.WorldError) as err:
        envs.load_world(name)
    message = _one_line(err)
    assert all(w in message for w in words), message
    if setup in ("missing", "file", "builtin"):  # never ignored, even when loading a built-in
        with pytest.raises(envs.WorldError):
            envs.load_world("world1")


def test_names_and_paths_are_told_apart(tmp_path, monkeypatch) -> None:
    assert names.is_name("corridor") and names.is_name("world1")
    assert not any(map(names.is_name, ["corridor.toml", "./corridor", "a/b", ""]))
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv(names.ENV_VAR, raising=False)
    _user_world(tmp_path, "here")
    (tmp_path / "here").write_text((tmp_path / "here.toml").read_text())
    assert envs.load_world("here.toml").name == "here"  # a path: the suffix says so
    assert envs.load_world("./here").name == "here"
    with pytest.raises(envs.WorldError) as err:  # a name: not on the (empty) search path
        envs.load_world("here")
    assert "give it as ./here" in _one_line(err)
    with pytest.raises(envs.WorldError) as err:
        envs.load_world("wrld1")
    assert "did you mean 'world1'?" in _one_line(err)


def test_the_baselines_check_world_names_without_jax(tmp_path) -> None:
    _user_world(tmp_path, "myworld")
    code = (
        "import sys\n"
        "from jaxais.baselines.config import TrainConfig\n"
        "TrainConfig(world='myworld'); TrainConfig(world='world2')\n"
        "try:\n"
        "    TrainConfig(world='nowhere')\n"
        "except ValueError as err:\n"
        "    print(err)\n"
        "print('jax' in sys.modules)\n"
        "import jaxais.envs, jaxais.envs.names as names\n"
        "print(jaxais.envs.names is names, jaxais.envs.WorldError is names.WorldError)\n"
    )
    out = run_python(
        code, env=script_env() | {"JAX_PLATFORMS": "cpu", names.ENV_VAR: str(tmp_path)}
    )
    assert out.returncode == 0, out.stderr[-2000:]
    lines = out.stdout.splitlines()
    assert lines[0].startswith("world: no built-in world or file 'nowhere'"), lines
    assert lines[1:] == ["False", "True True"], lines


@pytest.mark.slow
def test_custom_world_example_runs_tiny() -> None:
    out = run_python(
        f"import runpy, sys\nsys.argv = ['custom_world.py', '--tiny']\n"
        f"runpy.run_path({str(ROOT / 'examples' / 'custom_world.py')!r}, run_name='__main__')\n",
        env=script_env() | {"JAX_PLATFORMS": "cpu", names.ENV_VAR: ""},
    )
    assert out.returncode == 0, out.stderr[-3000:]
    assert "worlds by name: " in out.stdout and "corridor" in out.stdout, out.stdout
    found = re.search(
        r"^SIE in corridor: 4 trials, mean tau (\S+) s \(cap 30 s\)", out.stdout, re.M
    )
    assert found and 0 < float(found[1]) <= 30, out.stdout


# ---------------------------------------------------------------------------------- bad input


def _load_text(tmp_path, text: str, name: str = "bad.toml") -> envs.World:
    path = tmp_path / name
    path.write_text(text)
    return envs.load_world(path)


@pytest.mark.parametrize(
    ("old", "new", "field", "words"),
    [
        # A misspelt table or key would silently drop what it holds.
        ("[[pillars]]", "[[pilars]]", "pilars", ["unknown table", "did you mean 'pillars'?"]),
        ("[goal]", "[goals]", "goals", ["unknown table", "did you mean 'goal'?"]),
        ('name = "tiny"', 'name = "tiny"\ncolour = "red"', "colour", ["unknown key", "noise"]),
        ("wall_height = 0.1", "wall_height = 0.1\ndepth = 2.0", "arena.depth", ["wall_height"]),
        ("[robot]", "[robot]\nstart_pose = [0, 0]", "robot.start_pose", ["start_heading"]),
        ("height = 0.1\nregion", "hieght = 0.1\nregion", "goal.hieght", ["did you mean"]),
        ('material = "marker"', 'material = "marker"\nwidth = 1', "walls[0].width", ["from, to"]),
        ("radius = 0.04", "radius = 0.04\nheigth = 1", "pillars[0].heigth", ["center, radius"]),
        (
            "region = [0.1, 0.6, 0.4, 0.9]",
            "region = [0.1, 0.6, 0.4, 0.9]\nspeed = 2",
            "wanderers[0].speed",
            ["region"],
        ),  # noqa: E501
        (
            'name = "tiny"',
            'name = "tiny"\n[noise]\nir_std = 0.1',
            "noise.ir_std",
            ["ir_relative_std"],
        ),  # noqa: E501
        ('shape = "box"', 'shape = "box"\nradius = 0.05', "goal.radius", ["half_size"]),
        # Absurd sizes.
        ("width = 1.0", "width = 1e29", "arena.width", ["(0, 100] m", "1e+29"]),
        ("width = 1.0", "width = 0.0", "arena.width", ["(0, 100] m"]),
        ("height = 1.0", "height = -2.0", "arena.height", ["(0, 100] m"]),
        ("width = 1.0", "width = nan", "arena.width", ["finite"]),
        ("width = 1.0", "width = inf", "arena.width", ["finite"]),
        ("width = 1.0", "width = " + "9" * 400, "arena.width", ["finite", "..."]),
        ("wall_height = 0.1", "wall_height = 1e9", "arena.wall_height", ["(0, 10] m"]),
        ("radius = 0.04", "radius = 3.0", "pillars[0].radius", ["(0, 0.5] m"]),
        ("radius = 0.04", "radius = 0.0", "pillars[0].radius", ["(0, 0.5] m"]),
        ("half_size = [0.05, 0.05]", "half_size = [5.0, 0.05]", "goal.half_size", ["0.5] m"]),
        ("to = [0.5, 0.3]", "to = [0.5, 0.3]\nheight = -1.0", "walls[0].height", ["(0, 10] m"]),
        ("[robot]", "[robot]\nstart_heading = [-1e29, 0.0]", "robot.start_heading", ["rad"]),
        ("[0.1, 0.1, 0.4, 0.4]", "[0.1, 0.1, inf, 0.4]", "robot.start_region", ["4 numbers"]),
    ],
)
def test_bad_world_gets_one_line_naming_the_field(tmp_path, old, new, field, words) -> None:
    assert old in VALID
    with pytest.raises(envs.WorldError) as err:
        _load_text(tmp_path, VALID.replace(old, new, 1))
    message = str(err.value)
    assert "\n" not in message and len(message) < 300, message
    assert f"field '{field}'" in message, message
    for word in words:
        assert word in message, (word, message)


def test_unknown_keys_list_the_allowed_ones(tmp_path) -> None:
    with pytest.raises(envs.WorldError) as err:
        _load_text(tmp_path, VALID.replace("[[pillars]]", "[[pilars]]"))
    allowed = "allowed: name, arena, robot, goal, walls, boxes, pillars, wanderers, noise"
    assert str(err.value).endswith(allowed)


def test_every_documented_key_is_accepted(tmp_path) -> None:
    """A world that uses every key of the format (world1.toml's header) loads."""
    text = VALID.replace("[robot]\n", "[robot]\nstart_heading = [-1.0, 1.0]\n")
    text = text.replace('material = "marker"\n', 'material = "marker"\nheight = 0.2\n')
    text += (
        '[[boxes]]\ncenter = [0.8, 0.2]\nhalf_size = [0.03, 0.03]\nmaterial = "marker"\n'
        "height = 0.05\n"
        "[[boxes]]\nregion = [0.6, 0.1, 0.9, 0.3]\nhalf_size = [0.02, 0.02]\n"
        '[[pillars]]\ncenter = [0.9, 0.9]\nradius = 0.03\nmaterial = "wall"\nheight = 0.2\n'
        "[noise]\nir_relative_std = 0.1\ncamera_miss_prob = 0.1\ncamera_shift_prob = 0.1\n"
        "wheel_relative_std = 0.1\n"
    )
    world = _load_text(tmp_path, text, "full.toml")
    assert int(world.box_valid.sum()) == 2 and int(world.pillar_valid.sum()) == 2
    assert world.wheel_noise == 0.1 and float(world.seg_height[4]) == pytest.approx(0.2)
    ball = VALID.replace('shape = "box"\nhalf_size = [0.05, 0.05]', 'shape = "ball"\nradius = 0.05')
    assert _load_text(tmp_path, ball, "ball.toml").goal_shape == "ball"


def test_size_bounds_are_inclusive(tmp_path) -> None:
    big = VALID.replace("width = 1.0", "width = 100").replace("height = 1.0", "height = 100")
    world = _load_text(
        tmp_path,
        big.replace("radius = 0.04", "radius = 50.0").replace(
            "center = [0.7, 0.2]", "center = [50.0, 50.0]"
        ),
    )
    assert float(world.arena[2]) == 100.0 and float(world.pillar[0, 2]) == 50.0
    with pytest.raises(envs.WorldError, match="arena.width"):
        _load_text(tmp_path, big.replace("width = 100", "width = 100.001"))


def _crowded(n_walls: int, wanderers: int = 1) -> str:
    """VALID with ``n_walls`` extra short walls along the south wall's inside."""
    walls = "".join(
        f"[[walls]]\nfrom = [{0.55 + 0.002 * k:.3f}, 0.0]\nto = [{0.55 + 0.002 * k:.3f}, 0.02]\n"
        for k in range(n_walls)
    )
    extra = "[[wanderers]]\nregion = [0.1, 0.6, 0.4, 0.9]\n" * (wanderers - 1)
    return VALID + walls + extra


def test_more_surfaces_than_the_ray_caster_handles_are_refused(tmp_path, sim) -> None:
    # VALID: 5 walls (4 outer), 1 padding box, 1 pillar, 1 wanderer, the goal = 9 surfaces.
    limit = envs.world.MAX_SURFACES
    assert limit == 64
    ok = _load_text(tmp_path, _crowded(limit - 9), "ok.toml")
    assert ok.seg.shape[0] + ok.box_half.shape[0] + ok.pillar.shape[0] + ok.n_wanderers + 1 == 64
    # The limit is the ray caster's: a robot in that world senses (traced, not compiled) ...
    state = jax.eval_shape(envs.reset, jax.random.key(0), ok, sim.params)
    jax.eval_shape(envs.observe, jax.random.key(0), state, ok, sim.params)
    # ... and one surface more (padding it in by hand) is too many for it.
    more = ok.replace(
        pillar=jax.numpy.concatenate([ok.pillar, ok.pillar]),
        pillar_material=jax.numpy.concatenate([ok.pillar_material, ok.pillar_material]),
        pillar_height=jax.numpy.concatenate([ok.pillar_height, ok.pillar_height]),
        pillar_valid=jax.numpy.concatenate([ok.pillar_valid, ok.pillar_valid]),
    )
    with pytest.raises(AssertionError, match="64 surfaces"):
        jax.eval_shape(envs.observe, jax.random.key(0), state, more, sim.params)
    # Such a world is refused when it loads, in one line naming the count and the limit.
    for text, total in ((_crowded(limit - 8), 65), (_crowded(200), 209), (_crowded(50, 7), 65)):
        with pytest.raises(envs.WorldError) as err:
            _load_text(tmp_path, text)
        message = str(err.value)
        assert "\n" not in message and str(tmp_path / "bad.toml") in message
        assert f"has {total} surfaces" in message and "at most 64 are supported" in message
        assert f"remove at least {total - 64} walls" in message
    # Padding counts too: a Capacity that pads past the limit is refused as well.
    with pytest.raises(envs.WorldError, match="padding slots"):
        envs.load_world(tmp_path / "ok.toml", envs.Capacity(pillars=5))
