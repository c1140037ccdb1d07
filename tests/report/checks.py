"""Checks every report page must pass, as a reader of the PDF sees it (text and its position read
back with pymupdf): nothing off the page or overlapping, no near-empty page, type of 5.5 pt or more."""

from __future__ import annotations

import itertools
import re


def spans(page):
    """(ink box, text, size) of every text span: the box spans the glyphs from the baseline, not
    the font's whole line height (which pymupdf reports and which overlaps between table rows)."""
    import pymupdf

    out = []
    for block in page.get_text("dict")["blocks"]:
        for line in block.get("lines", []):
            for s in line["spans"]:
                if s["text"].strip():
                    x0, _, x1, _ = s["bbox"]
                    y, z = s["origin"][1], s["size"]
                    out.append((pymupdf.Rect(x0, y - 0.72 * z, x1, y + 0.18 * z), s["text"], z))
    return out


def check_pages(document, min_words: int = 40) -> None:
    """Assert every page of an open pymupdf document is laid out cleanly."""
    for number, page in enumerate(document, start=1):
        found = spans(page)
        box = page.rect
        outside = [t for r, t, _ in found if not box.contains(r)]
        assert not outside, f"page {number}: text off the page: {outside[:3]}"
        clash = [
            (t1, t2)
            for (r1, t1, _), (r2, t2, _) in itertools.combinations(found, 2)
            if (r1 & r2).get_area() > 0.25 * min(r1.get_area(), r2.get_area())
        ]
        assert not clash, f"page {number}: overlapping text {clash[:3]}"
        words = sum(len(t.split()) for _, t, _ in found)
        assert words >= min_words, f"page {number} holds almost nothing ({words} words)"
        assert min(z for _, _, z in found) >= 5.5, f"page {number}: type below 5.5 pt (8-pt exponents are 5.6)"


def page_texts(document) -> list[str]:
    """Each page's text with its lines rejoined by spaces."""
    return [" ".join(page.get_text().split()) for page in document]


def front_pages(document) -> int:
    """How many pages the report's front matter (title, contents and summary) takes (their footer says so)."""
    return sum(bool(re.search(r"contents and summary\s+·\s+page \d+ of", t)) for t in page_texts(document))
