"""The paper's protocol is stated once, in jaxais.experiments.protocol, and read from there.

The statement itself is checked against the paper's tables as shipped (package data); the scripts,
the statistics, the claims and the report are checked to follow it when it changes (a module
that kept its own list would not); a scan of the sources finds no second copy of its lists; and
no lower layer imports the experiments.
"""

from __future__ import annotations

import ast
import importlib.util
from pathlib import Path

import numpy as np
import pytest
from _python import run_python
from _records import trial

from jaxais import labels
from jaxais.experiments import claims, protocol, report, stats
from jaxais.trials import STL_CONFIG

ROOT = Path(__file__).resolve().parent.parent
SCRIPTS = ("reproduce", "trials", "ablate")
"""The scripts that run the paper's experiments."""


def load_script(name: str):
    """scripts/{name}.py as a module (its ``main`` is not run)."""
    spec = importlib.util.spec_from_file_location(
        f"protocol_{name}", ROOT / "scripts" / f"{name}.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# --------------------------------------------------------------------------- the statement


def test_protocol_states_the_papers_design():
    assert protocol.WORLDS == ("world1", "world2", "real")
    assert protocol.SYSTEMS == ("SIE", "SRL", "UIE-R1", "URL-R1", "UIE-R2", "URL-R2", "HDC")
    assert protocol.SYSTEMS is labels.LABELS  # the labels the systems know, not a copy
    assert protocol.SEEDED == ("SIE", "SRL")
    assert protocol.UNSEEDED == ("UIE-R1", "URL-R1", "UIE-R2", "URL-R2")
    assert protocol.systems_for_world("real") == ("SIE", "SRL", "UIE-R1", "URL-R1", "HDC")
    assert protocol.systems_for_world("world2") == protocol.SYSTEMS
    assert protocol.systems_for_world("my_world.toml") == protocol.SYSTEMS  # a world of ours
    assert [protocol.trials_for_world(w) for w in (*protocol.WORLDS, "x.toml")] == [30, 30, 20, 30]
    assert set(protocol.WORLD_NAMES) == set(protocol.WORLDS)
    assert len(protocol.COMPARISONS) == 12
    assert {s for pair in protocol.COMPARISONS for s in pair} == set(protocol.SYSTEMS)


def test_protocol_agrees_with_the_papers_tables():
    paper = report.load_paper_tables()
    stated = paper["protocol"]
    assert {w: protocol.trials_for_world(w) for w in protocol.WORLDS} == stated["trials"]
    assert stated["caps"] == {"c": protocol.COLLISION_CAP, "tau": protocol.TAU_CAP}
    assert stats.significance_level(protocol.ALPHA) == stated["significance_percent"]
    assert list(paper["table3"]) == list(protocol.WORLDS)
    for world in protocol.WORLDS:
        assert tuple(paper["table3"][world]) == protocol.systems_for_world(world)
        pairs = [f"{a} vs {b}" for a, b in stats.comparison_pairs(world)]
        assert list(paper["table4"][world]) == pairs


def test_the_engines_trial_caps_are_the_protocols():
    # jaxais.trials sits below the experiments and cannot read the protocol: the same numbers.
    assert STL_CONFIG.tau_cap == protocol.TAU_CAP
    assert STL_CONFIG.collision_cap == protocol.COLLISION_CAP


def test_the_shared_argument_checks():
    """The experiments' --worlds, --seed and cap checks: defaults filled in, one-line errors."""
    assert protocol.check_worlds(None) == list(protocol.WORLDS)
    assert protocol.check_worlds("world2,,real") == ["world2", "real"]
    assert protocol.check_caps(None, None) == (4000.0, 100)
    assert [type(c) for c in protocol.check_caps(10, np.int64(5))] == [float, int]
    protocol.check_seed(2**32 - 1)
    bad = [
        (lambda: protocol.check_worlds("world1,mars"), r"--worlds: unknown world\(s\) \['mars'\]"),
        (lambda: protocol.check_worlds(""), "--worlds: unknown world"),
        (
            lambda: protocol.check_worlds(["real", "real"]),
            "--worlds names a world twice: real,real",
        ),
        (lambda: protocol.check_seed(-1), r"--seed must be in \[0, 2\*\*32\), got -1"),
        (lambda: protocol.check_seed(2**32, "--eval-seed"), "--eval-seed must be in"),
        (lambda: protocol.check_caps(1e6 + 1, None), r"--tau-cap must be in \(0, 1e6\]"),
        (lambda: protocol.check_caps(0, None), "--tau-cap must be in"),
        (lambda: protocol.check_caps(None, 0), "--collision-cap >= 1"),
        # Types before ranges: 1.5 collisions is no cap of 1, True no cap of 1, "30" no time.
        (lambda: protocol.check_caps(None, 1.5), "--collision-cap must be an integer, got float"),
        (lambda: protocol.check_caps(None, True), "--collision-cap must be an integer, got bool"),
        (lambda: protocol.check_caps("30", None), "--tau-cap must be a number, got str '30'"),
        (lambda: protocol.check_seed("0"), "--seed must be an integer, got str '0'"),
        (lambda: protocol.check_worlds(123), "--worlds must be a list of names"),
    ]
    for call, message in bad:
        with pytest.raises(ValueError, match=message):
            call()


def test_the_protocol_and_the_scripts_flags_leave_jax_unloaded():
    # The scripts check their flags against the protocol before JAX starts (and before they set
    # the device count).
    code = (
        "import importlib.util, sys\n"
        "import jaxais.experiments.protocol\n"
        f"for name in {SCRIPTS!r}:\n"
        f"    path = {str(ROOT / 'scripts')!r} + '/' + name + '.py'\n"
        "    spec = importlib.util.spec_from_file_location(name, path)\n"
        "    spec.loader.exec_module(importlib.util.module_from_spec(spec))\n"
        "print('jax' in sys.modules)\n"
    )
    out = run_python(code)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "False"


# --------------------------------------------------------------------------- read from there


@pytest.fixture
def changed_protocol(monkeypatch: pytest.MonkeyPatch) -> dict:
    """Another protocol: worlds, system order, comparisons, trial count and caps changed."""
    changed = {
        "WORLDS": ("world2", "world1"),
        "SYSTEMS": tuple(reversed(protocol.SYSTEMS)),
        "COMPARISONS": tuple(reversed(protocol.COMPARISONS)),
        "SIMULATED_TRIALS": 7,
        "COLLISION_CAP": 9,
        "TAU_CAP": 123.0,
    }
    for name, value in changed.items():
        monkeypatch.setattr(protocol, name, value)
    monkeypatch.delenv("JAXAIS_DEBUG", raising=False)
    return changed


@pytest.mark.parametrize("name", ["reproduce", "ablate"])
def test_scripts_take_their_worlds_and_defaults_from_the_protocol(
    name, changed_protocol, tmp_path, capsys
):
    script = load_script(name)
    out = str(tmp_path / "out")
    args = script.parse_args(["--out", out])
    assert args.worlds == "world2,world1"
    assert args.tau_cap == 123.0 and args.collision_cap == 9
    with pytest.raises(SystemExit) as exit_:
        script.main(["--out", out, "--worlds", "mars"])
    assert exit_.value.code == 2
    assert "unknown world(s) ['mars'] (the paper's: world2, world1;" in capsys.readouterr().err


def test_trials_script_takes_its_defaults_from_the_protocol(changed_protocol, tmp_path):
    args = load_script("trials").parse_args(["--system", "SIE", "--out", str(tmp_path / "r.json")])
    assert args.world == "world2" and args.trials == 7
    assert args.tau_cap == 123.0 and args.collision_cap == 9


def test_tables_claims_and_report_follow_the_protocol(changed_protocol, tmp_path):
    results = {
        w: {s: [trial(100 + 10 * i, i) for i in range(3)] for s in protocol.SYSTEMS}
        for w in ("world1", "world2")
    }
    tables = stats.build_tables(results)
    assert list(tables["table3"]["world1"]) == list(changed_protocol["SYSTEMS"])
    pairs = [f"{a} vs {b}" for a, b in changed_protocol["COMPARISONS"]]
    assert list(tables["table4"]["world1"]) == pairs
    ledger = claims.claims(results)
    assert [c["world"] for c in ledger][:2] == ["world2", "world2"]
    report.write_report(tmp_path, tables, results, {}, None, {}, None, claims_ledger=ledger)
    text = (tmp_path / "report.md").read_text()
    assert text.index("**world2**") < text.index("**world1**")
    assert text.index("| HDC |") < text.index("| SIE |")
    assert text.index("| UIE-R2 vs URL-R2 |") < text.index("| SIE vs SRL |")


# --------------------------------------------------------------------------- stated once


def _sources(*folders: str, skip: tuple[str, ...] = ()) -> list[Path]:
    paths = [p for f in folders for p in sorted((ROOT / f).rglob("*.py"))]
    return [p for p in paths if p.relative_to(ROOT).as_posix() not in skip]


def _strings(node: ast.AST) -> list[str] | None:
    """The elements of a tuple/list/set literal of string constants (else None)."""
    if not isinstance(node, ast.Tuple | ast.List | ast.Set):
        return None
    if not all(isinstance(e, ast.Constant) and isinstance(e.value, str) for e in node.elts):
        return None
    return [e.value for e in node.elts]


def copies_of_the_protocol(path: Path) -> list[str]:
    """Literals in ``path`` that restate one of the protocol's lists: a collection of strings
    with the worlds, the systems, the real world's systems or the unseeded ones; a dict keyed by
    the worlds; pairs of systems from Table 4's comparisons."""
    lists = {
        "WORLDS": set(protocol.WORLDS),
        "SYSTEMS": set(protocol.SYSTEMS),
        "the real world's systems": set(protocol.systems_for_world(protocol.REAL_WORLD)),
        "UNSEEDED": set(protocol.UNSEEDED),
    }
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        where = f"{'/'.join(path.parts[-2:])}:{getattr(node, 'lineno', '?')}"
        items = _strings(node)
        if items is not None:
            found += [f"{where} {name}" for name, s in lists.items() if set(items) == s]
        keys = _strings(ast.Tuple(elts=node.keys)) if isinstance(node, ast.Dict) else None
        if keys is not None and set(keys) == lists["WORLDS"]:
            found.append(f"{where} a dict keyed by the worlds")
        pairs = [_strings(e) for e in getattr(node, "elts", ())]
        if len(pairs) > 1 and all(
            p is not None and tuple(p) in protocol.COMPARISONS for p in pairs
        ):
            found.append(f"{where} Table 4's comparisons")
    return found


def test_no_second_copy_of_the_protocols_lists():
    stated = ("jaxais/experiments/protocol.py", "jaxais/labels.py")
    copies = [
        c
        for p in _sources("jaxais", "envs", "scripts", skip=stated)
        for c in copies_of_the_protocol(p)
    ]
    assert not copies, copies


def test_lower_layers_never_import_the_experiments():
    lower = [p for p in _sources("jaxais", "envs") if "experiments" not in p.parts]
    offenders = []
    for path in lower:
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = "." * node.level + (node.module or "")
                names = [base, *(f"{base}.{a.name}" for a in node.names)]
            else:
                continue
            if any(n.split(".")[-1] == "experiments" or ".experiments." in n for n in names):
                offenders.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert not offenders, offenders
