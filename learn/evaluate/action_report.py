"""The action networks' part of ``handskin evaluate``'s report: accuracy beside the chance
levels, the accuracy against the frames seen, the mirror pairs by hand and how their prints
move on the skin, the confusion matrix, and two PNGs beside the report
(``<stem>_actions_confusion.png``, ``<stem>_actions_frames.png``).

    lines = action_section(rows, labels, Path("report.md"))   # rows of learn.evaluate.actions
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from matplotlib.figure import Figure

from learn import metrics as M
from tactile.files import save_figure

PHASES = ("approach", "load", "hold", "release")


def _pct(v: float) -> str:
    return "–" if np.isnan(v) else f"{100 * v:.1f}"


def _pair_rates(cm: np.ndarray, a: int, b: int) -> tuple[int, float, float]:
    """(presses of a or b, share answered right, share answered as the mirror; NaN without
    presses) from ``cm``."""
    n = int(cm[a].sum() + cm[b].sum())
    right, mirror = cm[a, a] + cm[b, b], cm[a, b] + cm[b, a]
    return n, right / n if n else np.nan, mirror / n if n else np.nan


def mirror_table(r: dict) -> list[str]:
    """Per mirror pair and hand: presses, and the share answered right or as the mirror action,
    after the first frame and after the whole press."""
    names = r["class_names"]
    out = [
        "| pair | hand | presses | right %, 1 frame | mirror %, 1 frame | right %, whole press "
        "| mirror %, whole press |",
        "|---|---|---|---|---|---|---|",
    ]
    cms = {"all": np.asarray(r["prefix_cm"])}
    cms |= {h: np.asarray(v["prefix_cm"]) for h, v in r["hands"].items()}
    for a, b in r["mirror_pairs"]:
        i, j = names.index(a), names.index(b)
        for hand, cm in cms.items():
            n, first_ok, first_mirror = _pair_rates(cm[0], i, j)
            _, ok, mirror = _pair_rates(cm[-1], i, j)
            cells = [f"{a} / {b}", hand, str(n), _pct(first_ok), _pct(first_mirror)]
            out.append("| " + " | ".join([*cells, _pct(ok), _pct(mirror)]) + " |")
    return out


def cue_table(cues: dict[str, dict]) -> list[str]:
    """How the mirror pairs' prints move on the skin (`learn.evaluate.actions.mirror_cues`)."""
    out = [
        "### What tells a mirror pair apart on the skin",
        "",
        "From the end of the load to the end of the hold, each test press's print moves "
        "(`tactile.prints.motion`): its centre of pressure shifts across the hand (the "
        "palm-to-fingers axis of its label image, turned a quarter turn counter-clockwise on the "
        "map) and its long axis turns (counter-clockwise positive). The skin reads pressure, not "
        "shear: this is what a network can see of a push's side or a twist's sense.",
        "",
        "| action | presses | shift across the hand, mm: mean (SD) | turn, °: mean (SD) |",
        "|---|---|---|---|",
    ]
    for name, c in cues.items():
        (a, a_sd), (t, t_sd) = c["across_mm"], c["turn_deg"]
        out.append(f"| {name} | {c['n']} | {a:+.1f} ({a_sd:.1f}) | {t:+.1f} ({t_sd:.1f}) |")
    return [*out, ""]


def frames_table(r: dict) -> list[str]:
    """Accuracy (%) after 1, 2, ... frames, for all presses and by hand."""
    frames = r["frames"]
    head = "| frames seen | " + " | ".join(str(k) for k in frames) + " |"
    rows = [("all", r["prefix_accuracy"])]
    rows += [
        (f"{h} hands ({v['n']})", [M.accuracy(cm) for cm in v["prefix_cm"]])
        for h, v in r["hands"].items()
        if v["n"]
    ]
    lines = [head, "|" + "---|" * (len(frames) + 1)]
    return lines + ["| " + " | ".join([name] + [_pct(a) for a in acc]) + " |" for name, acc in rows]


def confusion_figure(r: dict, title: str) -> Figure:
    """The whole-press confusion matrix as % of each true action, numbers in the cells."""
    names = r["class_names"]
    pct = M.percent_by_true_class(torch.tensor(r["cm"])).numpy()
    fig = Figure(figsize=(7.5, 6.2), layout="constrained")
    ax = fig.subplots()
    im = ax.imshow(pct, cmap="Blues", vmin=0, vmax=100)
    for (i, j), v in np.ndenumerate(pct):
        ax.text(j, i, f"{v:.0f}", ha="center", va="center", c="w" if v > 60 else "k", size=8)
    ax.set_xticks(range(len(names)), names, rotation=45, ha="right")
    ax.set_yticks(range(len(names)), names)
    ax.set_xlabel("predicted")
    ax.set_ylabel("true")
    chance = r["chance"]
    ax.set_title(
        f"{title}: {_pct(r['metrics']['accuracy'])} % on {r['n_test']} presses of held-out people\n"
        f"chance {_pct(chance['uniform'])} % (1/{len(names)}), "
        f"{_pct(chance['majority'])} % (always {chance['majority_class']})",
        size=9,
    )
    fig.colorbar(im, ax=ax, label="% of the true action", shrink=0.8)
    return fig


def frames_figure(rows: list[dict], labels: list[str]) -> Figure:
    """Accuracy against the frames seen: each network on all presses (solid) and on left hands
    (dashed), the chance levels, and the mean ends of the press's phases."""
    fig = Figure(figsize=(7.5, 4.2), layout="constrained")
    ax = fig.subplots()
    for k, (r, label) in enumerate(zip(rows, labels, strict=True)):
        ax.plot(r["frames"], [100 * a for a in r["prefix_accuracy"]], "o-", c=f"C{k}", label=label)
        left = r["hands"]["left"]
        if left["n"]:
            acc = [100 * M.accuracy(cm) for cm in left["prefix_cm"]]
            ax.plot(r["frames"], acc, "s--", c=f"C{k}", alpha=0.6, label=f"{label}, left hands")
    r = rows[0]
    chance = f"chance (1/{len(r['class_names'])})"
    ax.axhline(100 * r["chance"]["uniform"], c="0.5", ls=":", label=chance)
    ax.axhline(100 * r["chance"]["majority"], c="0.3", ls="-.", label="commonest action")
    for name, end_s in zip(PHASES, r["phase_end_s"] or (), strict=False):
        x = end_s / r["frame_period_s"]
        ax.axvline(x, c="0.8", lw=1)
        ax.text(x, 101, f"{name}\nends", va="bottom", ha="center", size=8, c="0.4")
    ax.set_xlabel(f"frames seen (one every {r['frame_period_s']:g} s)")
    ax.set_ylabel("accuracy on held-out people, %")
    ax.set_ylim(0, 100)
    ax.set_xticks(r["frames"])
    ax.legend(fontsize=8, loc="lower right")
    return fig


def _details(r: dict, label: str, confusion_png: Path) -> list[str]:
    chance = r["chance"]
    names = tuple(r["class_names"])
    lines = [
        f"### {label}: `{r['checkpoint']}` (epoch {r['epoch']}, {r['n_test']} test presses)",
        "",
        f"Accuracy {_pct(r['metrics']['accuracy'])} % over the whole press; chance "
        f"{_pct(chance['uniform'])} % (1 / {len(names)}), or {_pct(chance['majority'])} % "
        f"answering always the test split's commonest action ({chance['majority_class']}). "
        f"CPU {r['ms_per_sequence']:.1f} ms per sequence of {len(r['frames'])} frames at batch 1, "
        f"{r['threads']} thread(s); frames {tuple(r['input_size'])} px.",
        "",
        "Accuracy (%) against the frames seen (each answer from those frames alone):",
        "",
        *frames_table(r),
        "",
    ]
    if r["mirror_pairs"]:
        lines += ["Mirror pairs (% of the pair's presses):", "", *mirror_table(r), ""]
    lines += [
        f"![confusion matrix]({confusion_png.name})",
        "",
        "Confusion matrix (% of the true action), whole press:",
        "",
        confusion_markdown(torch.tensor(r["cm"]), names),
        "",
    ]
    return lines


def confusion_markdown(cm: torch.Tensor, names: tuple[str, ...]) -> str:
    """A markdown table of a confusion matrix as % of each true class (rows true)."""
    pct = M.percent_by_true_class(cm).numpy()
    head = "| true \\ predicted | " + " | ".join(names) + " |"
    rows = [
        f"| {n} | " + " | ".join(_pct(v / 100) for v in row) + " |"
        for n, row in zip(names, pct, strict=True)
    ]
    return "\n".join([head, "|" + "---|" * (len(names) + 1), *rows])


def action_section(rows: list[dict], labels: list[str], path: Path) -> list[str]:
    """The report's lines on the action networks among ``rows`` (none: no lines), and their
    PNGs beside the report at ``path``."""
    mine = [(r, lab) for r, lab in zip(rows, labels, strict=True) if r["task"] == "action"]
    if not mine:
        return []
    path = Path(path)
    frames_png = path.with_name(f"{path.stem}_actions_frames.png")
    save_figure(frames_figure([r for r, _ in mine], [lab for _, lab in mine]), frames_png)
    lines = [
        "## Actions from the 10 Hz sequence",
        "",
        f"| method | accuracy % | chance % (1/{len(mine[0][0]['class_names'])}) "
        "| commonest action % | CPU ms/sequence | trained on |",
        "|---|---|---|---|---|---|",
    ]
    for r, lab in mine:
        n_train = (r.get("train_data") or {}).get("n_train")
        data = Path((r.get("train_data") or {}).get("path") or "unknown data").name
        cells = [lab, _pct(r["metrics"]["accuracy"]), _pct(r["chance"]["uniform"])]
        cells += [_pct(r["chance"]["majority"]), f"{r['ms_per_sequence']:.1f}"]
        cells.append(data + ("" if n_train is None else f" ({n_train:,} presses)"))
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", f"![accuracy against frames seen]({frames_png.name})", ""]
    if mine[0][0].get("mirror_cues"):  # a property of the test data, shared by the rows
        lines += cue_table(mine[0][0]["mirror_cues"])
    for k, (r, lab) in enumerate(mine):
        suffix = "" if len(mine) == 1 else f"_{k + 1}"
        png = path.with_name(f"{path.stem}_actions_confusion{suffix}.png")
        save_figure(confusion_figure(r, lab), png)
        lines += _details(r, lab, png)
    return lines
