"""The picture of `handskin stats`: distributions of one or two datasets' prints, each part's
share of the hand by action, and the anchored figures against their published ranges.

Panels: active taxels, contact area (mm²) and press force (N) as histograms by contactor kind;
blobs after and before the morphology and parts per hand as bars of sample fractions; each
part's share of the hand's pixels and of its pressure by action (stacked bars); the anchored
figures placed in their published range (the grey band; a dot outside it is outside the range).
A second dataset is drawn dashed (histograms) or hatched (bars).
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from tactile.files import save_figure
from tactile.images.labels import PALETTE
from tactile.prints.anchors import ANCHORS
from tactile.prints.figures import PARTS
from tactile.prints.shapes import DIRECTION, EXTENT, STATISTICS, quartiles
from tactile.prints.stats import DatasetStats

KIND_COLOURS = {"hand": "#c0392b", "object": "#2471a3", "body": "#229954", "non_hand": "#7d3c98"}
STYLES = ("-", "--")
HATCHES = ("", "//")
MARKERS = ("o", "s")
DATASET_COLOURS = ("black", "#d35400")


def _kind_colour(kind: str) -> str:
    return KIND_COLOURS.get(kind, "#555555")


def _histograms(ax, stats: list[DatasetStats], attr: str, title: str, log: bool = False) -> None:
    values = [getattr(s.prints, attr) for s in stats]
    finite = np.concatenate([v[np.isfinite(v)] for v in values])
    if not finite.size or (
        attr == "force_n" and all("force_n" not in s.prints.fields for s in stats)
    ):
        ax.text(0.5, 0.5, "not in this dataset", ha="center", va="center", transform=ax.transAxes)
        ax.set_title(title)
        return
    top = np.percentile(finite, 99.5) or 1.0
    bins = np.linspace(0, top, 40)
    for s, v, style in zip(stats, values, STYLES, strict=False):
        for kind in dict.fromkeys(s.prints.kind.tolist()):
            x = v[(s.prints.kind == kind) & np.isfinite(v)]
            if x.size:
                weights = np.full(x.size, 1.0 / x.size)
                label = f"{kind} ({s.name})" if len(stats) > 1 else kind
                ax.hist(
                    np.clip(x, 0, top),
                    bins,
                    weights=weights,
                    histtype="step",
                    color=_kind_colour(kind),
                    linestyle=style,
                    label=label,
                )
    ax.set_title(title)
    ax.set_ylabel("fraction of samples")
    ax.legend(fontsize=7)


def _counts(ax, stats: list[DatasetStats], attr: str, title: str, hands_only: bool = False) -> None:
    series = [
        (s, hatch, kind)
        for s, hatch in zip(stats, HATCHES, strict=False)
        for kind in _kinds(s, hands_only)
    ]
    width = 0.8 / max(1, len(series))
    for k, (s, hatch, kind) in enumerate(series):
        x = np.clip(getattr(s.prints, attr)[s.prints.kind == kind], 0, 10)
        frac = np.bincount(x, minlength=11)[:11] / max(1, x.size)
        label = f"{kind} ({s.name})" if len(stats) > 1 else kind
        offset = (k - (len(series) - 1) / 2) * width
        ax.bar(
            np.arange(11) + offset,
            frac,
            width,
            color=_kind_colour(kind),
            hatch=hatch,
            edgecolor="black" if hatch else "white",
            linewidth=0.3,
            label=label,
        )
    ax.set_xticks(range(11), [*map(str, range(10)), "10+"])
    ax.set_title(title)
    ax.set_ylabel("fraction of samples")
    if series:
        ax.legend(fontsize=7)
    else:
        ax.text(0.5, 0.5, "not in this dataset", ha="center", va="center", transform=ax.transAxes)


def _kinds(s: DatasetStats, hands_only: bool) -> list[str]:
    kinds = list(dict.fromkeys(s.prints.kind.tolist()))
    if hands_only:
        return ["hand"] if "hand" in kinds and s.prints.has_labels else []
    return kinds


def _shares(ax, stats: list[DatasetStats], what: str) -> None:
    rows = []
    for g in dict.fromkeys(g for s in stats for g in s.shares):
        for s, hatch in zip(stats, HATCHES, strict=False):
            if g in s.shares and s.shares[g][f"{what}.palm"] is not None:
                name = g.removeprefix("hand: ") + (f" ({s.name})" if len(stats) > 1 else "")
                rows.append((name, hatch, [s.shares[g][f"{what}.{p}"].value for p in PARTS]))
    if not rows:
        ax.text(0.5, 0.5, "not in this dataset", ha="center", va="center", transform=ax.transAxes)
    for y, (_, hatch, values) in enumerate(rows):
        left = 0.0
        for k, v in enumerate(values):
            ax.barh(
                y,
                v,
                left=left,
                color=PALETTE[k + 1] / 255,
                hatch=hatch,
                edgecolor="white",
                label=PARTS[k] if y == 0 else None,
            )
            left += v
    ax.set_yticks(range(len(rows)), [r[0] for r in rows], fontsize=7)
    ax.invert_yaxis()
    ax.set_xlim(0, 100)
    ax.set_xlabel(f"% of the hand's {'labelled pixels' if what == 'pixels' else 'pressure'}")
    ax.set_title(f"each part's share of the {'pixels' if what == 'pixels' else 'pressure'}")
    if rows:
        ax.legend(fontsize=7, ncol=6, loc="upper center", bbox_to_anchor=(0.5, -0.12))


def _anchors(ax, stats: list[DatasetStats]) -> None:
    ax.axvspan(0, 1, color="0.85", label="published range")
    for k, s in enumerate(stats):
        shift = (k - (len(stats) - 1) / 2) * 0.25
        for y, a in enumerate(ANCHORS):
            e = s.anchored.get(a.key)
            if e is None:
                ax.text(1.2, y + shift, f"not in {s.name}", va="center", fontsize=6)
                continue
            span = a.high - a.low
            x, lo, hi = ((v - a.low) / span for v in (e.value, e.low, e.high))
            ax.errorbar(
                np.clip(x, -1.5, 2.5),
                y + shift,
                xerr=[[max(x - lo, 0)], [max(hi - x, 0)]],
                marker=MARKERS[k],
                color=DATASET_COLOURS[k],
                capsize=2,
                label=s.name if y == 0 else None,
            )
    ax.set_yticks(range(len(ANCHORS)), [a.label for a in ANCHORS], fontsize=7)
    ax.invert_yaxis()
    ax.set_xlim(-1.6, 2.6)
    ax.set_xticks([0, 1], ["low", "high"])
    ax.set_xlabel("place in the published range (clipped beyond)")
    ax.set_title("published measurements of real hands")
    ax.legend(fontsize=7, ncol=3, loc="upper center", bbox_to_anchor=(0.5, -0.12))


def save_stats_png(stats: list[DatasetStats], png: str | Path) -> Path:
    """Draw the statistics of one or two datasets (`tactile.prints.stats.dataset_stats`) to
    ``png``."""
    fig = Figure(figsize=(16, 13), layout="constrained")
    axes = fig.subplots(3, 3)
    _histograms(axes[0, 0], stats, "active", "active taxels")
    _histograms(axes[0, 1], stats, "area_mm2", "contact area (mm²)")
    _histograms(axes[0, 2], stats, "force_n", "press force (N)")
    _counts(axes[1, 0], stats, "blobs", "separate blobs (after the morphology)")
    _counts(axes[1, 1], stats, "blobs_grey", "separate blobs (before the morphology)")
    _counts(axes[1, 2], stats, "parts", "hand parts pressing", hands_only=True)
    _shares(axes[2, 0], stats, "pixels")
    _shares(axes[2, 1], stats, "pressure")
    _anchors(axes[2, 2], stats)
    fig.suptitle("prints of " + " and ".join(s.name for s in stats))
    return save_figure(fig, png, dpi=80)


def save_shapes_png(sets: dict, png: str | Path, reference: str | None = None) -> Path:
    """Draw the six print statistics (`tactile.prints.shapes.STATISTICS`), the two extents
    (`EXTENT`) and where the fingers point (`DIRECTION`) of named `tactile.prints.shapes.Shapes` as
    box plots side by side (box: IQR, line: median, whiskers: 5th and 95th percentiles), the IQR
    of ``reference`` shaded across each panel."""
    panels = {k: label for k, (label, _) in STATISTICS.items()}
    panels |= {k: f"extent {label}, mm" for k, label in EXTENT.items()}
    panels |= DIRECTION
    fig = Figure(figsize=(15, 12.5), layout="constrained")
    for ax, (key, label) in zip(fig.subplots(3, 3).ravel(), panels.items(), strict=True):
        data = [s.values[key][np.isfinite(s.values[key])] for s in sets.values()]
        ref = None if reference is None else quartiles(sets[reference].values[key])
        if ref is not None:
            ax.axhspan(ref[0], ref[2], color="0.85", zorder=0, label=f"{reference}: IQR")
            ax.legend(fontsize=8, loc="upper right")
        ax.boxplot(
            [d if len(d) else [np.nan] for d in data],
            whis=(5, 95),
            showfliers=False,
            medianprops={"color": "#c0392b", "linewidth": 2},
        )
        ax.set_xticks(range(1, len(sets) + 1), [f"{n}\n({len(s)} prints)" for n, s in sets.items()])
        ax.set_title(textwrap.fill(label, 60), fontsize=10)
        ax.tick_params(labelsize=8)
    fig.suptitle("print shapes: " + ", ".join(sets), fontsize=12)
    return save_figure(fig, png)
