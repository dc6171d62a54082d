"""`handskin stats`: the statistics of a set of prints, beside published measurements of hands.

    stats = [dataset_stats("data/paper"), dataset_stats("out/robot", name="robot")]
    Path("report.md").write_text(stats_markdown(stats))

`dataset_stats` reads every sample once (`tactile.prints.measures.read_prints`) and computes the
figures of `tactile.prints.figures`: by contactor kind and action, each part's share of the hand,
and the figures `tactile.prints.anchors.ANCHORS` holds published ranges for; on a dataset of several
contacts per sample, its samples by number and kinds of contacts (`tactile.prints.contacts`).
`stats_markdown` lays one or two datasets side by side; a figure the dataset cannot give reads
"not in this dataset".
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from tactile.dataset.reader import open_dataset
from tactile.prints.anchors import ANCHORS
from tactile.prints.contacts import ContactGroup, contact_groups
from tactile.prints.figures import (
    GROUP_STATS,
    PARTS,
    Estimate,
    anchored_values,
    group_figures,
    groups,
    part_shares,
)
from tactile.prints.measures import Prints, read_prints

MISSING = "not in this dataset"


@dataclass(frozen=True)
class DatasetStats:
    """The figures of one dataset: its ``name`` and ``origin`` (path, size, how it was made),
    the per-sample ``prints``, ``groups`` (name -> `GROUP_STATS` figures), ``shares`` (group
    name -> part shares), ``anchored`` (anchor key -> figure) and ``contacts`` (the groups of
    `tactile.prints.contacts.contact_groups`; None: one contact per sample)."""

    name: str
    origin: str
    prints: Prints
    groups: dict[str, dict[str, Estimate | None]]
    shares: dict[str, dict[str, Estimate | None]]
    anchored: dict[str, Estimate | None]
    contacts: list[ContactGroup] | None = None


def dataset_stats(
    path: str | Path, name: str | None = None, seed: int = 0, progress: bool = False
) -> DatasetStats:
    """Read the dataset at ``path`` and compute its figures (bootstrap seeded by ``seed``)."""
    with open_dataset(path) as ds:
        prints = read_prints(ds, progress=progress)
        contacts = contact_groups(ds, seed)
        attrs = ds.attrs
        origin = _origin(ds.path, len(ds), attrs)
    masks = groups(prints)
    hand_groups = [(g, m) for g, m in masks if (prints.kind[m] == "hand").all()]
    return DatasetStats(
        name=name or Path(path).name,
        origin=origin,
        prints=prints,
        groups={g: group_figures(prints, m, seed) for g, m in masks},
        shares={g: part_shares(prints, m, seed) for g, m in hand_groups},
        anchored=anchored_values(prints, seed),
        contacts=contacts,
    )


def _origin(path: Path, n: int, attrs: dict) -> str:
    config = attrs.get("config")
    if isinstance(config, dict):
        made = f"generated, part {config.get('part', '?')}, seed {config.get('seed', '?')}"
    else:
        made = "ingested recording" if attrs.get("source") == "ingest" else "recording"
    return f"`{path}`: {n} samples, {made}"


def fmt(e: Estimate | None) -> str:
    """``value [low, high]`` (the interval left out when it is a point; no decimals from 1000
    on, one below), or `MISSING`."""
    if e is None:
        return MISSING
    digits = 0 if abs(e.value) >= 1000 else 1
    if e.low == e.high == e.value:
        return f"{e.value:.{digits}f}"
    return f"{e.value:.{digits}f} [{e.low:.{digits}f}, {e.high:.{digits}f}]"


def _table(head: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in rows])


def anchor_rows(stats: list[DatasetStats]) -> list[list[str]]:
    """Rows of the anchored table: figure, each dataset's value, published, source, inside."""
    rows = []
    for a in ANCHORS:
        values = [s.anchored.get(a.key) for s in stats]
        inside = [MISSING if v is None else ("yes" if a.holds(v.value) else "no") for v in values]
        rows.append([a.label, *map(fmt, values), a.published, a.source, *inside])
    return rows


def stats_markdown(stats: list[DatasetStats], seed: int = 0) -> str:
    """The report of one or two datasets: anchored figures, prints by group, part shares."""
    names = [s.name for s in stats]
    both = len(stats) > 1
    out = [
        f"# Prints of {' and '.join(names)}",
        "",
        *[f"- {s.name}: {s.origin}" for s in stats],
        "",
        f"Means and shares with their 95 % bootstrap interval over samples (seed {seed}); "
        "shares are of sums over the samples. Hand parts: thumb, index, middle, ring, pinkie "
        "(little finger), palm.",
        "",
        "## Published measurements of real hands",
        "",
        _table(
            ["figure", *names, "published", "source", *[f"inside ({n})" for n in names]],
            anchor_rows(stats),
        ),
        "",
        "## Prints by contactor kind and action",
        "",
        _table(
            ["group", *(["dataset"] if both else []), "samples", *[h for _, h in GROUP_STATS]],
            _group_rows(stats, both),
        ),
        "",
        "## Each part's share of the hand (%)",
        "",
        _table(
            ["group", *(["dataset"] if both else []), "of", *PARTS, "thumb touches"],
            _share_rows(stats, both),
        ),
        "",
        *_contact_section(stats, both),
    ]
    return "\n".join(out)


def _contact_section(stats: list[DatasetStats], both: bool) -> list[str]:
    """The samples by number and kinds of contacts, of the datasets that have several (none:
    no lines)."""
    mine = [s for s in stats if s.contacts is not None]
    if not mine:
        return []
    rows = [
        [
            g.name,
            *([s.name] if both else []),
            str(g.contacts),
            str(g.n),
            f"{g.share:.1f}",
            fmt(g.seen),
            fmt(g.fewer),
        ]
        for s in mine
        for g in s.contacts
    ]
    head = ["contactors", *(["dataset"] if both else []), "contacts", "samples"]
    head += ["% of samples", "contacts seen", "fewer seen than pressing (%)"]
    return [
        "## Several contacts at once",
        "",
        "Samples by the contactors pressing at once (`n_contacts`; *all*: every sample of that "
        "number) and by their kinds (two hands: of one person or of two, by the contactors' "
        "subjects). Contacts seen: the separate contacts the tactile image shows (distinct "
        "values of `instance_image`); a contact with no taxel above the active threshold, a "
        "print too small for the image's erosion, or one outweighed by the other contact "
        "wherever it presses, leaves none.",
        "",
        _table(head, rows),
        "",
    ]


def _group_names(stats: list[DatasetStats], table: str) -> list[str]:
    return list(dict.fromkeys(g for s in stats for g in getattr(s, table)))


def _group_rows(stats: list[DatasetStats], both: bool) -> list[list[str]]:
    rows = []
    for g in _group_names(stats, "groups"):
        for s in stats:
            if g not in s.groups:
                continue
            n = next(e.n for e in s.groups[g].values() if e is not None)
            cells = [fmt(s.groups[g][stat]) for stat, _ in GROUP_STATS]
            rows.append([g, *([s.name] if both else []), str(n), *cells])
    return rows


def _share_rows(stats: list[DatasetStats], both: bool) -> list[list[str]]:
    rows = []
    for g in _group_names(stats, "shares"):
        for s in (s for s in stats if g in s.shares):
            for what in ("pixels", "pressure"):
                cells = [fmt(s.shares[g][f"{what}.{p}"]) for p in PARTS]
                touch = fmt(s.shares[g]["thumb_touch"]) if what == "pixels" else ""
                rows.append([g, *([s.name] if both else []), what, *cells, touch])
    return rows


def summary_lines(stats: list[DatasetStats]) -> list[str]:
    """One line per anchored figure for the terminal: values, published range, inside."""
    width = max(len(a.label) for a in ANCHORS)
    lines = []
    for a, row in zip(ANCHORS, anchor_rows(stats), strict=True):
        values = "  ".join(f"{v:<22}" for v in row[1 : 1 + len(stats)])
        inside = " ".join(row[-len(stats) :])
        lines.append(f"{a.label:<{width}}  {values}  [{a.low:.4g}, {a.high:.4g}]  {inside}")
    return lines
