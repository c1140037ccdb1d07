"""Shared plot styling: every figure is assembled from `(result, ax=None) -> Axes` functions."""

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


def axes_or_new(ax=None, figsize=(6, 4)):
    """The given axes, or a new figure's."""
    if ax is None:
        _, ax = plt.subplots(figsize=figsize)
    return ax


def page(nrows: int = 1, ncols: int = 1, title: str | None = None, **kw):
    """A new A4 page with a grid of axes; returns (figure, axes array)."""
    fig, axes = plt.subplots(nrows, ncols, figsize=PAGE_SIZE, squeeze=False, **kw)
    if title:
        fig.suptitle(title, fontsize=12, fontweight="bold")
    return fig, axes


def text_page(title: str, lines, fontsize: int = 9):
    """A page of monospaced text (tables, run facts)."""
    fig = plt.figure(figsize=PAGE_SIZE)
    fig.text(0.08, 0.95, title, fontsize=14, fontweight="bold", va="top")
    fig.text(0.08, 0.91, "\n".join(lines), fontsize=fontsize, family="monospace", va="top")
    return fig


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
