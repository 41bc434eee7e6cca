"""The package's public face and its import discipline."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest
from _python import run_python

import jaxais


@pytest.mark.parametrize("name", sorted(set(jaxais.__all__) - {"__version__"}))
def test_public_names_resolve(name):
    assert getattr(jaxais, name) is not None


def test_unknown_attribute_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'no_such_thing'"):
        _ = jaxais.no_such_thing


def test_cli_and_package_import_leave_jax_unloaded():
    # Scripts parse flags and may set XLA_FLAGS before JAX starts: importing jaxais.cli must not
    # import JAX.
    code = "import sys, jaxais, jaxais.cli; print('jax' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_reading_worlds_constants_and_the_seed_compiles_only_named_programs():
    # Every script starts this way. Arrays built op by op (jnp.asarray, slicing) would compile one
    # small XLA program each, 20-40 ms apiece on a CPU; only the named programs may compile.
    code = (
        "import jax\n"
        "from jaxais import envs\n"
        "from jaxais.experiments.records import build_systems\n"
        "names = []\n"
        "jax.config.update('jax_log_compiles', True)\n"
        "import logging\n"
        "class H(logging.Handler):\n"
        "    def emit(self, r):\n"
        "        m = r.getMessage()\n"
        "        if m.startswith('Compiling '): names.append(m.split()[1])\n"
        "logging.getLogger('jax').addHandler(H())\n"
        "for w in envs.BUILTIN_WORLDS: envs.load_world(w)\n"
        "envs.default_params()\n"
        "build_systems(['SIE', 'SRL', 'HDC'], None)\n"
        "print(' '.join(sorted(set(names))))\n"
    )
    out = run_python(code)
    assert out.returncode == 0, out.stderr[-2000:]
    compiled = set(out.stdout.split())
    # Eqs (1)-(2); the seed's limits are checked with NumPy.
    assert compiled <= {"jit(_seeded_paratopes)"}, compiled
    assert "jit(_seeded_paratopes)" in compiled  # the listener saw the compiles that do happen


def _imports(folder: str, optional: bool = True) -> dict[str, set[str]]:
    """file -> the modules it imports (absolute names; ``from m import n`` gives ``m.n`` too, as
    ``n`` may be a module), for every .py under ``folder``; ``optional=False`` leaves out those
    under ``except ImportError``."""
    root = Path(__file__).resolve().parent.parent
    found = {}
    for path in sorted((root / folder).rglob("*.py")):
        tree, names = ast.parse(path.read_text(), str(path)), set()
        skip = {
            id(n)
            for t in ast.walk(tree)
            if not optional and isinstance(t, ast.Try)
            and any("ImportError" in ast.unparse(h) for h in t.handlers)
            for n in ast.walk(t)
        }  # fmt: skip
        for node in (n for n in ast.walk(tree) if id(n) not in skip):
            if isinstance(node, ast.Import):
                names |= {a.name for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names |= {node.module, *(f"{node.module}.{a.name}" for a in node.names)}
        found[str(path.relative_to(root))] = names
    return found


def _jaxais_imports(folder: str) -> dict[str, set[str]]:
    """file -> the jaxais modules it imports (absolute names), for every .py under ``folder``."""
    return {
        f: {n for n in names if n.startswith("jaxais")} for f, names in _imports(folder).items()
    }


@pytest.mark.parametrize(
    ("folder", "allowed"),
    [
        ("envs", ("jaxais.envs",)),  # the physics never imports the rest
        ("jaxais/immune", ("jaxais.immune", "jaxais.envs")),  # the model, not the task loop
    ],
)
def test_lower_layers_import_only_themselves(folder, allowed):
    offenders = {
        f: sorted(n for n in names if not any(n == a or n.startswith(a + ".") for a in allowed))
        for f, names in _jaxais_imports(folder).items()
    }
    assert not {f: n for f, n in offenders.items() if n}


def test_envs_and_immune_are_the_installed_packages_not_a_path_hack():
    # pip maps envs/ to jaxais.envs (pyproject's package-dir); jaxais/__init__.py adds nothing to
    # its __path__, so tools that follow imports find the physics where the packaging puts it.
    import jaxais.envs
    import jaxais.immune

    assert list(jaxais.__path__) == [str(Path(jaxais.__file__).parent)]
    assert Path(jaxais.immune.__file__).parent.parent == Path(jaxais.__file__).parent
    assert (Path(jaxais.envs.__file__).parent / "worlds" / "world1.toml").is_file()


def test_scripts_are_thin_and_no_library_module_imports_the_cli():
    """Each entry point parses flags, calls the library and prints (at most 80 lines); the CLI
    layer is the scripts' alone."""
    root = Path(__file__).resolve().parent.parent
    lengths = {p.name: len(p.read_text().splitlines()) for p in (root / "scripts").glob("*.py")}
    assert {name: n for name, n in lengths.items() if n > 80} == {}
    for folder in ("jaxais", "envs"):
        users = {f for f, names in _jaxais_imports(folder).items() if "jaxais.cli" in names}
        assert users == set(), users


_IMPORTS_ONLY_DECLARED = """
import importlib, importlib.metadata as md, re, sys
from packaging.requirements import Requirement

extras, modules = set(sys.argv[1].split(",")) - {""}, sys.argv[2].split(",")
before = set(sys.modules)
for name in modules:
    try:
        importlib.import_module(name)
    except ModuleNotFoundError as err:
        if err.name != name:  # a missing distribution, not a name that is no module
            raise
dists = md.packages_distributions()
# Ours to declare: what the library imports, not what those packages load of their own accord.
ours = {m.split(".")[0] for m in modules}
loaded = {m.split(".")[0] for m in set(sys.modules) - before} & ours - set(sys.stdlib_module_names)
needed = {m: dists[m] for m in loaded if not m.startswith("_") and m in dists and m != "jaxais"}

def norm(name):
    return re.sub(r"[-_.]+", "-", name).lower()

closure, todo = set(), [("jaxais", extras)]
while todo:
    name, wanted = todo.pop()
    for text in md.requires(name) or []:
        req = Requirement(text)
        envs = [{"extra": e} for e in wanted or {""}]
        if (req.marker is None or any(req.marker.evaluate(e) for e in envs)) and (
            norm(req.name) not in closure
        ):
            closure.add(norm(req.name))
            todo.append((req.name, req.extras))
missing = {m: d for m, d in needed.items() if not {norm(x) for x in d} & closure}
print(sorted(missing.items()))
"""


def _third_party_imports(brax: bool) -> list[str]:
    """The third-party modules the library imports anywhere (in functions too), but those under
    ``except ImportError`` (optional: pandas); envs/brax.py's only when ``brax``."""
    files = _imports("jaxais", optional=False) | _imports("envs", optional=False)
    names = set().union(*(n for f, n in files.items() if (f == "envs/brax.py") == brax))
    return sorted(n for n in names if n.split(".")[0] not in (*sys.stdlib_module_names, "jaxais"))


@pytest.mark.slow
@pytest.mark.parametrize("extras", ["", "brax"])
def test_a_plain_install_imports_only_what_it_declares(extras):
    """Every distribution the library loads (every third-party import in jaxais/ and envs/) is a
    requirement of jaxais or of a requirement, extras included: the test extra brings packages a
    plain ``pip install .`` lacks (gymnax 1.0 imports six without requiring it), so the rest of
    the suite would not notice one missing."""
    modules = _third_party_imports(extras == "brax") + (["jaxais.envs.brax"] if extras else [])
    proc = subprocess.run(
        [sys.executable, "-c", _IMPORTS_ONLY_DECLARED, extras, ",".join(modules)],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert proc.stdout.splitlines()[-1] == "[]", proc.stdout  # brax prints before it
