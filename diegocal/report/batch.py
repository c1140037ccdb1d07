"""Report section for a merged batch table (``COMMAND.batch.csv``; registers itself on import).

One opening paragraph (what ran over which logs, how many succeeded, which failed and why, which
files it could not use and why), then the table: one row per log with its status and the command's
headline numbers, the logs it could not use with their reason; the full set of columns is in the CSV.
"""

from __future__ import annotations

from pathlib import Path

from diegocal.batch.table import NOT_APPLICABLE, is_table, read_table
from diegocal.batch.table import headline as headline_columns
from diegocal.report.layout import Column, table_sheets
from diegocal.report.registry import Section, register_section
from diegocal.report.style import save_page

MAX_REASON = 70  # characters of a failure's reason shown in the table (the CSV has all of it)


def recognise(path: Path) -> bool:
    return Path(path).is_file() and is_table(path)


def _read(path: Path):
    return read_table(path)


def abstract(path: Path, context=None) -> list[str]:
    fields, _, rows = _read(path)
    command, source = fields.get("command", "?"), fields.get("source", "?")
    count = {s: sum(r["status"] == s for r in rows) for s in ("done", "up to date", "failed")}
    logs = len({r["log"] for r in rows if r["status"] != NOT_APPLICABLE})
    text = (
        f"diegocal {command} ran over {logs} log(s) of {source}: {count['done']} run(s) done now, "
        f"{count['up to date']} already up to date (outputs newer than their log, not rerun), "
        f"{count['failed']} failed."
    )
    failed = [r for r in rows if r["status"] == "failed"]
    if failed:
        text += " Failures: " + "; ".join(f"{Path(r['log']).name}: {r['reason']}" for r in failed[:5])
        text += " …" if len(failed) > 5 else "."
    skipped = [r for r in rows if r["status"] == NOT_APPLICABLE]
    if skipped:
        text += " Not run, as not applicable: " + "; ".join(
            f"{Path(r['log']).name}: {r['reason']}" for r in skipped[:5]
        )
        text += " …" if len(skipped) > 5 else "."
    return [text, f"Every column of every output is in {Path(path).name}; this page shows the headline numbers."]


def pages(path: Path, pdf, context) -> None:
    fields, columns, rows = _read(path)
    command = fields.get("command", "")
    shown = headline_columns(command, columns)
    pairs = _rmse_pairs(shown)
    if pairs:  # diagnose: one column "baseline → extended" whatever the units, not two per unit
        shown = [c for c in shown if c not in {x for pair in pairs for x in pair[1:]}]
        for r in rows:
            r["held-out RMSE"] = "; ".join(
                f"{_num(r.get(b))} → {_num(r.get(e))} {u}" for u, b, e in pairs if r.get(b) not in (None, "")
            )
        shown.insert(0, "held-out RMSE")
    if not shown:  # predict: every error column
        shown = [c for c in columns if " RMSE [" in c or c.startswith("markers mean distance")][:5]
    cols = [Column("log", align="left")]
    if "domain" in columns:
        cols.append(Column("domain", align="left"))
    cols += [Column("status", align="left"), Column("time", "s")]
    cols += [
        Column("held-out RMSE", "baseline → extended", align="left")
        if c == "held-out RMSE"
        else Column(*_name_unit(c), align="right" if _numeric(rows, c) else "left")
        for c in shown
    ]
    cols.append(Column("reason", align="left"))  # why it failed, or why the command cannot use the file
    table = []
    for r in rows:
        row = [Path(r["log"]).name] + ([r["domain"]] if "domain" in columns else [])
        row += [r["status"], _num(r.get("seconds"))] + [_num(r.get(c)) for c in shown]
        reason = r.get("reason") or ""
        table.append(row + [reason if len(reason) <= MAX_REASON else reason[: MAX_REASON - 1] + "…"])
    title = f"Batch {command}: {Path(path).name}"
    for sheet in table_sheets(title, cols, table, intro=abstract(path)):
        save_page(pdf, sheet.fig)


def _rmse_pairs(columns) -> list[tuple[str, str, str]]:
    """(unit, baseline column, extended column) of a diagnose table's pooled held-out RMSE columns."""
    out = []
    for c in columns:
        if c.startswith("held-out RMSE baseline ["):
            unit = c[len("held-out RMSE baseline [") : -1]
            ext = f"held-out RMSE extended [{unit}]"
            if ext in columns:
                out.append((unit, c, ext))
    return out


def _name_unit(column: str) -> tuple[str, str]:
    if column.endswith("]") and " [" in column:
        name, unit = column[:-1].rsplit(" [", 1)
        return name, unit
    return column, ""


def _numeric(rows, column: str) -> bool:
    values = [r.get(column) for r in rows if r.get(column) not in (None, "")]
    try:
        [float(v) for v in values]
    except ValueError:
        return False
    return True


def _num(text) -> str:
    if text in (None, ""):
        return "–"
    try:
        return f"{float(text):.4g}"
    except ValueError:
        return str(text)


def headline(path: Path, context=None) -> str:
    fields, _, rows = _read(path)
    count = {s: sum(r["status"] == s for r in rows) for s in ("done", "up to date", "failed", NOT_APPLICABLE)}
    runs = len(rows) - count[NOT_APPLICABLE]
    said = ", ".join(f"{n} {s}" for s, n in count.items() if n or s != NOT_APPLICABLE)
    return f"{fields.get('command', '?')} over {runs} run(s): {said}"


register_section(
    Section(
        "batch",
        recognise,
        pages,
        lambda p: {"table": str(p)},
        heading="Batch results",
        abstract=abstract,
        headline=headline,
    )
)
