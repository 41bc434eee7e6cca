"""Extending the network from a user's file: a new constant is one declared field, a variant of
eqs (7)-(8) is a function handed to ``stl_controller``, and ``examples/network_variant.py`` runs
one as a user does.

The lists of parameters, bounds and users are derived, so a test-local subclass with one more
field must show up in each; the variant's act compiles once, for every value of its constant.
"""

from __future__ import annotations

import re
from pathlib import Path

import _stl_fixtures as F
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _python import run_python

from jaxais import STL, make_system, stl_controller, system_params, with_params
from jaxais import systems as S
from jaxais.controllers import stl_for
from jaxais.envs.struct import pytree_dataclass
from jaxais.immune import network as nw
from jaxais.immune.readings import Readings

ROOT = Path(__file__).resolve().parent.parent


@pytree_dataclass
class GainParams(nw.NetworkParams):
    """The paper's constants, a variant's stimulation gain, and a made-up compiled-in one."""

    # fmt: off
    gain: float = nw.param(1.0, bound=(0.0, 2.0), mechanism="idiotypic",
                           help="scales eq (7)'s stimulation")
    penalty_scale: float = nw.param(1.0, bound=(0.0, np.inf), mechanism="non_idiotypic",
                                    help="made up: a non-idiotypic penalty's scale")
    schedule: int = nw.param(5, kind=int, bound=(1, np.inf), static=True, mechanism="learning",
                             help="made up", fixed="a loop schedule")
    # fmt: on


@pytree_dataclass
class SwitchReadings(Readings):
    """Our readings and one more switch."""

    extra: jnp.ndarray = nw.param(False, kind=bool, mechanism="learning", help="made up")


# ----------------------------------------------------------- a new constant is one field


def test_a_subclass_field_is_bounded_swept_and_used_by_the_systems_its_mechanism_names():
    bounds = nw.bounds(GainParams)
    assert list(bounds) == [*nw.BOUNDS, "gain", "penalty_scale"]  # "schedule" is static
    assert bounds["gain"] == (0.0, 2.0)
    params = S.parameters(GainParams, SwitchReadings)
    assert params["gain"] == ("network", float) and params["extra"] == ("readings", bool)
    assert list(params) == [*[n for n in S.PARAMETERS if params[n][0] == "network"],
                            "gain", "penalty_scale",
                            *[n for n in S.PARAMETERS if params[n][0] == "readings"],
                            "extra"]  # fmt: skip
    used = S.used_by(GainParams, SwitchReadings)
    assert used["gain"] == S.USED_BY["k1"] == ("SIE", "UIE")
    assert used["penalty_scale"] == S.USED_BY["penalty_non_idiotypic"] == ("SRL", "URL")
    assert used["extra"] == ("SIE", "SRL", "UIE", "URL")
    fixed = S.fixed(GainParams, SwitchReadings)
    assert fixed["schedule"] == "a loop schedule" and "schedule" not in params
    assert set(fixed) - {"schedule"} == set(S.FIXED)


def test_a_subclass_field_is_validated_clipped_and_set_by_name():
    with pytest.raises(ValueError, match=r"GainParams.gain must be in \[0, 2\], got 3.0"):
        GainParams(gain=3.0).validate()
    with pytest.raises(ValueError, match="GainParams.schedule must be an int >= 1"):
        GainParams(schedule=0).validate()
    assert GainParams(gain=-1.0).clip_valid().gain == 0.0
    system = F.systems()["URL-R1"].replace(network=GainParams())
    assert system_params(system, ["gain", "k1"]) == {"gain": 1.0, "k1": 0.85}
    moved = with_params(system, {"gain": 5.0, "k1": 0.5})  # clipped into the field's bound
    assert (float(moved.network.gain), float(moved.network.k1)) == (2.0, 0.5)
    with pytest.raises(ValueError, match="unknown parameter 'gain'"):
        with_params(F.systems()["URL-R1"], {"gain": 1.0})  # the paper's network has none
    made = make_system("URL-R1", network=GainParams(gain=0.5))
    assert made.network.gain == 0.5


def test_an_unknown_mechanism_is_named():
    @pytree_dataclass
    class Typo(nw.NetworkParams):
        k4: float = nw.param(0.0, bound=(0.0, 1.0), mechanism="idiotipic", help="typo")

    with pytest.raises(ValueError, match="Typo.k4: unknown mechanism 'idiotipic'"):
        S.parameters(Typo)


def test_every_field_of_the_paper_network_and_our_readings_is_declared():
    # A field without a declaration would silently drop out of the derived lists.
    for cls in (nw.NetworkParams, Readings):
        assert list(nw.declared(cls)) == [f for f in cls.__dataclass_fields__]


# ------------------------------------------------------ eqs (7)-(8) as a function handed in


def gain_on_stimulation(P, I, C, n, params, alpha_on_self=False):
    """The paper's eqs (7)-(8) with eps scaled by the variant's own traced constant."""
    eps, delta = nw.stimulation_suppression(P, I, C, n, params, alpha_on_self)
    return params.gain * eps, delta


def test_the_paper_interaction_is_the_default_and_stl_for_builds_it():
    assert stl_controller() is stl_controller(True, True, True) is STL
    assert stl_for(F.stack([F.systems()["SIE"]])) is stl_controller(False, True, True)
    assert stl_controller(interaction=gain_on_stimulation) is not STL


def test_a_variant_handed_to_stl_controller_selects_with_its_own_constant():
    """test_stl's hand-worked case: alpha = set 0; the paper's eq (7) stimulates set 1 past it
    (eps_1 = 0.85 * 0.625^2), so beta = set 1. With gain 0 there is no stimulation: beta =
    alpha and set 1's clones grow by b * P alone. Both gains run one compiled act."""
    P = np.full((F.X, F.Y), 0.2)
    P[0, 2], P[1, 2] = 0.6, 0.5
    P[0, 5], P[1, 5] = 1.0, 0.0
    I = np.zeros((F.X, F.Y))
    I[0, 5] = 1.0
    act = jax.jit(stl_controller(interaction=gain_on_stimulation).act)
    for gain, acting, s2 in ((1.0, 1, 0.5 + 0.85 * 0.625**2), (0.0, 0, 0.5)):
        system = F.system(idiotypic=True)
        system = system.replace(network=GainParams(gain=jnp.float32(gain)))
        out, _ = act(jax.random.key(0), F.state(system, P, I=I), F.percept(m=2), system)
        assert (int(out.acting), int(out.differences)) == (acting, acting)
        np.testing.assert_allclose(float(out.N[1, 2]), 1000 + 100 * s2, rtol=1e-5)
    assert act._cache_size() == 1


# ------------------------------------------------------------------- the user's example file


@pytest.mark.slow  # a fresh interpreter compiles the trials: about 10 s
def test_network_variant_example_runs_tiny_trials_as_a_user_does():
    code = (
        "import runpy, sys\n"
        "sys.argv = ['network_variant.py', '--tiny']\n"
        f"runpy.run_path({str(ROOT / 'examples' / 'network_variant.py')!r}, run_name='__main__')\n"
    )
    proc = run_python(code, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    found = re.search(r"^SIEV .*: 2 trials in world1, mean tau (\S+) s, idiotypic difference "
                      r"rate (\S+) %$", proc.stdout, re.MULTILINE)  # fmt: skip
    assert found, proc.stdout
    assert 0.0 < float(found[1]) <= 10.0 and 0.0 <= float(found[2]) <= 100.0


@pytest.mark.parametrize(
    ("name", "value", "message"),
    [
        ("sigma0_floor", "0.1", "sigma0_floor must be a number, got str"),
        ("sigma0_floor", True, "sigma0_floor must be a number, got bool"),
        ("sigma0_floor", 2.0, "sigma0_floor must lie in [0, 1], got 2.0"),
        ("hold", 1.5, "hold must be an int >= 1 (iterations), got 1.5"),
        ("alpha_on_self", 1, "alpha_on_self must be True or False, got 1"),
    ],
)
def test_readings_check_each_value_type_before_range_in_one_line(name, value, message):
    from jaxais.immune.readings import readings

    with pytest.raises(ValueError) as info:
        readings(**{name: value})
    assert str(info.value) == message
