"""The merged table of a batch: one row per job, the numbers that compare sessions side by side.

Each row holds the log, its status (done, up to date, failed), the seconds the run took, the output,
the failure's reason and the job's warnings, then the numbers read back from the output (one reader
per command; also for a job failed by what its output says, such as a calibration that did not
converge):

    stac           iterations, converged, sigma pots [V], sigma markers [m], gain/bias of every pot
    sgp-fit        samples, in-sample nMSE of every joint, log marginal likelihood
    pneumatic-fit  chambers fitted, 2-s drift median / max [% of Pc - Pr], per chamber drift
    diagnose       domain, held-out RMSE of the baseline and the extended model, the findings
    predict        error of the prediction against the log's own measurement, per stream

The CSV starts with a ``# diegocal-batch command=... source=...`` line so that the report knows
it and no batch mistakes it for a log. :data:`HEADLINE` names the columns the report shows.
"""

from __future__ import annotations

import csv
import io
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from diegocal.batch.jobs import TABLE_HEADER, Outcome, Plan
from diegocal.errors import DiegocalError

#: Columns every row has, before the command's numbers.
BASE_COLUMNS = ("log", "domain", "status", "seconds", "output", "reason", "warnings")
#: The columns a one-page view (the report) shows per command, besides log, status and reason
#: (a trailing * matches every column that starts so).
HEADLINE = {
    "stac": ("iterations", "converged", "sigma pots [V]", "sigma markers [m]"),
    "sgp-fit": ("samples", "nMSE worst joint", "nMSE mean"),
    "pneumatic-fit": ("chambers", "drift 2 s median [%]", "drift 2 s max [%]", "chambers < 4 %"),
    "diagnose": ("held-out RMSE *", "findings"),
    "predict": (),
}


def headline(command: str, columns) -> list[str]:
    """The table's headline columns for ``command`` (see :data:`HEADLINE`), in the table's order."""
    pats = HEADLINE.get(command, ())
    exact = [c for p in pats for c in columns if c == p]
    return [c for c in columns if c in exact or any(p.endswith("*") and c.startswith(p[:-1]) for p in pats)]


def metrics(command: str, output: Path) -> dict:
    """The numbers of one output (an empty dict when it cannot be read)."""
    reader = READERS.get(command)
    if reader is None or not Path(output).exists():
        return {}
    try:
        return reader(Path(output))
    except (DiegocalError, OSError, KeyError, TypeError, ValueError):
        return {}


def _stac(path: Path) -> dict:
    from diegocal.io import load_yaml

    d = load_yaml(path)
    fit, sigma = d.get("fit") or {}, d.get("sigma") or {}
    row = {
        "method": d.get("method"),
        "iterations": fit.get("iterations"),
        "converged": fit.get("converged"),
        "sigma pots [V]": sigma.get("pots"),
        "sigma markers [m]": sigma.get("markers"),
    }
    from diegocal.stac.calibration import Calibration

    cal = Calibration.from_dict(d, str(path))  # layout 2 or 1
    for i, name in enumerate(cal.pot_names):
        row[f"gain {name}"] = float(cal.gain[i])
        row[f"bias {name} [V]"] = float(cal.bias[i])
    return row


def _sgp(path: Path) -> dict:
    from diegocal.io import load_yaml

    d = load_yaml(path / "sgp.yaml")
    nmse = {j: float(v) for j, v in (d.get("nmse_in_sample") or {}).items()}
    row = {
        "model": d.get("model_kind") or d.get("kind"),
        "samples": d.get("n_samples"),
        "nMSE worst joint": max(nmse.values()) if nmse else None,
        "nMSE mean": float(np.mean(list(nmse.values()))) if nmse else None,
        "log marginal likelihood": d.get("log_likelihood"),
    }
    row.update({f"nMSE {j}": v for j, v in nmse.items()})
    return row


def _pneumatic(path: Path) -> dict:
    from diegocal.io import load_yaml
    from diegocal.pneumatic.predict import drift_summary

    d = load_yaml(path)
    drifts = {n: c.get("drift_2s") for n, c in (d.get("chambers") or {}).items() if c.get("drift_2s") is not None}
    drift = drift_summary(drifts.values())
    row = {
        "chambers": len(d.get("chambers") or {}),
        "skipped": len((d.get("meta") or {}).get("skipped") or {}),
        "drift 2 s median [%]": 100 * drift["median"] if drifts else None,
        "drift 2 s max [%]": 100 * drift["max"] if drifts else None,
        "chambers < 4 %": drift["below 4 %"],
        "chambers < 10 %": drift["below 10 %"],
    }
    row.update({f"drift 2 s {n} [%]": 100 * float(x) for n, x in drifts.items()})
    return row


def _diagnose(path: Path) -> dict:
    from diegocal.diagnose.output import pooled_heldout_rmse
    from diegocal.io import load_yaml

    d = load_yaml(path)
    row = {}
    for unit, pair in pooled_heldout_rmse(d).items():  # pooled per unit, never across
        for name, value in zip(("baseline", "extended"), pair, strict=True):
            row[f"held-out RMSE {name} [{unit}]"] = None if np.isnan(value) else value
    findings = d.get("findings") or []
    row["findings"] = "; ".join(f"{f['cause']} on {f['channel']}" for f in findings) or "none"
    row["baseline model"] = (d.get("baseline") or {}).get("model")
    return row


def _predict(path: Path) -> dict:
    """Error of a prediction log against the log it predicts (named in none of its files: the
    job's log); filled in by :func:`rows` which knows both."""
    return {}


READERS = {"stac": _stac, "sgp-fit": _sgp, "pneumatic-fit": _pneumatic, "diagnose": _diagnose, "predict": _predict}


def prediction_errors(prediction: Path, log: Path) -> dict:
    """RMSE of every predicted stream the log also measured (markers: mean distance, m)."""
    from diegocal.io import load_log

    pred, meas = load_log(prediction), load_log(log)
    row = {}
    for name, stream in pred.streams.items():
        if name == "q" or not meas.has(name) or pred.n_samples != meas.n_samples:
            continue
        common = [n for n in stream.names if n in meas.streams[name].names]
        if not common:
            continue
        p, m = stream.select(common).data, meas.streams[name].select(common).data
        if name == "markers":
            row["markers mean distance [m]"] = float(np.nanmean(np.linalg.norm(p - m, axis=-1)))
        else:
            row[f"{name} RMSE"] = float(np.sqrt(np.nanmean((p - m) ** 2)))
    return row


def rows(outcomes: list[Outcome]) -> list[dict]:
    """One row per job (see the module docstring)."""
    out = []
    for o in outcomes:
        job = o.job
        row = {
            "log": str(job.log),
            "domain": job.domain or "",
            "status": o.status,
            "seconds": round(o.seconds, 2) if o.status == "done" else "",
            "output": str(job.output),
            "reason": o.message,
            "warnings": "; ".join(o.warnings),
        }
        if not o.failed or o.judged:
            row.update(metrics(job.command, job.output))
            if job.command == "predict":
                try:
                    row.update(prediction_errors(job.output, job.log))
                except (DiegocalError, OSError):
                    pass
        out.append(row)
    return out


def table_text(plan: Plan, outcomes: list[Outcome]) -> str:
    """The merged table as CSV text, with its ``# diegocal-batch`` header line."""
    data = rows(outcomes)
    columns = list(BASE_COLUMNS)
    for r in data:
        columns += [k for k in r if k not in columns]
    if plan.command != "diagnose":
        columns.remove("domain")
    buf = io.StringIO()
    created = datetime.now(UTC).isoformat(timespec="seconds")
    buf.write(f"{TABLE_HEADER} command={plan.command} source={plan.source} created={created}\n")
    writer = csv.DictWriter(buf, columns, extrasaction="ignore", lineterminator="\n")
    writer.writeheader()
    for r in data:
        writer.writerow({k: _cell(v) for k, v in r.items()})
    return buf.getvalue()


def _cell(v):
    if v is None:
        return ""
    if isinstance(v, float):
        return "" if not np.isfinite(v) else f"{v:.6g}"
    return v


def save_table(plan: Plan, outcomes: list[Outcome], path: Path) -> None:
    """Write the merged table (atomically)."""
    from diegocal.io import write_text

    write_text(path, table_text(plan, outcomes))


def read_table(path: Path) -> tuple[dict, list[str], list[dict]]:
    """(header fields, columns, rows) of a merged table; raises DiegocalError if it is none."""
    text = Path(path).read_text()
    first, _, body = text.partition("\n")
    if not first.startswith(TABLE_HEADER):
        raise DiegocalError(f"{path}: not a diegocal batch table (no '{TABLE_HEADER}' line)")
    fields = dict(f.split("=", 1) for f in first[len(TABLE_HEADER) :].split() if "=" in f)
    reader = csv.DictReader(io.StringIO(body))
    return fields, list(reader.fieldnames or []), list(reader)


def is_table(path: Path) -> bool:
    """Whether ``path`` is a merged batch table (its first line)."""
    try:
        with open(path, errors="replace") as fh:
            return fh.readline().startswith(TABLE_HEADER)
    except OSError:
        return False
