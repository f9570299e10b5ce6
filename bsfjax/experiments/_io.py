"""Files and tables of the experiments: tidy rows → CSV, summaries, Markdown pivots, PNG plots.

All files are written atomically (`bsfjax._util._files.atomic_path`): a failed or interrupted
run leaves no partial file.
"""

from __future__ import annotations

import csv
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .._util import atomic_path

__all__ = ["summarize", "pivot_markdown", "write_csv", "Report"]

#: The settings line of ``NAME.md`` (unless a report gives its own).
PAPER_SETTINGS = ("n_BSF = 5 % (Euclidean FPS), τ = (0.001, 0.005, 0.01) unit-area, γ = 0.75, "
                  "S = 10, ε = ‖f‖/10, area-weighted coding")


class Report(NamedTuple):
    """What an experiment's report function returns (files are written by ``reproduce``).

    **Attributes:**

    - `markdown`: the body of ``NAME.md`` (below the header).
    - `panels`: figure panels for ``NAME.png`` (``[(title, xlabel, {label: (xs, ys)},
      categorical)]``, see ``_line_plot``), or ``None`` for no figure.
    - `settings`: the settings line of the header, or ``None`` for `PAPER_SETTINGS`.
    """

    markdown: str
    panels: list | None = None
    settings: str | None = None
    #: ``figure(path) -> path`` writes a figure of its own (instead of ``panels``' line plot)
    figure: Callable[[Path], Path] | None = None


def summarize(rows: Sequence[dict], by: Sequence[str], value: str = "error") -> list[dict]:
    """Mean, standard deviation, median and count of ``value`` per group of ``by`` columns
    (groups in first-seen order; non-finite values are left out of the statistics).

    **Arguments:**

    - `rows`: tidy rows (dicts), as the experiments return them.
    - `by`: the columns that define a group.
    - `value`: the column to aggregate.
    """
    groups: dict = {}
    for r in rows:
        groups.setdefault(tuple(r[b] for b in by), []).append(r[value])
    out = []
    for key, vals in groups.items():
        v = np.asarray(vals, dtype=np.float64)
        v = v[np.isfinite(v)]
        out.append({**dict(zip(by, key)), "mean": float(v.mean()) if v.size else float("nan"),
                    "std": float(v.std()) if v.size else float("nan"),
                    "median": float(np.median(v)) if v.size else float("nan"), "n": int(v.size)})
    return out


def pivot_markdown(rows: Sequence[dict], index: str | Sequence[str], columns: str | Sequence[str],
                   value: str = "error", stat: str = "mean", fmt: str = "{:.3f}",
                   best: str | None = "min") -> str:
    """A Markdown table: one row per ``index`` value, one column per ``columns`` value, cells the
    ``stat`` of ``value``; the best cell of each column in bold (``best="min"``/``"max"``).

    **Arguments:**

    - `rows`: tidy rows.
    - `index`: column(s) whose values make the table's rows.
    - `columns`: column(s) whose values make the table's columns.
    - `value`: the aggregated column; stat: ``"mean"``, ``"std"``, ``"median"`` or ``"n"``.
    - `fmt`: cell format; best: ``"min"``, ``"max"`` or ``None`` (no bold cell).
    """
    index = (index,) if isinstance(index, str) else tuple(index)
    columns = (columns,) if isinstance(columns, str) else tuple(columns)
    summ = summarize(rows, index + columns, value)
    ridx = list(dict.fromkeys(tuple(s[i] for i in index) for s in summ))
    cidx = list(dict.fromkeys(tuple(s[c] for c in columns) for s in summ))
    cell = {(tuple(s[i] for i in index), tuple(s[c] for c in columns)): s[stat] for s in summ}
    bests = {}
    for c in cidx:
        vals = [cell[(r, c)] for r in ridx if (r, c) in cell and np.isfinite(cell[(r, c)])]
        if vals and best:
            bests[c] = min(vals) if best == "min" else max(vals)
    head = " / ".join(index) + " \\ " + " / ".join(columns)
    lines = ["| " + head + " | " + " | ".join(", ".join(map(str, c)) for c in cidx) + " |",
             "|---" * (len(cidx) + 1) + "|"]
    for r in ridx:
        cells = []
        for c in cidx:
            v = cell.get((r, c))
            if v is None or not np.isfinite(v):
                cells.append("–")
            else:
                s = fmt.format(v)
                cells.append(f"**{s}**" if bests.get(c) == v else s)
        lines.append("| " + ", ".join(map(str, r)) + " | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_csv(rows: Sequence[dict], path) -> Path:
    """Write tidy rows (union of keys as header) atomically; returns the path.

    **Arguments:**

    - `rows`: tidy rows (dicts).
    - `path`: the ``.csv`` file to write.
    """
    path = Path(path)
    # keys starting with "_" carry per-vertex payloads for figures, not table columns
    keys = [k for k in dict.fromkeys(k for r in rows for k in r) if not k.startswith("_")]
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=keys, extrasaction="ignore")
            w.writeheader()
            w.writerows(rows)
    return path


def _write_text(text: str, path) -> Path:
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text(text)
    return path


def _line_plot(panels, path, ylabel="mean relative error"):
    """``panels``: list of (title, xlabel, {label: (xs, ys)}, categorical) → one PNG."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(4.2 * len(panels), 3.6), dpi=110)
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, len(panels), squeeze=False)[0]
    bases = list(dict.fromkeys(lb.removesuffix(" (approx)") for _, _, ls, _ in panels
                               for lb in ls))
    colour = {b: f"C{i % 10}" for i, b in enumerate(bases)}  # one colour per method
    for ax, (title, xlabel, lines, categorical) in zip(axes, panels):
        for label, (xs, ys) in lines.items():
            x = np.arange(len(xs)) if categorical else np.asarray(xs, float)
            approx = label.endswith(" (approx)")
            ax.plot(x, ys, marker="o", ms=3, label=label, ls="--" if approx else "-",
                    color=colour[label.removesuffix(" (approx)")])
            if categorical:
                ax.set_xticks(x, [str(v) for v in xs])
        ax.set_title(title)
        ax.set_xlabel(xlabel)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=6)
    axes[0].set_ylabel(ylabel)
    fig.tight_layout()
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    return path


def _curve(summ, filt, x):
    pts = [(s[x], s["mean"]) for s in summ if all(s[k] == v for k, v in filt.items())]
    return [p[0] for p in pts], [p[1] for p in pts]


def _header(name: str, description: str, meta: dict) -> str:
    """The top of ``NAME.md``: title, what it reproduces, and the run's settings as a list."""
    m = "\n".join(f"- {k}: {v}" for k, v in meta.items())
    return f"# {name}\n\n{description}\n\n{m}\n"
