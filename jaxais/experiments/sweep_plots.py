"""Figures of a parameter sweep (:mod:`jaxais.experiments.sweeps`): lines for one axis, heatmaps
for two, the operating point of the swept system marked."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from jaxais.experiments.plotting import new_figure, save_figure
from jaxais.experiments.sweeps import surface

PANELS = (
    ("f", "mean f = (8c + τ)/2"),
    ("failure_rate", "failure rate"),
    ("idiotypic_difference_rate", "idiotypic difference rate"),
    ("tau", "mean τ (s)"),
    ("c", "mean c (capped at 100)"),
    ("trapped_s", "mean trapped time (s)"),
)
CONTOUR = 0.20
"""The idiotypic difference rate the paper tuned k1 and k2 for (section 5)."""


def _panels(doc: dict[str, Any]) -> list[tuple[str, str]]:
    return [(m, title) for m, title in PANELS if any(p.get(m) is not None for p in doc["points"])]


def _ci(rows: list[dict[str, Any] | None]) -> np.ndarray:
    """The rows' ``"ci"`` [n, 2] (NaN where a row is missing)."""
    return np.asarray([r["ci"] if r else [np.nan, np.nan] for r in rows], np.float64)


def _line_figure(doc: dict[str, Any], path: Path) -> None:
    ((name, values),) = doc["axes"].items()
    panels = _panels(doc)
    fig = new_figure((4.0 * len(panels), 3.2))
    axes = fig.subplots(1, len(panels), squeeze=False)[0]
    for ax, (metric, title) in zip(axes, panels, strict=True):
        mean = surface(doc, metric)
        ci = _ci([p.get(metric) for p in doc["points"]])
        ax.plot(values, mean, marker="o", color="C0")
        ax.fill_between(values, ci[:, 0], ci[:, 1], color="C0", alpha=0.2, label="95 % CI")
        ax.axvline(doc["base_values"][name], color="k", ls="--", lw=1, label="operating point")
        if metric == "idiotypic_difference_rate":
            ax.axhline(CONTOUR, color="C3", lw=1, label="20 %")
        ax.set_xlabel(name)
        ax.set_title(title, fontsize=9)
    axes[0].legend(fontsize=7)
    fig.suptitle(f"{doc['system']} in {doc['world']}, {doc['trials']} trials per point")
    save_figure(fig, path)


def _heatmap_figure(doc: dict[str, Any], path: Path) -> None:
    (ny, yv), (nx, xv) = ((n, np.asarray(v)) for n, v in doc["axes"].items())
    panels = _panels(doc)
    cols = 3
    rows = -(-len(panels) // cols)
    fig = new_figure((4.3 * cols, 3.6 * rows))
    axes = fig.subplots(rows, cols, squeeze=False).ravel()
    for ax in axes[len(panels) :]:
        ax.set_visible(False)
    for ax, (metric, title) in zip(axes, panels, strict=True):
        z = surface(doc, metric)  # [len(y), len(x)]
        mesh = ax.pcolormesh(xv, yv, z, shading="nearest", cmap="viridis")
        fig.colorbar(mesh, ax=ax, shrink=0.85)
        if metric == "idiotypic_difference_rate" and min(z.shape) > 1:
            if np.nanmin(z) <= CONTOUR <= np.nanmax(z):
                ax.contour(xv, yv, z, levels=[CONTOUR], colors="w", linewidths=1.5)
                title += " (white: 20 %)"
            else:
                title += f": {100 * np.nanmin(z):.1f}-{100 * np.nanmax(z):.1f} %, no 20 % contour"
        ax.set_title(title, fontsize=9)
        base = doc["base_values"]
        ax.plot(base[nx], base[ny], marker="*", ms=12, color="C3", mec="w", ls="none")
        ax.set_xlabel(nx)
        ax.set_ylabel(ny)
    fig.suptitle(
        f"{doc['system']} in {doc['world']}, {doc['trials']} trials per point "
        "(red star: the operating point)"
    )
    save_figure(fig, path)


def save_sweep_figures(doc: dict[str, Any], out: Path) -> list[Path]:
    """Draw ``doc``'s figure into ``out`` (sweep.png); none for three or more axes."""
    draw = {1: _line_figure, 2: _heatmap_figure}.get(len(doc["axes"]))
    if draw is None:
        return []
    path = Path(out) / "sweep.png"
    draw(doc, path)
    return [path]


def save_noise_figure(doc: dict[str, Any], out: Path) -> Path:
    """f and the failure rate against the noise scale, one line per system (reality_gap.png)."""
    scales = np.asarray(doc["scales"])
    fig = new_figure((9.0, 3.6))
    axes = fig.subplots(1, 2)
    labels = list(doc["points"][0]["systems"])
    titles = {"f": "mean f = (8c + τ)/2 (lower is better)", "failure_rate": "failure rate"}
    for ax, (metric, title) in zip(axes, titles.items(), strict=True):
        for k, label in enumerate(labels):
            rows = [p["systems"][label][metric] for p in doc["points"]]
            ci = _ci(rows)
            ax.plot(scales, [r["mean"] for r in rows], marker="o", color=f"C{k}", label=label)
            ax.fill_between(scales, ci[:, 0], ci[:, 1], color=f"C{k}", alpha=0.15)
        ax.axvline(1.0, color="k", ls="--", lw=1)
        ax.set_xlabel(f"noise scale ({', '.join(doc['kinds'])}; 1 = the world's own levels)")
        ax.set_title(title, fontsize=9)
    axes[0].legend(fontsize=8)
    fig.suptitle(f"The reality gap in {doc['world']}: {doc['trials']} trials per point, 95 % CIs")
    path = Path(out) / "reality_gap.png"
    save_figure(fig, path)
    return path
