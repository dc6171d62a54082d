"""The prints of each fidelity setting beside the default's: the statistics that say whether a
cheaper simulation still makes the same data (`tactile.prints.measures`), with 95 % bootstrap
spreads."""

from __future__ import annotations

from pathlib import Path

from experiments.report import markdown_table
from tactile.dataset.reader import open_dataset
from tactile.prints.measures import bootstrap_mean, read_prints

#: (contactor kind, statistic of `tactile.prints.measures.Prints`, column header with unit)
STATISTICS: tuple[tuple[str, str, str], ...] = (
    ("hand", "active", "hand: active taxels"),
    ("hand", "parts", "hand: parts pressing"),
    ("hand", "force_n", "hand: force (N)"),
    ("hand", "area_mm2", "hand: area (mm²)"),
    ("object", "active", "object: active taxels"),
    ("object", "force_n", "object: force (N)"),
    ("body", "active", "body part: active taxels"),
    ("body", "force_n", "body part: force (N)"),
)


def print_statistics(folder: Path, seed: int = 0) -> dict[str, list[float]]:
    """{"kind.statistic": [mean, low, high]} of a dataset's prints (95 % bootstrap, seeded)."""
    with open_dataset(folder) as ds:
        prints = read_prints(ds)
    out = {}
    for kind, stat, _ in STATISTICS:
        values = getattr(prints, stat)[prints.kind == kind]
        out[f"{kind}.{stat}"] = list(bootstrap_mean(values, seed=seed))
    return out


def same_prints(stats: dict[str, list[float]], reference: dict[str, list[float]]) -> bool:
    """Whether every mean of ``stats`` lies inside the 95 % spread of ``reference``'s."""
    return all(ref[1] <= stats[key][0] <= ref[2] for key, ref in reference.items())


def prints_table(rows: list[dict], default: str) -> str:
    """Markdown: each setting's print statistics (mean [95 % spread]); a mean outside the
    default's spread is marked with *."""
    ref = next(r["prints"] for r in rows if r["name"] == default)
    body = []
    for r in rows:
        cells = []
        for kind, stat, _ in STATISTICS:
            mean, low, high = r["prints"][f"{kind}.{stat}"]
            lo_ref, hi_ref = ref[f"{kind}.{stat}"][1:]
            mark = "" if lo_ref <= mean <= hi_ref else " *"
            cells.append(f"{mean:.1f} [{low:.1f}, {high:.1f}]{mark}")
        body.append([f"`{r['name']}`", *cells, "yes" if same_prints(r["prints"], ref) else "no"])
    head = ["setting", *(h for _, _, h in STATISTICS), "the default's prints"]
    return markdown_table(head, body)
