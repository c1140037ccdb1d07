"""Shared plot styling: every figure is assembled from `(result, ax=None) -> Axes` functions.

Colours with a meaning (measured, model, baseline, ...), the styles of traces that have none (the
channels of a stream), the page size and the helpers every section's plots and pages use.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

PAGE_SIZE = (8.27, 11.69)  # A4 portrait, inches
COLORS = {
    "measured": "0.2",
    "model": "tab:blue",
    "truth": "tab:green",
    "baseline": "tab:orange",
    "residual": "tab:red",
    "band": "tab:blue",
}
#: Traces without a meaning of their own (a stream's channels) take the ten colours in turn, then
#: the ten again with another line style: 40 traces stay distinct, in the plot and in its legend.
TRACE_COLORS = tuple(f"C{k}" for k in range(10))
TRACE_LINESTYLES = ("-", "--", ":", "-.")

#: Unit of each log stream (DESIGN.md, "Log format"; pressure: kPa in the bundled robots).
STREAM_UNITS = {
    "pots": "V",
    "markers": "m",
    "q": "rad",
    "qd": "rad/s",
    "qdd": "rad/s²",
    "tau": "N·m",
    "tau_std": "N·m",
    "tau_measured": "N·m",
    "pressure": "kPa",
    "valve": "V",
}

plt.rcParams.update(
    {
        "font.size": 8,
        "axes.titlesize": 9,
        "axes.grid": True,
        "grid.alpha": 0.3,
        "legend.fontsize": 7,
        "figure.dpi": 100,
    }
)


def trace_style(k: int) -> dict:
    """Colour and line style of the ``k``-th trace (from 0) of a plot of many channels."""
    n = len(TRACE_COLORS)
    return {"color": TRACE_COLORS[k % n], "ls": TRACE_LINESTYLES[(k // n) % len(TRACE_LINESTYLES)]}


def axes_or_new(ax=None, figsize=(6, 4)):
    """The given axes, or a new figure's."""
    if ax is None:
        _, ax = plt.subplots(figsize=figsize)
    return ax


def headroom(ax, share: float = 0.25) -> None:
    """Raise the top of the y axis by ``share`` of its range: a legend at the top then covers no data."""
    lo, hi = ax.get_ylim()
    ax.set_ylim(lo, hi + share * (hi - lo))


def legend_above_data(ax, ncol: int = 3) -> None:
    """One row of legend in a band added above the data, so that it covers none of it."""
    headroom(ax, 0.3)
    ax.legend(fontsize=6, loc="upper center", ncol=ncol, frameon=False)


def keep_layout(fig) -> None:
    """Mark a figure laid out by hand (:mod:`diegocal.report.layout`): save_page leaves it as drawn."""
    fig.diegocal_fixed_layout = True


def save_page(pdf, fig) -> None:
    """Lay the page out (unless it was laid out by hand) and add it to the report.

    The bottom 3 % of the page is left free for the report's footer (page numbers)."""
    if fig.axes and not getattr(fig, "diegocal_fixed_layout", False):
        fig.tight_layout(rect=(0, 0.03, 1, 0.96))
    pdf.savefig(fig)
    plt.close(fig)
