"""Why a claim of the paper fails here: the report's "why" column and its opening paragraph.

For each claim not held, the first that applies of: *sample size* (it holds in a run of more
trials), *seed-dependent* (it holds on some LTL seeds of the ledger), *depends on an unstated
choice* (it holds in a cell of a robustness map with a world scale or collision count other than
ours), *not reproduced* (the mechanism, in one measured sentence: :data:`MECHANISMS`). The
evidence is read from files (:func:`load`); JAX-free.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from jaxais.experiments import protocol

__all__ = ["MECHANISMS", "Evidence", "load", "mechanism", "why"]

SEEDS_FORMAT = "jaxais-seeds/1"
ROBUSTNESS_FORMAT = "jaxais-robustness/1"

MECHANISMS: dict[str, tuple[str, str]] = {
    "SIE-lowest-c": (
        "our RL-only SRL collides less than SIE in every world (n = 1000: c 0.7 vs 3.0 in "
        "world1, 1.6 vs 7.0 in world2), on every ledger seed: SIE's idiotypic switching costs "
        "contacts that SRL's greedy choice avoids (the paper's SRL had c = 8 in world1)",
        "docs/reproduction_1000/tables.json table3; docs/seeds/seeds.json (0 of 10 seeds)",
    ),
    "SIE-lowest-tau": (
        "our RL-only SRL is as fast as SIE (n = 1000: τ 143 vs 173 s in world1), where the "
        "paper's was slow (1298 vs 562 s): the paper's slow RL-only system is not reproduced",
        "docs/reproduction_1000/tables.json table3; the paper's Table 3",
    ),
    "SIE-lowest-f": (
        "f follows c and τ, and our SRL is lower in both (n = 1000: f 74 vs 98 in world1)",
        "docs/reproduction_1000/tables.json table3",
    ),
    "UIE-R1-f-below/URL-R1": (
        "our unseeded robots circle in open space rather than crash: UIE-R1 is trapped for 85-99 "
        "% of its run and times out (a saturated antibody penalised by 0.5 stays above 0.1 and "
        "is never replaced), where URL-R1's penalty of 1.0 replaces it; no counting rule or "
        "world scale changes that",
        "docs/reproduction_1000/tables.json trapped_s and table5; issue 41's counterfactual runs",
    ),
    "H2": (
        "idiotypic selection beats RL alone only where SRL's greedy choice locks up (seed 2, "
        "world2: SRL locked 2440 s a run); elsewhere SIE's extra switching costs collisions and "
        "time (n = 1000: SRL's f below SIE's in every world)",
        "docs/seeds/seeds.json; docs/reproduction_1000/tables.json hypotheses",
    ),
    "H3": (
        "in world2 the hand-designed HDC beats SIE (n = 1000: f 310 vs 415, p = 4.6e-09), SIE "
        "trapped 409 s a run there; in world1 SIE's lead over HDC is significant only at n = 1000",
        "docs/reproduction_1000/tables.json hypotheses and trapped_s",
    ),
    "H4": (
        "SIE fails in world2 without replacement (n = 1000: 3 % of runs, all by time)",
        "docs/reproduction_1000/tables.json table5",
    ),
    "SIE-no-failures": (
        "SIE times out in a few runs of the larger worlds (n = 1000: 3 % in world2), so a 0 % "
        "rate holds only in small samples",
        "docs/reproduction_1000/tables.json table5",
    ),
}
"""A claim's mechanism, measured: id (a world's claims by their id without the world) ->
(sentence, where it was measured)."""


def mechanism(claim_id: str) -> tuple[str, str] | None:
    """:data:`MECHANISMS`' entry for ``claim_id`` (``world1/SIE-lowest-c`` reads
    ``SIE-lowest-c``), or None."""
    return MECHANISMS.get(claim_id) or MECHANISMS.get(claim_id.split("/", 1)[-1])


@dataclass(frozen=True)
class Evidence:
    """What :func:`why` reads: ``larger`` (n, {claim: held}) of a run of more trials,
    ``ledger`` {claim: (held on, of)} over LTL seeds, ``cells`` a robustness map's cells
    (``{"ltl_seed", "scale", "rule", "claims"}``), and ``sources``: the paths given."""

    larger: tuple[int, dict[str, bool | None]] | None = None
    ledger: dict[str, tuple[int, int]] | None = None
    cells: list[dict[str, Any]] = field(default_factory=list)
    sources: list[str] = field(default_factory=list)


def _json(path: Path) -> Any:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as err:
        raise ValueError(f"--explain {path}: cannot read it as JSON ({err})") from None


def load(paths: Sequence[str | os.PathLike[str]] | None) -> Evidence:
    """The evidence in ``paths`` (one-line ValueError naming a path that is none of them): a
    reproduce.py folder (its claims.json and run.json; its trial count must exceed the paper's),
    a seeds ledger (``seeds.json``, jaxais-seeds/1) or a robustness map (``robustness.json``,
    jaxais-robustness/1), each kind at most once."""
    larger, ledger, cells, sources = None, None, [], []
    for given in paths or ():
        path = Path(given)
        if path.is_dir():
            if larger is not None:
                raise ValueError(f"--explain {path}: a second run of more trials; give one")
            claims, run = _json(path / "claims.json"), _json(path / "run.json")
            n = run.get("trials") if isinstance(run, dict) else None
            if not isinstance(n, int) or n <= protocol.SIMULATED_TRIALS:
                raise ValueError(
                    f"--explain {path}: its run.json has trials {n!r}; the 'sample size' reading "
                    f"needs a run of more than {protocol.SIMULATED_TRIALS} (reproduce.py --trials)"
                )
            larger = (n, {c["id"]: c["held"] for c in claims["claims"]})
        else:
            doc = _json(path)
            fmt = doc.get("format") if isinstance(doc, dict) else None
            if fmt == SEEDS_FORMAT and ledger is None:
                ledger = {k: (c["held_on"], c["of"]) for k, c in doc["claims"].items()}
            elif fmt == ROBUSTNESS_FORMAT and not cells:
                cells = list(doc["cells"])
            else:
                twice = fmt in (SEEDS_FORMAT, ROBUSTNESS_FORMAT)
                raise ValueError(
                    f"--explain {path}: "
                    + (f"a second {fmt} file; give one" if twice else f"format {fmt!r}, not a "
                       f"{SEEDS_FORMAT} ledger or a {ROBUSTNESS_FORMAT} map (or a run's folder)")
                )  # fmt: skip
        sources.append(str(given))
    return Evidence(larger, ledger, cells, sources)


def _cell(cell: Mapping[str, Any]) -> str:
    rule = "c per reading" if cell["rule"] == "reading" else "c per contact episode"
    return f"LTL seed {cell['ltl_seed']}, world scale {cell['scale']:g}, {rule}"


def _choice(cells: Sequence[Mapping[str, Any]], claim_id: str) -> str | None:
    """The unstated choice under which ``claim_id`` holds, with the first such cell. A claim of a
    world the scale leaves alone (the real pen, :data:`protocol.UNSCALED_WORLDS`) does not depend
    on the scale: its cells at another scale are its own world's at ours."""
    world = claim_id.split("/", 1)[0] if "/" in claim_id else None
    scaled = world not in protocol.UNSCALED_WORLDS

    def choices(cell: Mapping[str, Any]) -> list[str]:
        what = ["the world scale"] * (scaled and cell["scale"] != 1)
        return what + ["how a collision is counted"] * (cell["rule"] != protocol.DEFAULT_RULE)

    held = [c for c in cells if c["claims"].get(claim_id) is True and choices(c)]
    if not held:
        return None
    first = min(held, key=lambda c: (c["scale"] != 1, c["scale"], c["rule"], c["ltl_seed"]))
    return (
        f"depends on an unstated choice: {' and '.join(choices(first))} (holds at {_cell(first)})"
    )


def why(claim: Mapping[str, Any], evidence: Evidence) -> str:
    """The report's "why" of a claim (``{"id", "held"}``): "" when held or not evaluated."""
    cid = claim["id"]
    if claim.get("held") is not False:
        return ""
    if evidence.larger is not None and evidence.larger[1].get(cid) is True:
        return f"sample size: holds at n = {evidence.larger[0]}"
    if evidence.ledger is not None and evidence.ledger.get(cid, (0, 0))[0] > 0:
        k, n = evidence.ledger[cid]
        return f"seed-dependent: holds on {k} of {n} LTL seeds"
    choice = _choice(evidence.cells, cid)
    if choice:
        return choice
    found = mechanism(cid)
    if found is None:
        return "not reproduced (no mechanism measured)"
    return f"not reproduced: {found[0]} (measured: {found[1]})"
