"""Static-pose kinematic calibration, diegocal against FIGAROH's models, on the same contiguous
pose folds (issue #34).

Sessions from ``experiments/static_geometry_generator.py`` (the Panda arm, 7 joints; Talos's torso
and left arm, 9 joints; one gripper point measured in 3-D; every joint's placement off by ~2 mm
and ~0.3°, encoder zeros off, 0.3 mm marker noise). Each session's poses are cut into ten
contiguous folds; every method is fitted on nine and predicts the tenth's point from its
encoders. Rows:

- ``nominal + frame/tool``: the URDF as it is, only the mocap frame and the tool point fitted;
- ``diegocal stac``: STAC (encoders, marker, frame), then ``predict --from pots``;
- ``diegocal offsets``: the geometry fit with the joints' zeros, frame and tool only;
- ``diegocal stac --geometry``: the full fit (:mod:`diegocal.stac.geometry`);
- ``FIGAROH joint_offset`` / ``FIGAROH full_params``: FIGAROH's two models. FIGAROH (pip
  ``figaroh`` 1.0.2, in its own environment: ``FIGAROH_PYTHON``, default /tmp/figaroh-venv, never
  diegocal's) runs each fold through ``bench/figaroh_driver.py`` (its ``BaseCalibration`` with its
  defaults, base frame and tool points unknown); when it cannot be imported the rows say
  ``re-impl.``: a re-implementation of its models written here (joint offsets added to q, the
  base frame as xyz + roll-pitch-yaw, the tool point; ``full_params`` composes each joint's
  placement with ``SE3(RPY(φ), p)``, reduced to the columns of a QR of the numerical Jacobian
  with |R_ii| > 1e-6·max, then unweighted Levenberg-Marquardt from the nominal model, the frame
  started by a Kabsch fit of the nominal points, as a FIGAROH user supplies a starting frame).

The floor is the error of the true model at the encoders' angles (noise alone). Run:
``python bench/bench_static_calibration.py [--poses 61] [--sessions 2] [--folds 10]``; with
``--coverage K``, the standard errors' calibration over K hardware draws; with
``--design [--draws 12] [--methods ...] [--no-fit]``, the pose-selection tables instead: the
held-out error of a fit on N poses chosen by ``diegocal poses`` (I-optimal with exchanges, its
default; D-optimal greedy, FIGAROH's criterion) against N random ones of the same candidates, and
the prediction variance the design predicts, over paired draws (:func:`design_table`).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pinocchio as pin
from scipy.optimize import least_squares

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from diegocal.errors import FitError  # noqa: E402
from diegocal.robot import load_robot  # noqa: E402
from diegocal.stac.geometry import fit_geometry  # noqa: E402
from diegocal.stac.geometry_cv import fold_of  # noqa: E402
from diegocal.stac.predict import predict  # noqa: E402
from diegocal.stac.stac import calibrate  # noqa: E402
from diegocal.stac.static import take  # noqa: E402
from experiments import static_geometry_generator as gen  # noqa: E402


# ----------------------------------------------------------------------------- FIGAROH's models, re-implemented
class FigarohModel:
    """FIGAROH's offset-only (``full=False``) or ``full_params`` model of a serial chain seen
    through one or more tool points (module docstring)."""

    def __init__(self, robot, full: bool):
        self.robot, self.full = robot, full
        self.model = robot.model
        self.joints = [p.joint for p in robot.sensors.pots]
        self.qi = [robot.joint_index(j) for j in self.joints]
        self.fid = robot.frame_id(robot.sensors.markers[0].link)
        self.n, self.M = len(self.joints), len(robot.sensors.markers)

    def size(self) -> int:
        return 6 + 3 * self.M + self.n + (6 * self.n if self.full else 0)

    def points(self, theta, enc) -> np.ndarray:
        """Tool points (K, M, 3) in the mocap frame at encoder readings enc (K, n)."""
        n, M = self.n, self.M
        R = pin.rpy.rpyToMatrix(*theta[3:6])
        tool = theta[6 : 6 + 3 * M].reshape(M, 3)
        off = theta[6 + 3 * M : 6 + 3 * M + n]
        model = self.model
        if self.full:
            model = pin.Model(model)
            for j, g in zip(self.joints, theta[6 + 3 * M + n :].reshape(n, 6), strict=True):
                jid = model.getJointId(j)
                model.jointPlacements[jid] = model.jointPlacements[jid] * pin.SE3(pin.rpy.rpyToMatrix(*g[3:]), g[:3])
        data = model.createData()
        out = np.empty((enc.shape[0], M, 3))
        q = self.robot.neutral()
        for k, e in enumerate(enc):
            q[self.qi] = e + off
            pin.framesForwardKinematics(model, data, q)
            f = data.oMf[self.fid]
            out[k] = (tool @ f.rotation.T + f.translation) @ R.T + theta[:3]
        return out

    def fit(self, enc, x) -> np.ndarray:
        """θ by QR-reduced unweighted Levenberg-Marquardt (module docstring)."""
        theta = np.zeros(self.size())
        theta[6 : 6 + 3 * self.M] = np.array([m.xyz for m in self.robot.sensors.markers]).reshape(-1)
        nominal = self.points(theta, enc)
        seen = np.isfinite(x).all(-1)
        R, t = _kabsch(nominal[seen], x[seen])
        theta[:3], theta[3:6] = t, pin.rpy.matrixToRpy(R)

        def res(free, idx):
            th = theta.copy()
            th[idx] = free
            r = self.points(th, enc) - x
            return r[seen].reshape(-1)

        everything = np.arange(self.size())
        J = least_squares(res, theta, args=(everything,), max_nfev=1, method="lm").jac
        _, r, piv = _qr(J)
        d = np.abs(np.diag(r))
        idx = np.sort(piv[d > 1e-6 * d.max()])
        sol = least_squares(res, theta[idx], args=(idx,), method="lm", x_scale="jac")
        theta[idx] = sol.x
        return theta


def _qr(J):
    from scipy.linalg import qr

    return qr(J / np.maximum(np.linalg.norm(J, axis=0), 1e-300), mode="economic", pivoting=True)


def _kabsch(a, b):
    """R, t with b ≈ R a + t (points (N, 3))."""
    ca, cb = a.mean(0), b.mean(0)
    U, _, Vt = np.linalg.svd((a - ca).T @ (b - cb))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return R, cb - R @ ca


# ----------------------------------------------------------------------------- the methods
# each: run(train, test, robot, name) -> (predicted test markers (N, M, 3) m, seconds of the fit or None)
def _diegocal(groups):
    def run(train, test, robot, name):
        cal = calibrate(train, robot).calibration
        if groups == (0,):  # the encoders' zeros as sensors.yaml says
            cal = replace(cal, bias=np.array([p.bias for p in robot.sensors.pots], float))
        if groups is not None:
            cal = fit_geometry(train, robot, cal, groups=groups).calibration
        return predict(test, robot, cal, ("pots",), ("markers",)).markers, None

    return run


def _figaroh_reimpl(full: bool):
    def run(train, test, robot, name):
        model = FigarohModel(robot, full)
        theta = model.fit(train.stream("pots").data, train.stream("markers").data)
        return model.points(theta, test.stream("pots").data), None

    return run


def _figaroh(level: str, python: str):
    """FIGAROH itself, in its own environment (bench/figaroh_driver.py); seconds: its own fit."""

    def run(train, test, robot, name):
        urdf, joints, tool = gen.ROBOTS[name]
        with tempfile.TemporaryDirectory() as tmp:
            d = Path(tmp)
            job = {
                "urdf": str(gen.SHARE / urdf),
                "joints": list(joints),
                "tool_frame": tool,
                "level": level,
                "points": len(robot.sensors.markers),
            }
            (d / "job.json").write_text(json.dumps(job))
            for part, log in (("train", train), ("test", test)):
                _figaroh_csv(d / f"{part}.csv", log, joints)
            done = subprocess.run([python, str(DRIVER), str(d)], capture_output=True, text=True)
            if done.returncode != 0:
                raise RuntimeError(f"FIGAROH failed: {done.stderr.strip().splitlines()[-1]}")
            return np.load(d / "pred.npy"), float((d / "seconds.txt").read_text())

    return run


def _figaroh_csv(path: Path, log, joints) -> None:
    """FIGAROH's CSV layout: x1, y1, z1, ... per point, then one column per active joint (encoders)."""
    x = log.stream("markers").data
    head = [f"{a}{m + 1}" for m in range(x.shape[1]) for a in "xyz"] + list(joints)
    rows = np.hstack([x.reshape(len(x), -1), log.stream("pots").data])
    np.savetxt(path, rows, delimiter=",", header=",".join(head), comments="")


DRIVER = Path(__file__).with_name("figaroh_driver.py")


def figaroh_python() -> str | None:
    """FIGAROH's interpreter (``FIGAROH_PYTHON``, else /tmp/figaroh-venv) when it imports figaroh."""
    python = os.environ.get("FIGAROH_PYTHON", "/tmp/figaroh-venv/bin/python")
    if not Path(python).exists():
        return None
    ok = subprocess.run([python, "-c", "import figaroh.calibration.base_calibration"], capture_output=True)
    return python if ok.returncode == 0 else None


def methods(python: str | None) -> dict:
    out = {
        "nominal + frame/tool": _diegocal((0,)),
        "diegocal stac": _diegocal(None),
        "diegocal offsets (zeros, frame, tool)": _diegocal((0, 1)),
        "diegocal stac --geometry": _diegocal((0, 1, 2)),
    }
    if python:
        out["FIGAROH 1.0.2 joint_offset"] = _figaroh("joint_offset", python)
        out["FIGAROH 1.0.2 full_params"] = _figaroh("full_params", python)
    else:
        out["FIGAROH offsets (re-impl.)"] = _figaroh_reimpl(False)
        out["FIGAROH full_params (re-impl.)"] = _figaroh_reimpl(True)
    return out


def folds_errors(log, robot, name, run, folds: int) -> tuple[np.ndarray, float]:
    """Per-pose held-out error (K,) m over contiguous folds, and seconds per fit."""
    log = log.without_truth()
    K = log.n_samples  # snapshots: one sample per pose
    fold = fold_of(K, folds)
    x = log.stream("markers").data
    err = np.full(K, np.nan)
    seconds = 0.0
    for f in range(folds):
        held = np.flatnonzero(fold == f)
        t0 = time.perf_counter()
        pred, fit_s = run(take(log, np.flatnonzero(fold != f)), take(log, held), robot, name)
        seconds += time.perf_counter() - t0 if fit_s is None else fit_s
        err[held] = np.linalg.norm(pred - x[held], axis=-1).mean(axis=1)
    return err, seconds / folds


#: The pose-selection table's methods: name -> (criterion, exchange) of ``select_poses``; None: random.
DESIGNS = {
    "random": None,
    "D greedy": ("D", False),
    "D + exchange": ("D", True),
    "I greedy": ("I", False),
    "I + exchange": ("I", True),
}
#: Poses per robot of the pose-selection table (the smallest a little above what the fit needs).
DESIGN_SIZES = {"panda": (20, 25, 30, 40, 50), "talos": (25, 30, 35, 45, 55)}
#: Held-out error over the floor whose pose counts the pose-selection table reports.
DESIGN_TARGETS = (1.3, 1.2)
#: The methods the pose-selection table compares by default.
DESIGN_METHODS = ("random", "D greedy", "I + exchange")


def design_table(name: str, tmp: Path, draws: int, methods=DESIGN_METHODS, fit: bool = True) -> dict:
    """Held-out error over the floor of a geometry fit on N poses chosen from 300 candidates by each
    of ``methods`` (:data:`DESIGNS`), over ``draws`` draws of the hardware, the candidates, the
    noise and 100 held-out poses (the methods of one draw share all four: paired), and the
    linearised prediction variance of those held-out poses' markers that the design predicts (in
    σ_m²; ``fit=False``: that alone, no fit). Returns {"ratio" | "variance": {method: (draws, sizes)}}.
    Printed: mean ± sd per size, the mean paired difference with random, and the poses needed to
    reach each of :data:`DESIGN_TARGETS` (on the mean curve, linearly in 1/N; for the variance v,
    where √(1 + v) reaches it)."""
    from diegocal.stac.calibration import Calibration
    from diegocal.stac.geometry_design import pose_design, select_poses

    sizes = DESIGN_SIZES[name]
    out = {key: {m: np.full((draws, len(sizes)), np.nan) for m in methods} for key in ("ratio", "variance")}
    for k in range(draws):
        hw = 70 + k
        d, _ = gen.simulate(tmp / "design", gen.Session(name, 10, 1, seed=hw, hardware_seed=hw))
        robot = load_robot(d)
        cand = gen.candidate_poses(gen.Session(name), 300, seed=1000 + k)
        _, test = gen.simulate(tmp / "design", gen.Session(name, 100, 1, seed=2000 + k, hardware_seed=hw))
        design = pose_design(robot, Calibration.nominal(robot), cand)
        both = pose_design(robot, Calibration.nominal(robot), np.vstack([cand, test.truth.signals["q"].data]))
        rows = both.rows[len(cand) :].reshape(-1, both.rows.shape[-1])
        held = rows.T @ rows / len(rows)
        order = np.random.default_rng(k).permutation(len(cand))
        for m in methods:
            for i, n in enumerate(sizes):
                how = DESIGNS[m]
                idx = order[:n] if how is None else select_poses(design, n, criterion=how[0], exchange=how[1])
                out["variance"][m][k, i] = np.trace(np.linalg.solve(both.information(idx), held))
                if fit:
                    session = gen.Session(name, n, 1, seed=hw, hardware_seed=hw)
                    try:
                        out["ratio"][m][k, i] = _ratio(tmp, session, cand[idx], robot, test)
                    except FitError as exc:  # counted in the table (NaN), never dropped silently
                        print(f"  {name} draw {k + 1} {m} N={n}: the fit failed: {exc}", file=sys.stderr)
        print(f"  {name} draw {k + 1}/{draws} done", file=sys.stderr, flush=True)
    if fit:
        _design_rows(f"{name}: held-out mean / floor of a geometry fit on N poses", sizes, out["ratio"], draws, False)
    _design_rows(f"{name}: predicted mean variance of a held-out marker, σ_m²", sizes, out["variance"], draws, True)
    return out


def _design_rows(title: str, sizes, table: dict, draws: int, variance: bool) -> None:
    """One pose-selection table (:func:`design_table`)."""
    print(f"\n{title} (of 300 candidates), mean ± sd over {draws} draws")
    head = "".join(f"{'N@' + format(t, 'g'):>7}" for t in DESIGN_TARGETS)
    print(f"{'method':16}" + "".join(f"{n:>13d}" for n in sizes) + head)
    for m, r in table.items():
        cells = "".join(f"{a:7.3f}±{b:5.3f}" for a, b in zip(np.nanmean(r, 0), np.nanstd(r, 0), strict=True))
        curve = np.sqrt(1.0 + np.nanmean(r, 0)) if variance else np.nanmean(r, 0)
        failed = int(np.isnan(r).sum())
        print(
            f"{m:16}{cells}"
            + "".join(f"{_poses_to_reach(sizes, curve, t):>7}" for t in DESIGN_TARGETS)
            + (f"  ({failed} fits failed, left out)" if failed else "")
        )
    for ref, short in (("random", "rnd"), ("D greedy", "D")):
        for m, r in table.items():
            if m not in (ref, "random") and ref in table:
                diff = r - table[ref]
                se = np.nanstd(diff, 0) / np.sqrt(np.maximum(np.isfinite(diff).sum(0), 1))
                cells = "".join(f"{a:+7.3f}±{b:5.3f}" for a, b in zip(np.nanmean(diff, 0), se, strict=True))
                print(f"{m[:12] + ' - ' + short:16}{cells}   (paired, ± standard error)")


def _poses_to_reach(sizes, curve, target: float) -> str:
    """The pose count at which ``curve`` (per size) first falls to ``target``, linearly in 1/N
    ('>N' when it never does, '<=N' when it starts below)."""
    below = np.flatnonzero(np.asarray(curve) <= target)
    if not len(below):
        return f">{sizes[-1]}"
    i = below[0]
    if i == 0:
        return f"<={sizes[0]}"
    a, b = 1.0 / sizes[i - 1], 1.0 / sizes[i]
    w = (curve[i - 1] - target) / (curve[i - 1] - curve[i])
    return f"{1.0 / (a + w * (b - a)):.1f}"


def _ratio(tmp: Path, session, q, robot, test) -> float:
    """Held-out mean error over the floor of a geometry fit on the session recorded at poses q."""
    from diegocal.stac.geometry import calibrate_geometry

    _, log = gen.simulate(tmp / "design", session, q=q)
    # one sample per pose, as the generator writes them: static_poses' snapshot test can read a
    # chosen set whose joint repeats a few values in turn as one held pose (not a design's fault)
    cal = calibrate_geometry(log, robot, poses=np.arange(log.n_samples)).calibration
    x = test.stream("markers").data
    floor = np.linalg.norm(test.truth.signals["markers_floor"].data - x, axis=-1).mean()
    return float(np.linalg.norm(predict(test, robot, cal, ("pots",), ("markers",)).markers - x, axis=-1).mean() / floor)


def coverage_table(name: str, draws: int, tmp: Path) -> None:
    """z = (θ̂ − θ) / SE of the identifiable parameters (θ: θ_kept + alias θ_dropped of the truth)
    over ``draws`` hardware draws of 61 poses: the share within 2 and 3 SE, and the z's spread."""
    from diegocal.stac.geometry import calibrate_geometry

    zs = []
    for k in range(draws):
        d, log = gen.simulate(tmp / f"cov{k}", gen.Session(name, 61, 1, seed=80 + k, hardware_seed=80 + k))
        fit = calibrate_geometry(log, load_robot(d))
        ident = fit.identifiability
        truth = gen.truth_of(fit.names, pin.exp3(-fit.value[3:6]) @ fit.calibration.mocap_R, log.truth.params)
        target = truth[ident.kept] + ident.alias @ truth[~ident.kept]
        zs.append((fit.value[ident.kept] - target) / fit.stderr[ident.kept])
    z = np.concatenate(zs)
    print(
        f"{name:7} {len(z):4d} z over {draws} draws: |z| <= 2 {np.mean(np.abs(z) <= 2):.3f}, |z| <= 3 "
        f"{np.mean(np.abs(z) <= 3):.3f}, sd {np.std(z):.2f}, max |z| {np.abs(z).max():.2f}"
    )


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--poses", type=int, default=61)
    ap.add_argument("--sessions", type=int, default=2, help="hardware draws per robot")
    ap.add_argument("--folds", type=int, default=10)
    ap.add_argument("--robots", default="panda,talos")
    ap.add_argument("--design", action="store_true", help="only the pose-selection table (chosen vs random poses)")
    ap.add_argument("--draws", type=int, default=12, help="--design: draws of hardware, candidates, noise, test poses")
    ap.add_argument(
        "--methods", default=",".join(DESIGN_METHODS), help=f"--design: comma-separated of {', '.join(DESIGNS)}"
    )
    ap.add_argument("--no-fit", action="store_true", help="--design: the predicted variance alone (no fits)")
    ap.add_argument("--coverage", type=int, default=0, help="only the z-score table, over this many hardware draws")
    a = ap.parse_args(argv)
    if a.coverage:
        with tempfile.TemporaryDirectory() as tmp:
            for name in a.robots.split(","):
                coverage_table(name, a.coverage, Path(tmp))
        return
    if a.design:
        with tempfile.TemporaryDirectory() as tmp:
            for name in a.robots.split(","):
                design_table(name, Path(tmp), a.draws, tuple(a.methods.split(",")), not a.no_fit)
        return
    python = figaroh_python()
    table = methods(python)
    which = f"FIGAROH 1.0.2 itself ({python})" if python else "FIGAROH not importable: its models re-implemented"
    print(
        f"{a.folds} contiguous folds of {a.poses} static poses, one gripper point, 0.3 mm marker noise; "
        f"{which}; errors in mm, s/fit: one fold's fit\n"
    )
    print(f"{'robot':7} {'method':38} {'mean':>6} {'median':>7} {'worst':>6} {'/floor':>7} {'s/fit':>6}")
    with tempfile.TemporaryDirectory() as tmp:
        for name in a.robots.split(","):
            errs = {m: [] for m in table}
            secs = {m: [] for m in table}
            floors = []
            for s in range(a.sessions):
                d, log = gen.simulate(
                    Path(tmp) / f"s{s}", gen.Session(name, a.poses, 1, seed=50 + s, hardware_seed=50 + s)
                )
                robot = load_robot(d)
                x = log.stream("markers").data
                floors.append(np.linalg.norm(log.truth.signals["markers_floor"].data - x, axis=-1).mean(axis=1))
                for m, run in table.items():
                    e, t = folds_errors(log, robot, name, run, a.folds)
                    errs[m].append(e)
                    secs[m].append(t)
            floor = np.concatenate(floors)
            for m in table:
                e = 1e3 * np.concatenate(errs[m])
                print(
                    f"{name:7} {m:38} {np.nanmean(e):6.2f} {np.nanmedian(e):7.2f} {np.nanmax(e):6.2f} "
                    f"{np.nanmean(e) / (1e3 * floor.mean()):7.2f} {np.mean(secs[m]):6.2f}"
                )
            print(
                f"{name:7} {'noise floor (true model)':38} {1e3 * floor.mean():6.2f} {1e3 * np.median(floor):7.2f} "
                f"{1e3 * floor.max():6.2f}"
            )


if __name__ == "__main__":
    main()
