"""Pages typeset top to bottom: headings, paragraphs, tables and plot areas on an A4 sheet.

A :class:`Sheet` is a matplotlib figure with a cursor: each block is placed below the previous
one, measured after drawing (so wrapped text never runs off the page or into the next block).
:func:`table_sheets` flows a long table over as many sheets as it needs, repeating the header;
:func:`table_below` puts one below what a page holds; :func:`flow` places a run of figure panels,
as many per sheet as fit, each sheet's panels captioned. A column of names too wide for the page
is shortened in the middle so that different names stay different (:func:`shorten_distinct`).
Sheets keep their layout as drawn (``save_page`` does not re-run tight_layout on them).
"""

from __future__ import annotations

import functools
import textwrap
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import matplotlib.pyplot as plt
from matplotlib.backends.backend_agg import RendererAgg
from matplotlib.font_manager import FontProperties
from matplotlib.lines import Line2D
from matplotlib.patches import Rectangle

from diegocal.report.style import COLORS, PAGE_SIZE, keep_layout

LEFT, RIGHT = 0.08, 0.92  # text column, fraction of the page width
TOP, BOTTOM = 0.95, 0.06  # the footer (page numbers) sits below BOTTOM
GAP = 0.012  # between blocks, fraction of the page height
ROW_PAD = 1.45  # table row height in units of the font size


@dataclass(frozen=True)
class Column:
    """A table column: header (with its unit on a second line), alignment and cell format."""

    name: str
    unit: str = ""
    align: str = "right"
    fmt: Callable[[object], str] | None = None

    def header(self) -> str:
        return f"{self.name}\n[{self.unit}]" if self.unit else self.name

    def cell(self, value) -> str:
        if self.fmt is not None:
            return self.fmt(value)
        if value is None:
            return "–"
        if isinstance(value, float):
            return f"{value:.4g}"
        return str(value)


class Sheet:
    """One A4 page filled from the top; ``y`` is the cursor in figure coordinates."""

    def __init__(self, title: str | None = None):
        self.fig = plt.figure(figsize=PAGE_SIZE)
        keep_layout(self.fig)
        self.y = TOP
        if title:
            self.heading(title, size=14)

    # ------------------------------------------------------------------ measuring
    def _height(self, artist) -> float:
        renderer = self.fig.canvas.get_renderer()
        return artist.get_window_extent(renderer=renderer).height / self.fig.bbox.height

    def _width(self, artist) -> float:
        renderer = self.fig.canvas.get_renderer()
        return artist.get_window_extent(renderer=renderer).width / self.fig.bbox.width

    def room(self) -> float:
        """Height left above the bottom margin, fraction of the page."""
        return self.y - BOTTOM

    def line(self, size: float) -> float:
        """Height of one text line of ``size`` points, fraction of the page."""
        return size * 1.3 / (72 * PAGE_SIZE[1])

    # ------------------------------------------------------------------ blocks
    def heading(self, text: str, size: float = 11) -> None:
        t = self.fig.text(LEFT, self.y, text, fontsize=size, fontweight="bold", va="top")
        self._fit_width(t, text, size, bold=True)
        self.y -= self._height(t) + GAP

    def paragraph_height(self, text: str, size: float = 9) -> float:
        """The height a paragraph would take (with the gap after it), drawing nothing."""
        y = self.y
        self.y = 10.0  # far above the page: it always fits
        self.paragraph(text, size)
        height = 10.0 - self.y
        self.fig.texts[-1].remove()
        self.y = y
        return height

    def paragraph(self, text: str, size: float = 9, indent: float = 0.0, color: str = "black") -> bool:
        """Wrapped text; returns False (and draws nothing) when it does not fit the page."""
        width = RIGHT - LEFT - indent
        chars = int(width * PAGE_SIZE[0] * 72 / (0.52 * size))
        while True:
            body = "\n".join(textwrap.wrap(text, chars, break_long_words=True, break_on_hyphens=False)) or " "
            t = self.fig.text(LEFT + indent, self.y, body, fontsize=size, va="top", linespacing=1.3, color=color)
            if self._width(t) <= width or chars < 20:
                break
            t.remove()
            chars -= 4
        h = self._height(t)
        if self.y - h < BOTTOM:
            t.remove()
            return False
        self.y -= h + GAP
        return True

    def _fit_width(self, t, text: str, size: float, bold: bool = False) -> None:
        while self._width(t) > RIGHT - LEFT and size > 6:
            size -= 0.5
            t.set_fontsize(size)

    def axes(self, height: float, left: float = 0.1, right: float = 0.95, title_room: float = 0.025, **kw):
        """An Axes filling ``height`` of the page below the cursor; room is left above it for its
        title and below it for its tick labels and x label."""
        bottom_room = 0.045
        top = self.y - title_room
        ax = self.fig.add_axes((left, top - height + bottom_room, right - left, height - bottom_room), **kw)
        self.y -= height + title_room + GAP
        return ax

    def axes_row(self, height: float, n: int, gap: float = 0.09, left: float = 0.1, right: float = 0.95, **kw):
        """``n`` Axes side by side filling ``height`` of the page below the cursor."""
        width = (right - left - gap * (n - 1)) / n
        top = self.y - 0.025
        bottom = top - height + 0.045
        axes = [self.fig.add_axes((left + k * (width + gap), bottom, width, height - 0.045), **kw) for k in range(n)]
        self.y -= height + 0.025 + GAP
        return axes

    def caption(self, text: str) -> bool:
        """A figure's caption: what each line, band and threshold means (small, grey)."""
        return self.paragraph(text, size=8, color="0.2")

    def table(
        self,
        columns: Sequence[Column],
        rows: Sequence[Sequence],
        size: float = 7.5,
        max_rows: int | None = None,
        dry: bool = False,
        reserve: float = 0.0,
    ) -> int:
        """Draw as many rows as fit, at most ``max_rows`` (header first); returns how many rows were
        drawn (with ``dry``, how many would fit, drawing nothing); ``reserve`` keeps that much of the
        page free below the table when every row fits (for the notes that follow it)."""
        texts = [[c.cell(v) for c, v in zip(columns, row, strict=True)] for row in rows]
        widths = _column_widths(columns, texts, size)
        scale = min(1.0, (RIGHT - LEFT) / sum(widths))
        if scale < 1.0:  # too wide: smaller type, down to 6.5 pt
            size = max(6.5, size * scale)
            widths = _column_widths(columns, texts, size)
        texts, widths = _clip_to_page(columns, texts, widths, size)
        total = sum(widths)
        x0 = LEFT
        row_h = size * ROW_PAD / (72 * PAGE_SIZE[1])
        head_lines = max(c.header().count("\n") + 1 for c in columns)
        head_h = row_h * (0.35 + 0.9 * head_lines)
        n = int((self.y - head_h - BOTTOM) // row_h)
        if reserve and n >= len(texts):  # all rows fit: do the notes fit below them too?
            n = min(n, int((self.y - head_h - BOTTOM - reserve) // row_h))
        n = max(0, min(n, len(texts), len(texts) if max_rows is None else max_rows))
        if dry or (n == 0 and texts):
            return n
        y = self.y
        xs = [x0 + sum(widths[:k]) for k in range(len(widths))]
        for c, x, w in zip(columns, xs, widths, strict=True):
            self._cell(c.header(), x, w, y - head_h / 2, c.align, size, bold=True)
        y -= head_h
        self.fig.add_artist(_rule(x0, y, total, lw=0.8))
        for i, cells in enumerate(texts[:n]):
            if i % 2 == 1:
                self.fig.add_artist(
                    Rectangle((x0, y - row_h), total, row_h, transform=self.fig.transFigure, color="0.94", lw=0)
                )
            for c, x, w, text in zip(columns, xs, widths, cells, strict=True):
                self._cell(text, x, w, y - row_h / 2, c.align, size)
            y -= row_h
        self.fig.add_artist(_rule(x0, y, total, lw=0.6))
        self.y = max(y - GAP, BOTTOM)
        return n

    def _cell(self, text: str, x: float, w: float, y: float, align: str, size: float, bold: bool = False) -> None:
        pad = 0.006
        ha = {"right": "right", "left": "left", "center": "center"}[align]
        xx = {"right": x + w - pad, "left": x + pad, "center": x + w / 2}[align]
        self.fig.text(
            xx, y, text, fontsize=size, ha=ha, va="center", fontweight="bold" if bold else "normal", linespacing=1.1
        )


def _column_widths(columns, texts, size: float) -> list[float]:
    """Widths (fraction of the page) of the widest cell of each column at ``size`` points (the
    header in bold), measured with the renderer's font metrics, plus padding."""
    out = []
    for k, c in enumerate(columns):
        head = [text_width(line, size, bold=True) for line in c.header().split("\n")]
        widest = max(head + [text_width(r[k], size) for r in texts])
        out.append(widest + 0.016)
    return out


def _clip_to_page(columns, texts, widths, size: float):
    """When a table is still wider than the text column, shorten the cells of its widest
    left-aligned column (text, not numbers) until it fits, keeping different cells different."""
    excess = sum(widths) - (RIGHT - LEFT)
    left = [k for k, c in enumerate(columns) if c.align == "left"]
    if excess <= 0 or not left:
        return texts, widths
    k = max(left, key=lambda i: widths[i])
    target = max(widths[k] - excess, 0.08)
    short = shorten_distinct([row[k] for row in texts], lambda t: text_width(t, size) + 0.016 <= target)
    texts = [[*row[:k], cell, *row[k + 1 :]] for row, cell in zip(texts, short, strict=True)]
    return texts, _column_widths(columns, texts, size)


ELLIPSIS = "…"
SEPARATORS = "_./- "
#: Shares of the kept characters given to the end of a shortened text, tried in turn (the first
#: that keeps every text distinct wins): names that share a prefix differ at their ends.
TAIL_SHARES = (0.5, 0.6, 0.7, 0.4, 0.8, 0.3)


def shorten_distinct(texts: Sequence[str], fits: Callable[[str], bool]) -> list[str]:
    """``texts`` with those that do not ``fit`` shortened by an ellipsis in the middle, so that
    different texts stay different: ``r_shoulder_pitch.flex`` and ``r_shoulder_pitch.ext`` become
    ``r_shoul…pitch.flex`` and ``r_shoul…pitch.ext``, not twice ``r_shoulder_pitch.…``.

    The head and tail are shared as :data:`TAIL_SHARES` says, the first share that keeps every
    text distinct; failing that, each text keeps the shortest tail no other text ends with. A text
    that cannot be shortened to fit and stay distinct is left whole."""
    unique = list(dict.fromkeys(texts))
    long = [t for t in unique if not fits(t)]
    if not long:
        return list(texts)
    for share in TAIL_SHARES:
        short = {t: _middle(t, fits, share) for t in long}
        if len({short.get(t, t) for t in unique}) == len(unique):
            return [short.get(t, t) for t in texts]
    short = {t: _distinct_tail(t, unique, fits) for t in long}
    if len({short.get(t, t) for t in unique}) < len(unique):
        short = {}
    return [short.get(t, t) for t in texts]


def _middle(text: str, fits: Callable[[str], bool], tail_share: float) -> str:
    """The longest ``head…tail`` of ``text`` that fits, about ``tail_share`` of the kept characters at
    the end; the tail starts after a separator (``_``, ``.``, ``/``, ``-``, space) when one is near."""
    after = [i + 1 for i, c in enumerate(text) if c in SEPARATORS]
    for keep in range(len(text) - 1, 1, -1):
        want = max(1, round(keep * tail_share))
        near = [len(text) - i for i in after if abs(len(text) - i - want) <= max(2, want // 3)]
        tail = min(near, key=lambda n: abs(n - want)) if near else want
        if tail >= keep:
            continue
        candidate = text[: keep - tail] + ELLIPSIS + text[len(text) - tail :]
        if fits(candidate):
            return candidate
    return text[:1] + ELLIPSIS


def _distinct_tail(text: str, others: Sequence[str], fits: Callable[[str], bool]) -> str:
    """``head…tail`` with the shortest tail no other text ends with and as much head as fits; the
    whole text when that does not fit."""
    rest = [o for o in others if o != text]
    n = next((n for n in range(1, len(text)) if not any(o.endswith(text[-n:]) for o in rest)), len(text))
    for head in range(len(text) - n - 1, 0, -1):
        if fits(text[:head] + ELLIPSIS + text[-n:]):
            return text[:head] + ELLIPSIS + text[-n:]
    return text


def text_width(text: str, size: float, bold: bool = False) -> float:
    """Width of one line of text at ``size`` points, fraction of the page width."""
    prop = FontProperties(size=size, weight="bold" if bold else "normal")
    w, _, _ = _renderer().get_text_width_height_descent(text or " ", prop, ismath=False)
    return w / (MEASURE_DPI * PAGE_SIZE[0])  # pixels at MEASURE_DPI -> fraction of the page width


#: Text is measured at this resolution: at 72 dpi glyph hinting makes widths wrong by up to 10 %, and
#: differently at each type size (a 59-character line of 7.5-pt text: 243 pt at 72 dpi, 227 pt at 288 dpi).
MEASURE_DPI = 288


@functools.cache
def _renderer():
    return RendererAgg(10, 10, MEASURE_DPI)


def _rule(x: float, y: float, w: float, lw: float = 0.6):
    return Line2D([x, x + w], [y, y], lw=lw, color=COLORS["measured"])


def table_sheets(
    title: str,
    columns: Sequence[Column],
    rows: Sequence[Sequence],
    intro: Sequence[str] = (),
    notes: Sequence[str] = (),
    sheet: Sheet | None = None,
    size: float = 7.5,
    balance: bool = True,
) -> list[Sheet]:
    """A table over as many sheets as it needs: the intro paragraphs first, the header repeated on
    every sheet ("title (continued)"), the notes after the last row (on a new sheet if need be).
    Continues on ``sheet`` when given. ``balance``: when the rows spill onto one more sheet, share
    them evenly (no stub last page); without it, fill each sheet (more content follows the table)."""
    sheets = [sheet or Sheet(title)]
    if sheet is not None:
        sheet.heading(title)
    for p in intro:
        if not sheets[-1].paragraph(p):
            sheets.append(Sheet(f"{title} (continued)"))
            sheets[-1].paragraph(p)
    rest = list(rows)
    reserve = sum(sheets[-1].paragraph_height(p, size=8) for p in notes)  # the notes stay with rows
    while True:
        fit = sheets[-1].table(columns, rest, size=size, dry=True, reserve=reserve)
        limit, fresh = None, None
        if fit < len(rest) and balance:  # it spills: when one more page takes the rest, share the rows evenly
            fresh = Sheet(f"{title} (continued)")
            if len(rest) - fit <= fresh.table(columns, rest, size=size, dry=True, reserve=reserve):
                limit = max(1, min(fit, -(-len(rest) // 2)))
        n = sheets[-1].table(columns, rest, size=size, max_rows=limit, reserve=reserve)
        rest = rest[n:]
        if not rest:
            if fresh is not None:
                plt.close(fresh.fig)
            break
        sheets.append(fresh or Sheet(f"{title} (continued)"))
    for p in notes:
        if not sheets[-1].paragraph(p, size=8, color="0.25"):
            sheets.append(Sheet(f"{title} (continued)"))
            sheets[-1].paragraph(p, size=8, color="0.25")
    return sheets


def table_below(
    sheets: list[Sheet], title: str, columns, rows, notes, room: float = 0.25, balance: bool = True
) -> None:
    """A table below the last sheet's content when ``room`` is left there, else from a new page.
    ``balance`` as in :func:`table_sheets` (False for a table that figures follow: fill its pages)."""
    if sheets[-1].room() > room:
        sheets[-1:] = table_sheets(title, columns, rows, notes=notes, sheet=sheets[-1], balance=balance)
    else:
        sheets += table_sheets(title, columns, rows, notes=notes, balance=balance)


#: Figure panels placed by :func:`flow` may shrink to this share of their height to fill a page.
SHRINK = 0.75


def flow(
    sheets: list[Sheet],
    title: str,
    heading: str,
    caption: str | Callable[[range], str],
    n: int,
    height: float,
    draw: Callable[[int, Sheet, float], object],
    last: bool = False,
) -> None:
    """``n`` panels (``draw(k, sheet, height)`` places panel k), as many per sheet as fit, under
    ``heading``, the caption below each sheet's panels; new sheets are titled ``title (continued)``.
    ``caption``: the words, or a function of the panels a sheet holds (a ``range``) that says what
    those panels show. Panels are ``height`` high, or down to ``SHRINK`` of it when that fits one
    more on the sheet. ``last``: nothing follows in the section, so no sheet is left holding a lone
    panel."""
    words = caption if callable(caption) else lambda panels: caption
    k = 0
    while k < n:
        sheet = sheets[-1]
        longest = max((words(range(k, k + m)) for m in range(1, n - k + 1)), key=len)
        room = sheet.room() - 0.035 - sheet.paragraph_height(longest, size=8)
        extra = 0.025 + GAP  # title room and gap of each panel
        fit = int(room // (height + extra))
        tight = int(room // (SHRINK * height + extra))
        h = height
        if tight > fit and fit < n - k:  # smaller panels take one more (or the rest)
            fit = min(tight, n - k)
            h = min(height, room / fit - extra)
        if fit < 1:
            sheets.append(Sheet(f"{title} (continued)"))
            continue
        take = min(fit, n - k)
        lone = last and n - k - take == 1 and take >= 2  # the next sheet would hold a lone panel
        take -= lone
        sheet.heading(heading + (" (continued)" if k else ""))
        for i in range(k, k + take):
            draw(i, sheet, h)
        sheet.caption(words(range(k, k + take)))
        k += take
        if lone:  # the two last panels share the next sheet
            sheets.append(Sheet(f"{title} (continued)"))


def split_axes(ax, share: float = 0.62, gap: float = 0.012):
    """Split an Axes' area in two stacked Axes sharing its x axis: the top ``share`` of the height
    (its x tick labels hidden) and the rest below, ``gap`` (fraction of the page) between them.
    Returns (top, bottom); the top's x label stays hidden (the bottom's says it)."""
    box = ax.get_position()
    top_h = (box.height - gap) * share
    bottom_h = box.height - gap - top_h
    ax.set_position((box.x0, box.y1 - top_h, box.width, top_h))
    below = ax.figure.add_axes((box.x0, box.y0, box.width, bottom_h), sharex=ax)
    ax.tick_params(labelbottom=False)
    ax.xaxis.label.set_visible(False)
    return ax, below
