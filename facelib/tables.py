"""Tables for the chapters: a number with its 95 % interval, a Markdown table, and a
table of the paper's beside ours (method | paper | ours [95 % interval] | same
ordering?)."""

from __future__ import annotations

import numpy as np

from . import metrics


def interval_cell(value, interval=None, digits=0):
    """'83 [75, 90]': ``value`` with its 95 % ``interval`` (None: the value alone),
    ``digits`` decimals."""
    text = f"{value:.{digits}f}"
    return (
        text
        if interval is None
        else f"{text} [{interval[0]:.{digits}f}, {interval[1]:.{digits}f}]"
    )


def rate_cell(hits):
    """A rate in % of boolean ``hits`` (one per sequence) with its 95 % bootstrap
    interval, as a cell."""
    hits = np.asarray(hits, dtype=float)
    low, high = np.clip(
        metrics.bootstrap_interval(lambda h: 100 * h.mean(), hits), 0, 100
    )
    return interval_cell(100 * hits.mean(), (low, high))


def score_cells(score, multimodality=False):
    """The cells of an ``Evaluator.score(..., intervals=True)`` result: Acc (%) and FID,
    each with its 95 % interval, and the multimodality when asked."""
    cells = [
        interval_cell(score["accuracy"], score["accuracy_ci"]),
        interval_cell(score["fid"], score["fid_ci"], 1),
    ]
    return cells + [f"{score['multimodality']:.2f}"] if multimodality else cells


def markdown(columns, rows):
    """A Markdown table: a header line of ``columns``, then one line per row (cells
    shown with ``str``)."""
    if any(len(row) != len(columns) for row in rows):
        raise ValueError(
            f"every row needs {len(columns)} cells ({columns}), got"
            f" {[len(r) for r in rows]}"
        )
    lines = ["| " + " | ".join(map(str, columns)) + " |", "|" + "---|" * len(columns)]
    return "\n".join(lines + ["| " + " | ".join(map(str, row)) + " |" for row in rows])


def show(columns, rows):
    """Display :func:`markdown`'s table in a notebook."""
    show_markdown(markdown(columns, rows))


def show_markdown(text):
    """Display Markdown text (a table) in a notebook."""
    from IPython.display import Markdown, display

    display(Markdown(text))


def ranks(values, higher_is_better=True):
    """The rank (1 = best) of each of ``values``."""
    order = np.argsort(
        -np.asarray(values) if higher_is_better else np.asarray(values), kind="stable"
    )
    return (np.argsort(order) + 1).tolist()


def paper_beside_ours(paper, ours, higher_is_better=True, digits=1):
    """Rows [method, paper, ours [95 % interval], rank: paper / ours, same ordering?]
    for one column of a paper's table.  ``paper``: {method: printed value} (shown with 2
    decimals, as printed); ``ours``: {method: (value, interval or None)} for the paper's
    methods (a method of the paper that we did not reproduce gets a row saying so, and
    the ranks are among the methods both have).  "Same ordering?" looks at every other
    method: "yes" when none swaps places with this one, "no (intervals overlap)" when
    every swap is with a method whose interval overlaps this one's (our data cannot
    order the two), and "**no**" otherwise."""
    extra = sorted(set(ours) - set(paper))
    if extra:
        raise ValueError(
            f"methods {extra} are not in the paper's table {sorted(paper)}"
        )
    methods = [m for m in paper if m in ours]
    paper_rank = dict(
        zip(methods, ranks([paper[m] for m in methods], higher_is_better))
    )
    our_rank = dict(
        zip(methods, ranks([ours[m][0] for m in methods], higher_is_better))
    )
    rows = []
    for m in paper:
        if m not in ours:
            rows.append([m, f"{paper[m]:.2f}", "not reproduced", "", ""])
            continue
        value, interval = ours[m]
        swapped = [
            n
            for n in methods
            if n != m and (paper_rank[m] < paper_rank[n]) != (our_rank[m] < our_rank[n])
        ]
        unresolved = all(
            interval is not None
            and ours[n][1] is not None
            and metrics.intervals_overlap(interval, ours[n][1])
            for n in swapped
        )
        same = (
            "yes"
            if not swapped
            else "no (intervals overlap)" if unresolved else "**no**"
        )
        rows.append(
            [
                m,
                f"{paper[m]:.2f}",
                interval_cell(value, interval, digits),
                f"{paper_rank[m]} / {our_rank[m]}",
                same,
            ]
        )
    return rows


PAPER_COLUMNS = [
    "method",
    "paper",
    "ours [95 % interval]",
    "rank: paper / ours",
    "same ordering?",
]


def paper_and_ours(paper_table, ours, lower_is_better=(), digits=1):
    """The table "The paper and this book" for several columns of a paper table: rows
    [column, method, paper, ours [95 % interval], rank: paper / ours, same ordering?]
    (:func:`paper_beside_ours`).  ``paper_table``: {method: {column: printed value}};
    ``ours``: {column: {method: (value, interval)}}; ``lower_is_better``: the columns
    where lower is better (FID)."""
    rows = []
    for name, values in ours.items():
        printed = {m: row[name] for m, row in paper_table.items()}
        rows += [
            [name, *r]
            for r in paper_beside_ours(
                printed, values, name not in lower_is_better, digits
            )
        ]
    return rows


PAPER_TABLE_COLUMNS = ["column", *PAPER_COLUMNS]
