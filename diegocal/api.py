"""diegocal as a library: what each command does, as a call (``import diegocal.api as dc``).

::

    import diegocal.api as dc

    log = dc.load_log("sample_data/diego_kinematics.h5")
    robot = dc.robot_for(log)                          # the robot the log names (or pass a directory)
    stac = dc.Stac().fit(log, robot)                   # thesis ch. 2: stac.calibration_, stac.q_
    stac.save("diego.calib.yaml", log="sample_data/diego_kinematics.h5")
    held = dc.predict("diego.calib.yaml", "sample_data/diego_kinematics_heldout.h5")
    print(held.rows)                                   # markers predicted from the pots: MAE

The estimators follow scikit-learn's contract: options in the constructor, ``fit(log, robot)``
returns the estimator, what it learnt ends in ``_``. :class:`Stac` (kinematics), :class:`SGP`
(dynamics), :class:`Pneumatic` (pneumatics); :func:`predict` uses any saved model;
:func:`diagnose` names what a model gets wrong; :func:`report` writes the PDF. The command line
calls these same functions.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from pathlib import Path

from diegocal.errors import FitError, NotFittedError, OptionError
from diegocal.io import Log, load_log, save_yaml
from diegocal.io.bundle import header
from diegocal.predict import Prediction, PredictOptions, predict
from diegocal.robot import Robot, load_robot
from diegocal.robot.resolve import robot_for_log


def __getattr__(name: str):
    """``pooled_heldout_rmse`` (part of the API) is imported when first asked for: the diagnosis
    package and scipy.stats need not load for a ``stac`` or ``predict`` call."""
    if name == "pooled_heldout_rmse":
        from diegocal.diagnose.output import pooled_heldout_rmse

        return pooled_heldout_rmse
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "SGP",
    "Pneumatic",
    "Prediction",
    "PredictOptions",
    "Stac",
    "calibrate",
    "diagnose",
    "load_log",
    "load_robot",
    "predict",
    "report",
    "robot_for",
]

#: The ``command`` a model fitted from Python records in its header.
LIBRARY = "diegocal (Python)"


class _Estimator:
    """scikit-learn's parameter protocol for the dataclass estimators (``get_params``,
    ``set_params``: their fields not starting with ``_``), so that ``sklearn.base.clone`` and a
    grid search can build them, and the not-fitted error."""

    def get_params(self, deep: bool = True) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self) if not f.name.startswith("_")}

    def set_params(self, **params):
        unknown = sorted(set(params) - set(self.get_params()))
        if unknown:
            have = ", ".join(self.get_params())
            raise OptionError(f"{type(self).__name__} has no parameter {unknown[0]!r} (has {have})")
        for name, value in params.items():
            setattr(self, name, value)
        return self

    def _check_fitted(self) -> None:
        if not hasattr(self, "robot_"):
            raise NotFittedError(f"this {type(self).__name__} is not fitted yet: call fit(log, robot) first")


def robot_for(log: Log, robot=None) -> Robot:
    """The robot to fit ``log`` with: ``robot`` (a directory, URDF or bundled name; None: the one
    the log names), reduced to the joints the log and the sensors use."""
    return robot_for_log(robot, log)


def _log_and_robot(log, robot) -> tuple[Log, Robot, Path | None]:
    path = Path(log) if isinstance(log, (str, Path)) else None
    log = load_log(path) if path is not None else log
    if not isinstance(robot, Robot):
        robot = robot_for(log, robot)
    return log.without_truth(), robot, path


# ----------------------------------------------------------------------------- kinematics
def calibrate(log: Log, robot: Robot, method: str = "stac", options=None):
    """Calibrate pots, markers and the mocap frame with ``method`` (stac, thesis ch. 2; classical,
    §2.2.1; ekf, §2.4.1; nominal: sensors.yaml as it is): a :class:`~diegocal.stac.result.StacResult`."""
    from diegocal.stac.calibration import Calibration
    from diegocal.stac.result import StacOptions, StacResult

    options = options or StacOptions()
    if method == "stac":
        from diegocal.stac.stac import calibrate as stac

        return stac(log, robot, options)
    if method == "nominal":
        from diegocal.stac.model import Observation
        from diegocal.stac.stac import initial_q

        obs = Observation(log, robot)
        cal = Calibration.nominal(robot)
        return StacResult(cal, initial_q(obs, obs.params_from(cal), options))
    if method == "classical":
        from diegocal.stac.classical import calibrate_classical

        return calibrate_classical(log, robot, options, nonlinear="constrain")
    if method == "ekf":
        from diegocal.stac.ekf import calibrate_ekf

        return calibrate_ekf(log, robot, options)
    raise FitError(f"unknown method {method!r} (expected stac, classical, ekf or nominal)")


@dataclass
class Stac(_Estimator):
    """Kinematic calibration (thesis ch. 2). ``options``: :class:`~diegocal.stac.result.StacOptions`.

    Learnt: ``calibration_`` (:class:`~diegocal.stac.calibration.Calibration`), ``q_`` (T, n) rad
    the tracked joint angles, ``robot_``."""

    method: str = "stac"
    options: object = None

    def fit(self, log, robot=None) -> Stac:
        """Calibrate on ``log`` (a Log or a file; ``robot``: by default the log's); returns self."""
        log, robot, path = _log_and_robot(log, robot)
        result = calibrate(log, robot, self.method, self.options)
        self.calibration_, self.q_, self.robot_, self.log_path_ = result.calibration, result.q, robot, path
        return self

    def save(self, path, log=None, command: str = LIBRARY) -> Path:
        """Write calib.yaml (with its bundle header: robot, log, command, version)."""
        self._check_fitted()
        head = header("kinematics", self.robot_, log or self.log_path_, command)
        cal = replace(self.calibration_, header=head)
        save_yaml(cal.to_dict(), path)
        return Path(path)

    def predict(self, log, sources=("pots",), targets=("markers",)):
        """Cross-sensor prediction (thesis §2.7.2): :class:`~diegocal.stac.predict.Prediction`."""
        from diegocal.stac.predict import predict as stac_predict

        self._check_fitted()
        log = load_log(log) if isinstance(log, (str, Path)) else log
        return stac_predict(log.without_truth(), self.robot_, self.calibration_, sources, targets)


# ----------------------------------------------------------------------------- dynamics
@dataclass
class SGP(_Estimator):
    """Inverse dynamics (thesis ch. 3): PR, GP, PRGP or the semi-parametric GP, by
    ``options.kind`` (:class:`~diegocal.sgp.model.SGPOptions`; default the guarded SGP).

    Learnt: ``model_`` (:class:`~diegocal.sgp.model.DynamicsModel`: ``parametric_``,
    ``hyperparameters_``), ``robot_``."""

    options: object = None

    def fit(self, log, robot=None, progress=None) -> SGP:
        """Fit the torque model to ``log`` (a Log or a file; ``robot``: by default the log's); returns self."""
        from diegocal.sgp.model import SGPOptions, fit_dynamics

        log, robot, path = _log_and_robot(log, robot)
        self.model_ = fit_dynamics(log, robot, self.options or SGPOptions(), progress=progress)
        self.robot_, self.log_path_ = robot, path
        return self

    def predict(self, log):
        """Torques and their predictive std: :class:`~diegocal.sgp.model.TorquePrediction`."""
        self._check_fitted()
        log = load_log(log) if isinstance(log, (str, Path)) else log
        return self.model_.predict(log.without_truth())

    def save(self, directory, log=None, command: str = LIBRARY, meta: dict | None = None) -> Path:
        """Write the model's directory (sgp.yaml, model.npz, a copy of the robot)."""
        from diegocal.sgp.store import save_model

        self._check_fitted()
        log = log or self.log_path_
        meta = {"log": None if log is None else str(Path(log).resolve()), "command": command, **(meta or {})}
        return save_model(self.model_, directory, meta, header=header("dynamics", self.robot_, log, command))


# ----------------------------------------------------------------------------- pneumatics
@dataclass
class Pneumatic(_Estimator):
    """The 9-parameter valve-chamber model (thesis ch. 4), one fit per chamber.

    ``chambers``: names, or one name (empty: every chamber of sensors.yaml the log lets us fit); ``options``:
    :class:`~diegocal.pneumatic.fit.FitOptions`. Learnt: ``fits_`` (chamber -> its fit),
    ``skipped_`` (chamber -> why it was not fitted), ``robot_``."""

    chambers: tuple = ()
    options: object = None
    jobs: int = 1
    _batch: object = field(default=None, repr=False)

    def fit(self, log, robot=None, progress=None) -> Pneumatic:
        """Fit each chamber to ``log`` (a Log or a file; ``robot``: by default the log's); returns self."""
        from diegocal.errors import DiegocalError
        from diegocal.pneumatic.data import chamber_data
        from diegocal.pneumatic.fit import FitOptions, fit_chambers

        log, robot, path = _log_and_robot(log, robot)
        asked = (self.chambers,) if isinstance(self.chambers, str) else tuple(self.chambers)  # one name, or several
        names = asked or robot.sensors.chamber_names
        datasets, skipped = [], {}
        for name in names:
            try:
                datasets.append(chamber_data(log, robot.sensors, name))
            except DiegocalError as exc:
                if asked:
                    raise
                skipped[name] = str(exc)
        batch = fit_chambers(datasets, self.options or FitOptions(), jobs=self.jobs, progress=progress)
        batch.skipped.update(skipped)
        if not batch.fits:
            first = next(iter(batch.skipped.values()), f"robot {robot.name!r} has no chambers")
            raise FitError(f"no chamber could be fitted ({first})")
        self._batch, self.fits_, self.skipped_, self.robot_ = batch, dict(batch.fits), dict(batch.skipped), robot
        self.log_path_ = path
        return self

    def save(self, path, log=None, command: str = LIBRARY, meta: dict | None = None) -> Path:
        """Write pneumatic.yaml (with its bundle header)."""
        from diegocal.pneumatic.files import model_dict
        from diegocal.pneumatic.fit import FitOptions

        self._check_fitted()
        log = log or self.log_path_
        meta = {"log": None if log is None else str(Path(log).resolve()),
                "robot": str(self.robot_.directory or self.robot_.name), **(meta or {})}
        head = header("pneumatics", self.robot_, log, command)
        save_yaml(model_dict(self._batch, self.robot_.sensors, self.options or FitOptions(), meta, head), path)
        return Path(path)


# ----------------------------------------------------------------------------- diagnose and report
def diagnose(log, robot=None, domain: str | None = None, options=None) -> dict:
    """Diagnose ``log`` in ``domain`` (None: every domain its streams allow): domain ->
    :class:`~diegocal.diagnose.Diagnosis` (``findings``, ``to_dict()``, ``save(...)``)."""
    from diegocal.diagnose import DiagnoseOptions, domains_of
    from diegocal.diagnose import diagnose as run

    log, robot, _ = _log_and_robot(log, robot)
    options = options or DiagnoseOptions()
    todo = (domain,) if domain else domains_of(log)
    return {d: run(log, robot, replace(options, domain=d)) for d in todo}


def report(results, output, heldout=(), robot=None, command: str = LIBRARY) -> Path:
    """Write one PDF of ``results`` (fitted models, diagnoses, logs; paths) with ``heldout`` logs."""
    from diegocal.report import ReportContext, write_report

    write_report([Path(r) for r in results], Path(output), ReportContext(robot=robot, heldout=tuple(heldout)),
                 command=command)
    return Path(output)


# ----------------------------------------------------------------------------- summaries of results
