"""The ablation of our readings (``jaxais.experiments.ablation``, ``scripts/ablate.py``).

The variants' settings and their batching are checked on data alone (a stand-in for
``run_trials`` records the batches). Real trials run in world1 with 2 trials, an 8 s time cap and
a made-up LTL seed: the ablation's batch (ours, hold=1 and the tracking HDC together), and two
systems alone, to show that a variant's trials are those of its system run by itself (common
random numbers). ``scripts/ablate.py``'s files are checked on its uninterrupted run in
``tests/test_resume.py``.
"""

from __future__ import annotations

import dataclasses
import io
from pathlib import Path

import _stl_fixtures as F
import jax
import numpy as np
import pytest
from _python import call_main
from tqdm.auto import tqdm

from jaxais import envs
from jaxais.experiments import ablation, protocol
from jaxais.immune.antibodies import TYPE_NAMES, from_dicts
from jaxais.immune.readings import DEFAULT, LITERAL, readings
from jaxais.systems import HAND_DESIGNED, LABELS, make_system
from jaxais.trials import STL_CONFIG, TrialSet, run_trials

BASE = dataclasses.replace(STL_CONFIG, tau_cap=8.0)
"""8 s runs: 250 iterations."""
RECORD = dataclasses.replace(BASE, record=True)
RUN_VARIANTS = ("ours", "hold=1", "hdc_tracks=True")
"""The variants of the real runs: one batch (traced differences only)."""
TRACK = TYPE_NAMES.index("track markers")


def by_name(name: str) -> ablation.Variant:
    return ablation.select([name])[0]


# ---------------------------------------------------------------------------------- variants


def test_each_variant_switches_what_its_name_says():
    names = [v.name for v in ablation.VARIANTS]
    assert len(set(names)) == len(names) == 11
    assert by_name("ours").switched() == []
    singles = {
        "hold=1": ("hold", 1),
        "count_encounters=False": ("count_encounters", False),
        "sigma0_floor=0": ("sigma0_floor", 0.0),
        "collision_rule=entry": ("collision_rule", "entry"),
        "stop_at_collision_cap=True": ("stop_at_collision_cap", True),
        "hdc_tracks=True": ("hdc_tracks", True),
        "ir_noise=0": ("ir_noise", False),
        "alpha_on_self=True": ("alpha_on_self", True),
        "penalties=swapped": ("swap_penalties", True),
    }
    for name, (field, value) in singles.items():
        v = by_name(name)
        assert v.switched() == [field], name
        assert getattr(v, field) == value
    literal = by_name("literal")
    assert set(literal.switched()) == {
        "hold", "count_encounters", "sigma0_floor", "collision_rule",
        "stop_at_collision_cap", "hdc_tracks",
    }  # fmt: skip
    assert F.tree_equal(literal.readings(), LITERAL)
    assert F.tree_equal(by_name("ours").readings(), DEFAULT)
    with pytest.raises(ValueError, match="unknown variant"):
        ablation.select(["ours", "holdd=1"])
    with pytest.raises(ValueError, match="twice"):
        ablation.select(["ours", "ours"])


def test_variant_systems_carry_the_variants_data():
    seed = F.random_seed()
    ours = ablation.variant_systems(by_name("ours"), LABELS, seed)
    for label in LABELS:
        assert F.tree_equal(ours[label], make_system(label, seed))
    hold = ablation.variant_systems(by_name("hold=1"), LABELS, seed)
    counts = ablation.variant_systems(by_name("count_encounters=False"), LABELS, seed)
    floor = ablation.variant_systems(by_name("sigma0_floor=0"), LABELS, seed)
    for label in LABELS:
        assert int(hold[label].readings.hold) == 1
        assert not bool(counts[label].readings.count_encounters)
        assert float(floor[label].readings.sigma0_floor) == 0.0
        assert F.tree_equal(hold[label].antibodies, ours[label].antibodies)
    literal = ablation.variant_systems(by_name("literal"), LABELS, seed)
    assert all(F.tree_equal(s.readings, LITERAL) for s in literal.values())
    # The tracking HDC maps "target seen" (antigen 1) to marker tracking, all else as ours.
    tracking = ablation.variant_systems(by_name("hdc_tracks=True"), LABELS, seed)
    hdc, old = tracking["HDC"].antibodies, ours["HDC"].antibodies
    np.testing.assert_array_equal(np.asarray(hdc.type)[:, 1], TRACK)
    np.testing.assert_array_equal(np.asarray(hdc.speed)[:, 1], 350)
    np.testing.assert_array_equal(np.asarray(hdc.angle)[:, 1], 30)
    assert int(np.asarray(old.type)[0, 1]) != TRACK
    keep = [j for j in range(8) if j != 1]
    for a, b in zip(jax.tree.leaves(hdc), jax.tree.leaves(old), strict=True):
        np.testing.assert_array_equal(np.asarray(a)[:, keep], np.asarray(b)[:, keep])
    for label in LABELS:
        if label != "HDC":
            assert F.tree_equal(tracking[label], ours[label])
    # Episode rules and simulator parameters.
    assert by_name("collision_rule=entry").config(BASE).collision_rule == "entry"
    assert by_name("stop_at_collision_cap=True").config(BASE).stop_at_collision_cap
    assert by_name("literal").config(BASE) == dataclasses.replace(
        BASE, collision_rule="entry", stop_at_collision_cap=True
    )
    assert by_name("hold=1").config(BASE) == BASE
    np.testing.assert_array_equal(np.asarray(by_name("ir_noise=0").sim_params().ir_noise), 0)
    assert F.tree_equal(by_name("ours").sim_params(), envs.default_params())
    # The old network reading and the swapped penalties are data of the systems.
    own = ablation.variant_systems(by_name("alpha_on_self=True"), LABELS, seed)
    swapped = ablation.variant_systems(by_name("penalties=swapped"), LABELS, seed)
    for label in LABELS:
        assert bool(own[label].readings.alpha_on_self)
        assert not bool(ours[label].readings.alpha_on_self)
        assert float(swapped[label].network.penalty_idiotypic) == 1.0
        assert float(swapped[label].network.penalty_non_idiotypic) == 0.5
        assert F.tree_equal(swapped[label].readings, ours[label].readings)


# ---------------------------------------------------------------------------------- batching


def fake_records(label: str, n: int, config, sim_params) -> list[dict]:
    """Plausible trial records that depend on the label, the config and the IR noise."""
    shift = len(label) % 7 + 3 * (config.collision_rule == "entry")
    shift += float(np.asarray(sim_params.ir_noise).sum())
    out = []
    for i in range(n):
        tau = 100.0 + 50 * (i + shift) + 10 * len(label)
        c = (i + len(label)) % 4
        out.append(
            {
                "tau": tau, "collisions": c, "collisions_capped": c,
                "fitness": (8 * c + tau) / 2, "failed": False, "failed_collisions": False,
                "failed_time": False, "failed_by": [], "trapped_s": 1.0 * i,
                "idiotypic_difference_rate": None, "iterations": int(tau / 0.032),
                "replaced": 0,
            }
        )  # fmt: skip
    return out


class Recorder:
    """A stand-in for ``run_trials`` that records every batch it is given."""

    def __init__(self):
        self.calls = []

    def __call__(self, world, systems, n, seed, config, sim_params, progress, timings):
        self.calls.append((world.name, list(systems), n, seed, config, sim_params))
        progress.update(1)  # part of its runs: run_ablation completes the batch's share
        return {k: TrialSet(fake_records(k, n, config, sim_params), None) for k in systems}


def test_traced_variants_share_one_batch_per_world(monkeypatch):
    calls = ablation.plan_calls(ablation.VARIANTS, BASE)
    assert [c.variants for c in calls] == [
        (
            "ours",
            "hold=1",
            "count_encounters=False",
            "sigma0_floor=0",
            "hdc_tracks=True",
            "alpha_on_self=True",
            "penalties=swapped",
        ),
        ("collision_rule=entry",),
        ("stop_at_collision_cap=True",),
        ("ir_noise=0",),
        ("literal",),
    ]
    assert calls[0].config == calls[3].config == BASE and not calls[3].ir_noise

    recorder = Recorder()
    monkeypatch.setattr("jaxais.trials.run_trials", recorder)
    n = {"world1": 2, "real": 3}
    bar = tqdm(file=io.StringIO())
    result = ablation.run_ablation(
        ["world1", "real"], ablation.VARIANTS, 5, F.random_seed(), n, BASE, progress=bar
    )
    assert len(recorder.calls) == len(result.calls) == 10  # 5 batches in each world
    assert bar.n == bar.total == sum(c["runs"] for c in result.calls)
    world, labels, trials, seed, config, params = recorder.calls[0]
    assert (world, trials, seed, config) == ("world1", 2, 5, BASE)
    traced = ("ours", "hold=1", "count_encounters=False", "sigma0_floor=0")
    # The tracking HDC's other six systems are ours: run once, shared.
    assert labels == (
        [f"{lab}@{v}" for v in traced for lab in LABELS]
        + ["HDC@hdc_tracks=True"]
        + [f"{lab}@{v}" for v in ("alpha_on_self=True", "penalties=swapped") for lab in LABELS]
    )
    assert result.calls[0]["shared"] == {
        "hdc_tracks=True": {lab: f"{lab}@ours" for lab in LABELS if lab != "HDC"}
    }
    trials_ = result.trials
    assert trials_["hdc_tracks=True"]["world1"]["SIE"] is trials_["ours"]["world1"]["SIE"]
    assert trials_["hdc_tracks=True"]["world1"]["HDC"] is not trials_["ours"]["world1"]["HDC"]
    rules = [(c[0], c[4].collision_rule, c[4].stop_at_collision_cap) for c in recorder.calls]
    assert rules[1:5] == [
        ("world1", "entry", False), ("world1", "episode", True),
        ("world1", "episode", False), ("world1", "entry", True),
    ]  # fmt: skip
    assert float(np.asarray(recorder.calls[3][5].ir_noise).sum()) == 0
    assert all(float(np.asarray(c[5].ir_noise).sum()) > 0 for i, c in enumerate(recorder.calls)
               if i % 5 != 3)  # fmt: skip
    real = [c for c in recorder.calls if c[0] == "real"]
    real_labels = protocol.systems_for_world("real")
    assert real[1][1] == [f"{lab}@collision_rule=entry" for lab in real_labels]
    assert all(c[2] == 3 for c in real)
    # Without sharing every variant runs its every system.
    unshared = Recorder()
    monkeypatch.setattr("jaxais.trials.run_trials", unshared)
    ablation.run_ablation(
        ["world1"], ablation.VARIANTS[:7], 5, F.random_seed(), 2, BASE, share=False, progress=bar
    )  # fmt: skip
    assert len(unshared.calls[0][1]) == 5 * len(LABELS)

    doc = ablation.document(result, ablation.VARIANTS, n)
    assert [v["name"] for v in doc["variants"]] == [v.name for v in ablation.VARIANTS]
    for v in doc["variants"]:
        assert set(v["claims"]) == {"reproduced", "evaluated", "total"}
        assert set(v["worlds"]) == {"world1", "real"}
        assert set(v["worlds"]["world1"]) == {"SIE", "HDC", "UIE-R1", "URL-R1"}
        assert {"f", "failure_rate", "trapped_s", "locked_s", "replaced"} == set(
            v["worlds"]["world1"]["SIE"]
        )
    table = ablation.markdown(doc)
    assert "world1 SIE f" in table and "real SIE fail %" in table and "world1 UIE-R1 f" in table
    # One row per variant, then UIE against URL for ours and the swapped penalties per world.
    assert table.count("\n| `") == 11 + 2 * 2
    assert "| `penalties=swapped` | real |" in table


# ---------------------------------------------------------------------------------- real runs


def same(a: TrialSet, b: TrialSet) -> bool:
    """The same trials: records and trajectories."""
    return a.records == b.records and all(
        np.array_equal(x, y) for x, y in zip(a.trajectories, b.trajectories, strict=True)
    )


@pytest.fixture(scope="module")
def ran() -> ablation.Ablation:
    """world1, every system, ours + hold=1 + the tracking HDC: one batch, 2 trials, 8 s, with
    trajectories (after 8 s every record reads the same: tau 8 s, no collisions)."""
    variants = ablation.select(list(RUN_VARIANTS))
    return ablation.run_ablation(["world1"], variants, 0, F.random_seed(), 2, RECORD)


@pytest.mark.slow
def test_a_variant_runs_as_its_system_run_alone(ran):
    """Common random numbers: SIE under hold=1 and the tracking HDC give, in the ablation's
    batch, the trials those systems give run by themselves (plain labels, same seed)."""
    assert len(ran.calls) == 1 and ran.calls[0]["runs"] == 2 * (2 * len(LABELS) + 1)
    seed = F.random_seed()
    hdc = make_system("HDC")
    track = [dict(a) for a in HAND_DESIGNED]
    track[1] = {"antigen": "target seen", "type": "track markers", "S": 350, "A": 30}
    one = from_dicts(track)
    tracking = hdc.replace(antibodies=jax.tree.map(lambda a: np.stack([a] * 5), one))
    alone = run_trials(
        F.world(),
        {"SIE": make_system("SIE", seed, readings=readings(hold=1)), "HDC": tracking},
        2, 0, RECORD, F.sim_params(),
    )  # fmt: skip
    got = {v: ran.trials[v]["world1"] for v in RUN_VARIANTS}
    assert same(got["hold=1"]["SIE"], alone["SIE"])
    assert same(got["hdc_tracks=True"]["HDC"], alone["HDC"])
    # Every variant met the same start placements; the readings took effect: hold=1 changed
    # SIE's runs, and the shared systems are ours.
    for v in RUN_VARIANTS:
        for ts in got[v].values():
            for i in range(2):
                np.testing.assert_array_equal(
                    ts.trajectories[i][0], alone["SIE"].trajectories[i][0]
                )
    assert not same(got["hold=1"]["SIE"], got["ours"]["SIE"])
    assert got["hdc_tracks=True"]["SIE"] is got["ours"]["SIE"]


@pytest.mark.parametrize(
    "args, words",
    [
        (["--trials", "1"], ["--trials"]),  # the library's check
        (["--trials", "many"], ["--trials"]),
    ],
)
def test_bad_flags_give_one_line_errors(args, words, tmp_path: Path):
    proc = call_main("ablate.py", "--out", tmp_path / "o", *args)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert len(lines) == 1 and lines[0].startswith("ablate.py: error: "), proc.stderr
    assert all(w in lines[0] for w in words), lines[0]
    assert not (tmp_path / "o" / "ablation.json").exists()


def test_ablate_checks_its_arguments_before_it_runs(tmp_path: Path):
    """What ``ablate.py`` passes on, as it passes it: a one-line ValueError (the script's one-line
    error) before anything is written."""
    for kw, message in (
        ({"worlds": ["world1", "mars"]}, "mars"),
        ({"variants": ["ours", "hold=2"]}, "--variants.*hold=2"),
    ):
        with pytest.raises(ValueError, match=message) as err:
            ablation.ablate(tmp_path / "o", **kw)
        assert "\n" not in str(err.value)
    assert not (tmp_path / "o").exists()
