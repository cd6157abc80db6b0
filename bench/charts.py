"""matplotlib charts for the report, drawn off-screen (Agg) into PNG files.

matplotlib is optional (the bench extras): :func:`pyplot` raises
:class:`~bench.core.MissingDependencyError` without it, and the runner then leaves the charts out
and says so in the report. The helpers cover what the report needs: bars (receive rates, wire
bytes), a latency histogram and a line chart (throughput against window size).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from .core import require

_DPI = 110
_COLORS = ("#2b6cb0", "#c05621", "#2f855a", "#6b46c1", "#b7791f", "#4a5568", "#c53030")


@functools.cache
def pyplot() -> Any:
    """matplotlib.pyplot on the Agg backend (no display needed)."""
    matplotlib = require("matplotlib", "matplotlib")
    matplotlib.use("Agg")
    return require("matplotlib.pyplot", "matplotlib")


def _short_number(x: float, _pos: object = None) -> str:
    """Axis labels that do not run into each other: 250k rather than 250,000."""
    if abs(x) >= 1_000_000:
        return f"{x / 1_000_000:g}M"
    if abs(x) >= 1_000:
        return f"{x / 1_000:g}k"
    return f"{x:g}"


def _save(fig: Any, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    # No timestamp in the PNG's metadata, so an unchanged chart stays byte-identical.
    fig.savefig(path, dpi=_DPI, metadata={"Software": None})
    pyplot().close(fig)
    return path


def hbars(
    path: Path,
    labels: Sequence[str],
    panels: Sequence[tuple[str, Sequence[float]]],
    *,
    title: str,
    log: bool = False,
    highlight: int | None = None,
    secondary: Sequence[int] = (),
    vline: tuple[str, float] | None = None,
) -> Path:
    """Horizontal bars, one panel per (x label, values), labels top to bottom.

    ``highlight`` is the index of the bar drawn in the first colour (protoduino), ``secondary``
    those drawn in a lighter shade of it (variants of protoduino), the others are grey;
    ``vline`` marks a goal on the last panel.
    """
    plt = pyplot()
    ticker = require("matplotlib.ticker", "matplotlib")
    fig, axes = plt.subplots(
        1, len(panels), figsize=(5.2 * len(panels), 0.45 * len(labels) + 1.4), squeeze=False
    )
    ys = list(range(len(labels)))[::-1]
    colors = [
        _COLORS[0] if i == highlight else "#90cdf4" if i in secondary else "#a0aec0"
        for i in range(len(labels))
    ]
    for ax, (xlabel, values) in zip(axes[0], panels, strict=True):
        ax.barh(ys, values, color=colors)
        ax.set_yticks(ys)
        ax.set_yticklabels(labels if ax is axes[0][0] else [""] * len(labels))
        ax.set_xlabel(xlabel)
        if log:
            ax.set_xscale("log")
        ax.grid(axis="x", alpha=0.3)
        ax.xaxis.set_major_formatter(ticker.FuncFormatter(_short_number))
    if vline is not None:
        ax = axes[0][-1]
        ax.axvline(vline[1], color=_COLORS[6], linestyle="--", linewidth=1)
        ax.text(vline[1], len(labels) - 0.4, f" {vline[0]}", color=_COLORS[6], fontsize=8)
    fig.suptitle(title, fontsize=11)
    return _save(fig, path)


def stacked_hbars(
    path: Path,
    labels: Sequence[str],
    stacks: Sequence[tuple[str, Sequence[float]]],
    *,
    title: str,
    xlabel: str,
    vline: tuple[str, float] | None = None,
    legend_below: bool = False,
) -> Path:
    """Horizontal bars stacked from (legend label, values) pairs, labels top to bottom.

    ``vline`` marks a goal (label, x); ``legend_below`` moves the legend under the axes, for
    bars long enough to run under it.
    """
    plt = pyplot()
    extra = 0.9 if legend_below else 0.0
    fig, ax = plt.subplots(figsize=(7.5, 0.5 * len(labels) + 1.4 + extra))
    ys = list(range(len(labels)))[::-1]
    left = [0.0] * len(labels)
    for i, (name, values) in enumerate(stacks):
        ax.barh(ys, values, left=left, color=_COLORS[i % len(_COLORS)], label=name)
        left = [a + b for a, b in zip(left, values, strict=True)]
    ax.set_yticks(ys)
    ax.set_yticklabels(labels)
    ax.set_xlabel(xlabel)
    ax.grid(axis="x", alpha=0.3)
    if vline is not None:
        ax.axvline(vline[1], color=_COLORS[6], linestyle="--", linewidth=1, label=vline[0])
    if legend_below:
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.25), ncol=2, fontsize=8)
    else:
        ax.legend(loc="lower right", fontsize=8)
    ax.set_title(title, fontsize=11)
    return _save(fig, path)


def histogram(
    path: Path,
    series: Mapping[str, Sequence[float]],
    *,
    title: str,
    xlabel: str,
    bins: int = 50,
    vlines: Mapping[str, float] | None = None,
) -> Path:
    """Overlaid histograms (e.g. round-trip latencies per board), with labelled markers
    (e.g. the wire-time lower bound)."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    # One set of bin edges for every series (and the markers), so their bars line up.
    every = [v for values in series.values() for v in values] + list((vlines or {}).values())
    low, high = (min(every), max(every)) if every else (0.0, 1.0)
    step = (high - low) / bins if high > low else 1.0
    edges = [low + k * step for k in range(bins + 1)]
    for i, (name, values) in enumerate(series.items()):
        ax.hist(values, bins=edges, alpha=0.6, color=_COLORS[i % len(_COLORS)], label=name)
    for i, (name, x) in enumerate((vlines or {}).items()):
        ax.axvline(x, color=_COLORS[(i + 3) % len(_COLORS)], linestyle="--", label=name)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("count")
    ax.legend(fontsize=8)
    ax.set_title(title, fontsize=11)
    return _save(fig, path)


def lines(
    path: Path,
    x: Sequence[float],
    series: Mapping[str, Sequence[float]],
    *,
    title: str,
    xlabel: str,
    ylabel: str,
    hlines: Mapping[str, float] | None = None,
) -> Path:
    """One line per series over ``x`` (e.g. throughput against window size), with labelled
    horizontal references (e.g. the line rate)."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    for i, (name, values) in enumerate(series.items()):
        ax.plot(x, values, marker="o", color=_COLORS[i % len(_COLORS)], label=name)
    for i, (name, y) in enumerate((hlines or {}).items()):
        ax.axhline(y, color=_COLORS[(i + 3) % len(_COLORS)], linestyle="--", label=name)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(title, fontsize=11)
    return _save(fig, path)
