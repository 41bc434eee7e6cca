"""A trial record of the current schema, built by hand for the statistics and report tests."""

from __future__ import annotations


def trial(
    tau: float,
    c: int = 0,
    rate: float | None = None,
    trapped: float = 0.0,
    locked: float = 0.0,
    replaced: int = 0,
) -> dict:
    """A record as the trial runner writes it (SPEC 9): c > 100 fails by collisions, tau = 4000
    by time, both can hold; f uses c capped at 100."""
    capped = min(c, 100)
    by_c, by_tau = c > 100, tau >= 4000
    return {
        "tau": float(tau),
        "collisions": int(c),
        "collisions_capped": int(capped),
        "fitness": (8 * capped + tau) / 2,
        "failed": by_c or by_tau,
        "failed_collisions": by_c,
        "failed_time": by_tau,
        "failed_by": [k for k, hit in (("collisions", by_c), ("time", by_tau)) if hit],
        "trapped_s": float(trapped),
        "locked_s": float(locked),
        "idiotypic_difference_rate": rate,
        "iterations": int(tau / 0.032),
        "replaced": int(replaced),
    }
