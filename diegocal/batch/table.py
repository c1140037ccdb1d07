"""The merged table of a batch: one row per job, the numbers that compare sessions side by side.

Each row holds the log, its status (done, up to date, failed, not applicable), the seconds the run
took, the output (empty when the job wrote none: a failed run, a log not applicable), the failure's
or the log's reason and the job's warnings, then the numbers read back from the output (one reader
per command; also for a job failed by what its output says, such as a calibration that did not
converge):

    stac           iterations, converged, the noise σ of each sensor type in its unit (sigma rotary [V],
                   sigma encoder [rad], sigma markers [m]), every estimated gain and every bias with units
                   (an encoder's gain, 1 by design, is left out)
    sgp-fit        samples, in-sample nMSE of every joint, log marginal likelihood
    pneumatic-fit  chambers fitted, 2-s drift median / max [% of Pc - Pr], per chamber drift
    diagnose       domain, held-out RMSE of the baseline and the extended model, the findings
    predict        error of each predicted stream against the log's own measurement, with its unit
                   (markers mean distance [m], rotary RMSE [V], encoder RMSE [rad], tau RMSE [N·m],
                   pressure RMSE [kPa]); a stream the prediction was made from (pots for --from pots)
                   is no prediction and has no column

Logs the command cannot use (another program's file, a log without the streams it needs) are rows
too, with status "not applicable" and the reason, as the terminal lists them.

The CSV starts with a ``# diegocal-batch command=... source=...`` line so that the report knows
it and no batch mistakes it for a log. :data:`HEADLINE` names the columns the report shows.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from diegocal.batch.jobs import TABLE_HEADER, Outcome, Plan
from diegocal.domains import domain as domain_record
from diegocal.errors import DiegocalError

#: The status of a log the command cannot use (the plan's ``not_applicable``).
NOT_APPLICABLE = "not applicable"
#: Columns every row has, before the command's numbers.
BASE_COLUMNS = ("log", "domain", "status", "seconds", "output", "reason", "warnings")
#: The columns a one-page view (the report) shows per command, besides log, status and reason
#: (a trailing * matches every column that starts so).
HEADLINE = {
    "stac": ("iterations", "converged", "sigma *"),
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
    from diegocal.stac.calibration import READING_UNITS, Calibration

    fit, sigma = d.get("fit") or {}, d.get("sigma") or {}
    row = {"method": d.get("method"), "iterations": fit.get("iterations"), "converged": fit.get("converged")}
    by_group = sigma.get("by_group") or {}
    if by_group:  # one column per sensor type, in its unit: the pots' pooled σ mixes V and rad
        row.update({f"sigma {g} [{READING_UNITS.get(g, 'sensor unit')}]": v for g, v in by_group.items()})
    else:  # files without σ per type
        row.update({"sigma pots [V]": sigma.get("pots"), "sigma markers [m]": sigma.get("markers")})
    cal = Calibration.from_dict(d, str(path))  # layout 2 or 1
    roles = cal.pot_roles()
    for i, name in enumerate(cal.pot_names):
        gain_unit, bias_unit = cal.pot_units[i] if cal.pot_units else ("", "V")
        if roles[name][0] != "design":
            row[f"gain {name}" + (f" [{gain_unit}]" if gain_unit else "")] = float(cal.gain[i])
        row[f"bias {name} [{bias_unit}]"] = float(cal.bias[i])
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


#: The streams a model predicts, by domain (the rest of a prediction log, q, qd, qdd, tau_std and the
#: measured torques, is what the prediction was made from or reports beside it), and their units.
PREDICTED = {"kinematics": ("markers", "pots"), "dynamics": ("tau",), "pneumatics": ("pressure",)}
STREAM_UNITS = {"markers": "m", "tau": "N·m", "pressure": "kPa"}


@dataclass(frozen=True)
class Predicted:
    """What a prediction log predicts, so what its errors are: the model's domain and, for a
    calibration, the sensor types the joint angles were tracked from (``sources``) and those asked
    for (``targets``), with each pot's type ({pot: kind}; empty when the robot is not found)."""

    domain: str
    sources: tuple[str, ...] = ()
    targets: tuple[str, ...] = ()
    kinds: dict = field(default_factory=dict)

    def channels(self, stream: str, names) -> dict:
        """{type: channels} of ``stream`` that were predicted, each type a column of the table."""
        if stream not in PREDICTED.get(self.domain, ()):
            return {}
        if self.domain != "kinematics":
            return {stream: list(names)}
        others = "others" in self.sources  # each reading from every other sensor: all are predictions
        if stream == "markers":
            asked = "markers" in self.targets and ("markers" not in self.sources or others)
            return {"markers": list(names)} if asked else {}
        out = {}
        for n in names:
            kind = self.kinds.get(n, "pots")
            asked = "pots" in self.targets or kind in self.targets
            given = "pots" in self.sources or kind in self.sources
            if asked and (others or not given):
                out.setdefault(kind, []).append(n)
        return out


def predicted(job) -> Predicted | None:
    """What the predict job's output predicts (None when its model or options cannot be read)."""
    from diegocal.batch.jobs import job_args
    from diegocal.cli.common import split_words
    from diegocal.io.bundle import load_bundle
    from diegocal.robot.resolve import pot_kinds

    try:
        args = job_args(job)
        bundle = load_bundle(args.model)
        domain = bundle.data.get("domain") if bundle.kind == "diagnosis" else bundle.kind
        domain = domain_record(domain).name
    except (DiegocalError, OSError, KeyError, TypeError, ValueError):
        return None
    if domain != "kinematics":
        return Predicted(domain)
    record = bundle.robot or {}  # the robot the calibration was fitted on, unless predict's --robot
    kinds = pot_kinds(args.robot or record.get("dir") or record.get("name"))
    return Predicted(domain, split_words(args.sensors_from), split_words(args.sensors_to), kinds)


def prediction_errors(prediction: Path, log: Path, what: Predicted | None = None) -> dict:
    """The error of every predicted stream the log also measured, one column per sensor type with
    its unit: markers the mean distance (m), the others the RMSE (pots of each type in their unit,
    :data:`diegocal.stac.calibration.READING_UNITS`). ``what``: what the prediction predicts
    (:func:`predicted`); None scores every stream a model of the log's domain predicts."""
    from diegocal.io import load_log
    from diegocal.stac.calibration import READING_UNITS

    pred, meas = load_log(prediction), load_log(log)
    row = {}
    if pred.n_samples != meas.n_samples:
        return row
    for name, stream in pred.streams.items():
        if not meas.has(name):
            continue
        known = [n for n in stream.names if n in meas.streams[name].names]
        chosen = what.channels(name, known) if what is not None else _every(name, known)
        for kind, common in chosen.items():
            p, m = stream.select(common).data, meas.streams[name].select(common).data
            if name == "markers":
                row["markers mean distance [m]"] = float(np.nanmean(np.linalg.norm(p - m, axis=-1)))
            else:
                unit = STREAM_UNITS.get(name) or READING_UNITS.get(kind, "sensor unit")
                row[f"{kind} RMSE [{unit}]"] = float(np.sqrt(np.nanmean((p - m) ** 2)))
    return row


def _every(name: str, names) -> dict:
    """What is a prediction when the job's options cannot be read: torques and pressures only (markers
    and pots may be what a calibration's prediction was made from)."""
    return {name: list(names)} if names and name in ("tau", "pressure") else {}


def rows(outcomes: list[Outcome], not_applicable: dict | None = None) -> list[dict]:
    """One row per job, then one per log the command cannot use (see the module docstring)."""
    out = []
    for o in outcomes:
        job = o.job
        wrote = not o.failed or o.judged  # a failed run wrote nothing of its own (what is there is older)
        row = {
            "log": str(job.log),
            "domain": job.domain or "",
            "status": o.status,
            "seconds": round(o.seconds, 2) if o.status == "done" else "",
            "output": str(job.output) if wrote else "",
            "reason": o.message,
            "warnings": "; ".join(o.warnings),
        }
        if wrote:
            row.update(metrics(job.command, job.output))
            if job.command == "predict":
                try:
                    row.update(prediction_errors(job.output, job.log, predicted(job)))
                except (DiegocalError, OSError):
                    pass
        out.append(row)
    for path, reason in (not_applicable or {}).items():
        out.append({"log": str(path), "status": NOT_APPLICABLE, "output": "", "reason": reason})
    return out


def table_text(plan: Plan, outcomes: list[Outcome]) -> str:
    """The merged table as CSV text, with its ``# diegocal-batch`` header line."""
    data = rows(outcomes, plan.not_applicable)
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
