"""What does the rigid body + friction model get wrong on real robots? `diagnose` on TX40 and TIAGo.

    .venv/bin/python bench/bench_diagnose_real.py [--data DIR] [--tx40-blocks N] [--tiago-blocks N]
        [--inertia identified|nominal]

The real-robot logs of ``sample_data/real`` (README there; imported by ``diegocal import``; the
same logs as ``bench_real_identification.py``) are diagnosed in the dynamics domain with the
library's defaults, as ``diegocal diagnose sample_data/real/tx40.h5`` does (``--*-blocks`` only to
compare another number of blocks; ``--inertia nominal`` as ``diagnose --inertia nominal``: the URDF's
inertias kept, friction and the found terms fitted, on the splits too). Printed per robot:

1. the diagnosis (interleaved train / validation / held-out blocks): the baseline's held-out RMSE
   per joint, each finding with its fitted values (± standard error) and its held-out RMSE before
   → after on the joints it acts on (an ``unexplained`` one: whether the SGP's GP absorbed it,
   kept on the validation blocks, and its held-out gain), the extended model's held-out RMSE;
2. the extended model judged on the time splits of ``bench_real_identification.py`` (TX40: first /
   second half and the reverse; TIAGo: 9.2-48 s / 48-67.9 s as FIGAROH): PR (base parameters +
   viscous + Coulomb, ``SGPOptions(kind="pr")``) without and with the terms the diagnosis named
   (the terms' structure only; their values are refitted on the training half; an SGP as the
   diagnosis fits it, ``diagnose.dynamics.EXTENDED_SGP``, where its GP was kept), next to the
   nominal model (URDF inertias, no friction) and, for the TX40, the nominal model + the README's
   published priors (friction, rotor inertia, offsets, wrist-coupling motor terms).

The diagnosis never reads anything but the log; the splits never see their held-out half. One
BLAS thread (the machine is shared).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))  # this checkout's diegocal, not whichever one is installed

try:  # two cores shared by many processes: one BLAS thread is much faster than contention
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
except ImportError:  # pragma: no cover
    pass

from bench_real import tx40_model  # noqa: E402
from bench_real_identification import FIGAROH, arrays, nominal, tiago_log, tiago_split, tx40_splits  # noqa: E402

from diegocal.diagnose import DiagnoseOptions, diagnose  # noqa: E402
from diegocal.diagnose.dynamics import EXTENDED_SGP  # noqa: E402
from diegocal.io import load_log  # noqa: E402
from diegocal.robot import BUNDLED_ROBOTS, load_robot  # noqa: E402
from diegocal.sgp import SGPOptions  # noqa: E402
from diegocal.sgp.model import DynamicsModel  # noqa: E402

REPO = HERE.parent
DEFAULT_DATA = REPO / "sample_data" / "real"


def _fmt(x: float) -> str:
    return f"{x:.3g}" if np.isfinite(x) else "nan"


def show_diagnosis(name: str, d, nm_joints) -> None:
    u = d.units[0]
    base, ext = u.baseline_score, u.extended_score
    print(
        f"\n== {name}: diagnose (blocks: {d.blocks.n_blocks}, held-out {int(d.blocks.mask('heldout').sum())} samples)"
    )
    print(f"baseline: {u.baseline_model}")
    print("held-out RMSE per joint (N·m; torso N):")
    print("  " + "  ".join(f"{c}={_fmt(r)}" for c, r in zip(base.channels, base.rmse, strict=True)))
    if not d.findings:
        print("findings: none")
    for f in d.findings:
        where = (
            ""
            if f.term.region is None
            else f" [{f.term.region.variable} {f.term.region.low:.3g}..{f.term.region.high:.3g}]"
        )
        extra = "" if not f.term.extra else " " + ", ".join(f"{k}={v}" for k, v in f.term.extra.items())
        values = ", ".join(
            f"{p.name}={p.value:.4g}" + ("" if not np.isfinite(p.stderr) else f"±{p.stderr:.2g}") + f" {p.unit}"
            for p in f.term.parameters
        )
        line = f"- {f.kind} {f.cause} on {f.channel}{where}{extra}: {values}"
        np_note = f.evidence.get("nonparametric")
        if np_note:
            line += (
                f" | GP {'kept' if np_note['kept'] else 'dropped'} on validation "
                f"({np_note['validation_rmse_before']:.3g} → {np_note['validation_rmse_after']:.3g})"
            )
        if f.heldout_before is not None and f.heldout_after is not None:
            chans = [c for c in f.evidence.get("channels", []) if c in base.channels]
            per = []
            for c in chans:
                i = f.heldout_before.channels.index(c)
                per.append(f"{c} {f.heldout_before.rmse[i]:.3g} → {f.heldout_after.rmse[i]:.3g}")
            line += " | held-out " + "; ".join(per)
        line += (
            f" | validation gain {f.evidence.get('validation_gain', float('nan')):.0%}, t {f.evidence.get('t', 0):.1f}"
        )
        print(line)
    print(f"extended: {u.extended_model}")
    print("  " + "  ".join(f"{c}={_fmt(r)}" for c, r in zip(ext.channels, ext.rmse, strict=True)))
    idx = [base.channels.index(j) for j in nm_joints]
    pooled = [float(np.sqrt(np.mean(s.rmse[idx] ** 2))) for s in (base, ext)]
    print(f"pooled held-out RMSE over {len(idx)} N·m joints: {pooled[0]:.3f} → {pooled[1]:.3f} N·m")


def friction_check(d, alpha: float = 0.01) -> None:
    """Does friction differ by direction, or near zero velocity? After the diagnosed model (as
    fitted on the training blocks), per joint: the residual's mean while the joint turns one
    way, the other, or rests (|qd| under 5 % of its std), on the validation and held-out blocks,
    ± block standard errors (sub-blocks of five correlation times); then three candidate
    columns tested out of sample exactly as ``diagnose`` tests its terms (fitted on the training
    blocks with the model's columns projected out, t on the validation blocks, Bonferroni over
    the joints × columns of this check):

    - direction Coulomb, |sign(qd)|: with the model's sign(qd) column, Coulomb levels c+ ≠ c−
      (c+·[qd>0] − c−·[qd<0] = (c+ + c−)/2 · sign(qd) + (c+ − c−)/2 · |sign(qd)|);
    - direction viscous, |qd|: viscous coefficients that differ by direction;
    - low-velocity, sign(qd)·exp(−|qd|/v): friction near zero velocity other than the Coulomb
      level (Stribeck: above it; negative: a smooth change of sign), v = 0.02-0.5 × std(qd), the
      best on the training blocks."""
    from diegocal.diagnose.dynamics_system import filler, layout, project
    from diegocal.diagnose.engine import Candidate, EngineOptions
    from diegocal.diagnose.selection import evaluate_candidates
    from diegocal.diagnose.stats import cluster_length
    from diegocal.evaluate import sub_blocks
    from diegocal.sgp.terms import Proposal
    from diegocal.terms import Parameter, Term

    ad, fitted = d.adapters[0], d.units[0].fitted
    blocks = d.blocks
    train, val, held = (blocks.mask(r) for r in ("train", "validation", "heldout"))
    fitted = ad.fit(fitted.terms, train)  # the terms' model (not an SGP) on the training blocks
    res = ad.residuals(fitted)
    weights = {}
    for c, r in res.channels.items():
        rms = float(np.sqrt(np.nanmean(r[train] ** 2)))
        weights[c] = 1.0 / rms if rms > 0 else 1.0
    shown = val | held
    clusters = sub_blocks(shown, cluster_length([r[train] for r in res.channels.values()]))
    props = []
    for j in ad.joints:
        v = ad.qd[:, ad.robot.joint_index(j)]
        s = float(np.std(v[train]))
        columns = {"direction Coulomb": [np.abs(np.sign(v))], "direction viscous": [np.abs(v)]}
        columns["low-velocity"] = [np.sign(v) * np.exp(-np.abs(v) / (f * s)) for f in (0.02, 0.05, 0.1, 0.2, 0.5)]
        for label, cols in columns.items():
            for col in cols:
                term = Term(label, j, (Parameter("c", 0.0, "N·m"),))
                props.append(Proposal(term, f"{label}:{j}", {j: col[:, None]}))
    # each column minus its fit by the model's columns (Frisch-Waugh-Lovell, as the diagnosis does)
    width, slots = layout(ad, props)
    B, _, slots = project(ad, fitted, train, width, slots, filler(ad, props, width, slots))
    cands = [
        Candidate(p.term, {ad.joints[r]: B[r][:, sl].astype(float) for r, sl in slot.items()}, family=p.family)
        for p, slot in zip(props, slots, strict=True)
    ]
    tested = {
        (t.term.cause, t.term.channel): t
        for t in evaluate_candidates(cands, res, weights, train, val, EngineOptions(alpha=alpha))
    }
    print(f"\nfriction by direction after the extended model ({ad.describe(fitted)}):")
    print("joint              residual mean N·m (± block SE; val + held-out)      validation gain, t (threshold)")
    for j in ad.joints:
        r, v = res.channels[j], ad.qd[:, ad.robot.joint_index(j)]
        eps = 0.05 * float(np.std(v[train]))
        parts = []
        for name, sel in (("qd>0", v > eps), ("qd<0", v < -eps), ("rest", np.abs(v) <= eps)):
            m = shown & sel & np.isfinite(r)
            if m.sum() < 10:
                parts.append(f"{name} n={int(m.sum())}")
                continue
            x = r[m]
            _, cl = np.unique(clusters[m], return_inverse=True)
            sums = np.bincount(cl, weights=x - x.mean())
            se = float(np.sqrt(sums @ sums)) / m.sum() if sums.size > 1 else float("nan")
            parts.append(f"{name} {x.mean():+.2f}±{se:.2f}")
        tests = []
        for label in ("direction Coulomb", "direction viscous", "low-velocity"):
            t = tested.get((label, j))
            if t is not None:
                mark = "*" if t.significant else ""
                tests.append(f"{label} {t.gain:+.0%}, {t.test.t:.1f}{mark}")
        thr = next((t.threshold for t in tested.values()), float("nan"))
        print(f"{j:18s} {'  '.join(parts):50s} {'; '.join(tests)} ({thr:.1f})")


def pr(split, terms, sgp: bool = False, inertia: str = "identified"):
    options = SGPOptions(kind="sgp", inertia=inertia, **EXTENDED_SGP) if sgp else SGPOptions(kind="pr", inertia=inertia)
    model = DynamicsModel(split.robot, options, split.tau_joints, terms)
    q, qd, qdd, tau = arrays(split, split.train)
    model.fit_arrays(q, qd, qdd, tau, time=split.train.time)
    q, qd, qdd, _ = arrays(split, split.test)
    return model.predict_arrays(q, qd, qdd, split.test.time).tau


def judge_splits(splits, terms, tx40: bool, sgp: bool = False, inertia: str = "identified") -> None:
    print("\nsplit            model                        RMSE N·m   nMSE per joint")
    for split in splits:
        q, qd, qdd, tau = arrays(split, split.test)
        cols = [split.tau_joints.index(j) for j in split.rmse_joints]
        rows = [split.robot.joint_index(j) for j in split.tau_joints]
        rb = nominal(split.robot, q, qd, qdd)
        cases = [("nominal (URDF, no friction)", rb[:, rows])]
        if tx40:
            cases.append(("nominal + published priors", tx40_model(rb, qd, qdd)[:, rows]))
        cases.append(("PR", pr(split, ())))
        label = "PR" if inertia == "identified" else "PR (URDF inertias)"
        if inertia != "identified":
            cases.append((label, pr(split, (), inertia=inertia)))
        if terms:
            named = ", ".join(f"{t.cause}:{t.channel}" for t in terms)
            cases.append((f"{label} + {named}", pr(split, terms, inertia=inertia)))
        if sgp:
            cases.append(("SGP + the terms (the extended model)", pr(split, terms, sgp=True, inertia=inertia)))
        for label, pred in cases:
            err = pred - tau
            rmse = float(np.sqrt(np.mean(err[:, cols] ** 2)))
            nmse = np.mean(err**2, axis=0) / np.var(tau, axis=0)
            print(f"{split.name:16s} {label[:44]:44s} {rmse:6.2f}   " + " ".join(f"{v:.2f}" for v in nmse))
        ref = FIGAROH.get(split.name)
        if ref:
            print(f"{split.name:16s} {'FIGAROH 1.0.2 (identified, nominal)':44s} {ref[0]:.2f}, {ref[1]:.2f}")


def options(n_blocks: int | None, inertia: str = "identified") -> DiagnoseOptions:
    """The library's defaults (a number of blocks only when one is given)."""
    blocks = {} if n_blocks is None else {"n_blocks": n_blocks}
    return DiagnoseOptions("dynamics", inertia=inertia, **blocks)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--tx40-blocks", type=int, default=None, help="Default: the library's.")
    ap.add_argument("--tiago-blocks", type=int, default=None, help="Default: the library's.")
    ap.add_argument("--inertia", choices=("identified", "nominal"), default="identified", help="As diagnose's.")
    args = ap.parse_args(argv)
    if not (args.data / "tx40.h5").exists():
        print(f"no real-robot data at {args.data}; skipped")
        return 0
    t0 = time.time()
    # TX40
    robot = load_robot(BUNDLED_ROBOTS / "tx40")
    log = load_log(args.data / "tx40.h5")
    t = time.time()
    d = diagnose(log, robot, options(args.tx40_blocks, args.inertia))
    print(f"TX40: {log.n_samples} samples, {log.time[-1] - log.time[0]:.1f} s; diagnose {time.time() - t:.1f} s wall")
    show_diagnosis("TX40", d, robot.joint_names)
    friction_check(d)
    fitted = d.units[0].fitted
    judge_splits(tx40_splits(args.data, 1), fitted.terms, True, fitted.gp is not None, args.inertia)
    # TIAGo
    robot = load_robot(BUNDLED_ROBOTS / "tiago")
    log = tiago_log(args.data)
    t = time.time()
    d = diagnose(log, robot, options(args.tiago_blocks, args.inertia))
    print(
        f"\nTIAGo: {log.n_samples} samples, {log.time[-1] - log.time[0]:.1f} s; diagnose {time.time() - t:.1f} s wall"
    )
    split = tiago_split(args.data, 1)
    show_diagnosis("TIAGo", d, split.rmse_joints)
    friction_check(d)
    fitted = d.units[0].fitted
    judge_splits([split], fitted.terms, False, fitted.gp is not None, args.inertia)
    print(f"\ntotal {time.time() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
