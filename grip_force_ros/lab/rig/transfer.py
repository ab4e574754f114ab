"""Sim-to-real across instruments and occasions: fit on some rig folders, judge on another.

The observer (:mod:`.estimator`) fitted on one folder of the MRDLab rig was 10-21 mN*m
off on the others. What the motor side alone fixes, and what one run of the new folder
whose jaw torque is read (a calibration jig, once per instrument) fixes of the rest
(the model itself gains a load-dependent efficiency and a Coulomb friction that changes
along the stroke, :data:`TRANSFER_SETTINGS`, and a run's start-up estimate is the
session's, :func:`predict_session`):

* **Motor-side conventions, per folder, from the motor side alone.** Which way is
  closing (:func:`orient`): the current pushes the motor the way it moves (friction),
  so current against disk velocity gives the encoder sign; the mean current, once
  tared, has the sign of the resisting load, so closing is where it points; the
  gearbox encoder follows the disk. The header's spindle (left/right) gives the
  upstream convention first; the data check it.
* **The current sensor zero of a session** (:func:`current_tare`): the measured
  current equals the drive's current command (back-end command x 2.05 A) plus a
  sensor zero that changes from session to session (-0.004 A in
  ``Tool_4_Maryland_L_2``, -0.019 A in ``Tool_4_Maryland_L_4``: 15 mN*m at the jaw,
  most of the zero-shot gap). Robust least squares of the measured current on the
  command over the folder's runs gives it; motor-side columns only.
* **The session consistency, from the motor side of every run of the folder**
  (:mod:`.consistency`): a run holds one load, so its closing- and opening-branch
  estimates may differ only by the rig front end's own friction (learned on the
  training folders); their disagreement over the folder's runs, at several loads,
  tells the groups that split the branches (efficiency, Coulomb friction and its
  change along the stroke), zero-shot too.
* **Per instrument, identified on the calibration run** (:func:`calibrate`): a
  Bayesian update of the forward model's coefficients in physical groups (gain,
  efficiency, Coulomb friction, friction map, spring, zeros, viscous; with the session
  consistency's rows when a session is given), each regularised towards the
  training folders' value with a prior width (a stated tolerance, widened to the
  spread between training folders), the calibration run's residual treated as
  correlated noise plus a run-level offset per friction branch (the run-to-run
  friction scatter seen in training, which one run cannot tell from a parameter).
  What transfers and is never refitted: the model's structure, the Dahl width,
  thresholds, filters and observer (the fixed settings), the gain except through its
  narrow prior.

Scoring target. Zero-shot: the jaw torque sensor as recorded (the rig firmware tares
it at the start of each session, header ``torque0AverageTorque``), with the sign of
the header's spindle convention (upstream's loader negates the right spindle). With
a calibration run, the calibration run fixes the sensor's sign and zero, as a jig
would: the sign so that its mean jaw torque is positive (the jaw holds a closing
torque against the resisting motor), the zero as its mean reading minus the
resisting motor's torque (front-end gain x command, the gain fitted on the training
folders: 0.1175 N*m/A in ``L_2``, 0.1171 in ``L_4``; the sensor zeros found that way:
+0.1 and +1.3 mN*m). Training folders are put in the same frame (their own zeros
removed). The scored runs' jaw-side columns are read only to score.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from grip_force_ros.lab.rig import constants as C
from grip_force_ros.lab.rig.consistency import FrontEnd, fit_front_end, session_residuals
from grip_force_ros.lab.rig.estimator import (POSITION_RANGE, CableFrictionObserver, EstimatorError,
                                              ObserverSettings, causal_lowpass, causal_velocity)
from grip_force_ros.lab.rig.reader import RigDataError, RigRun, data_root, read_runs

#: Samples of a run used by the motor-side statistics (every n-th sample; 1 kHz data).
STAT_STRIDE = 5
#: Residual (A) beyond which a sample is left out of the tare fit (glitches: run 07 of
#: Tool_4_Maryland_L_4 has a disk-encoder slip where the command hits 1.06).
TARE_OUTLIER_A = 0.05


#: The transfer model: the one-folder observer's settings plus the load-dependent
#: efficiency (the training folders together span 10-100 % loads) and a Coulomb friction
#: that changes linearly along the disk stroke (friction map, Legendre P1): in
#: ``Tool_4_Maryland_L_4`` it falls by 28 mN*m at the jaw from the open to the closed end,
#: in ``L_2`` by 9 mN*m (docs/real_data.md, "The wide-load floor"); and the load model: the
#: observer averages the held load's level and adds the load's shape along the stroke
#: learned on the training folders (the rig's resisting motor has its own friction and
#: lever; :class:`.estimator.LoadModel`).
TRANSFER_SETTINGS = ObserverSettings(load_dependent_efficiency=True, friction_map_order=1,
                                     load_model=True)


# -- folders: read, orient, tare ---------------------------------------------------------------
@dataclass
class CurrentTare:
    """Current sensor zero of a session, from measured vs commanded current.

    Attributes
    ----------
    zero_A : float
        Sensor zero (A): measured = scale * commanded + zero.
    scale : float
        Measured current per commanded current (1 when the drive's 2.05 A/unit holds).
    samples : int
        Samples the robust fit kept.
    residual_std_A : float
        Standard deviation of the kept residuals (A).
    """

    zero_A: float
    scale: float
    samples: int
    residual_std_A: float


def current_tare(runs: Sequence[RigRun]) -> CurrentTare:
    """Robust least-squares fit of measured on commanded current over a folder's runs.

    Two passes: least squares, then again without samples whose residual exceeds
    5 robust standard deviations or :data:`TARE_OUTLIER_A`. Reads ``current`` and
    ``current_command`` only. Without a usable command (absent or constant) the
    zero is 0 and ``samples`` is 0.
    """
    xs, ys = [], []
    for run in runs:
        cmd = getattr(run, 'current_command', None)
        if cmd is None:
            continue
        xs.append(np.asarray(cmd, dtype=np.float64)[::STAT_STRIDE])
        ys.append(np.asarray(run.current, dtype=np.float64)[::STAT_STRIDE])
    if not xs:
        return CurrentTare(0.0, 1.0, 0, float('nan'))
    x, y = np.concatenate(xs), np.concatenate(ys)
    if x.size < 10 or np.std(x) < 1e-6:
        return CurrentTare(0.0, 1.0, 0, float('nan'))
    keep = np.ones(x.size, dtype=bool)
    coef = np.zeros(2)
    for _ in range(2):
        a = np.column_stack([x[keep], np.ones(int(keep.sum()))])
        coef = np.linalg.lstsq(a, y[keep], rcond=None)[0]
        res = y - coef[0] * x - coef[1]
        mad = 1.4826 * np.median(np.abs(res[keep] - np.median(res[keep])))
        keep = np.abs(res) < min(TARE_OUTLIER_A, 5.0 * max(mad, 1e-4))
    res = y[keep] - coef[0] * x[keep] - coef[1]
    return CurrentTare(float(coef[1]), float(coef[0]), int(keep.sum()), float(np.std(res)))


def _vote(values: Iterable[float]) -> tuple[int, int, int]:
    """(sign of the majority, runs for +, runs for -) of per-run statistics."""
    values = [v for v in values if np.isfinite(v) and v != 0.0]
    plus = sum(1 for v in values if v > 0)
    minus = len(values) - plus
    return (1 if plus >= minus else -1), plus, minus


def _run_statistics(run: RigRun, zero: float) -> dict[str, float]:
    """Motor-side sign statistics of one run (see :func:`orient`)."""
    dt = float(np.median(np.diff(run.t))) if len(run) > 1 else C.SAMPLE_PERIOD
    i_f = causal_lowpass(run.current - zero, 10.0, dt)
    v_disk = causal_velocity(run.motor_angle, dt, 0.02, 10.0)
    v_shaft = causal_velocity(run.motor_shaft_angle, dt, 0.02, 10.0)
    moving = np.abs(v_disk) > 0.1
    stats = {'current_vs_disk_motion': float('nan'), 'mean_current_A': float(np.mean(i_f[moving]))
             if moving.any() else float('nan'),
             'shaft_vs_disk_motion': float('nan'), 'current_vs_command': float('nan')}
    if moving.sum() > 10:
        stats['current_vs_disk_motion'] = float(np.corrcoef(i_f[moving], v_disk[moving])[0, 1])
        stats['shaft_vs_disk_motion'] = float(np.corrcoef(v_shaft[moving], v_disk[moving])[0, 1])
    cmd = run.current_command
    if np.std(cmd) > 1e-9:
        stats['current_vs_command'] = float(np.corrcoef(run.current, cmd)[0, 1])
    return stats


@dataclass
class Folder:
    """One rig folder (an instrument on one occasion), oriented and tared.

    Attributes
    ----------
    path : Path
        The folder.
    runs : list of RigRun
        Runs with closing-positive motor-side signs and the current tared
        (``current - zero``); the jaw-side columns as read.
    raw_runs : list of RigRun
        The runs as read (header convention, no tare).
    spindle : str
        ``'left'``/``'right'`` (majority of the runs' headers or folder name).
    spindle_source : str
        ``'header'``, ``'folder'`` or ``'default'``.
    tare : CurrentTare
        The current sensor zero removed from ``runs``.
    orientation : dict
        Motor-side sign checks: per statistic the folder's vote and counts, and the
        flips applied (:func:`orient`).
    """

    path: Path
    runs: list
    raw_runs: list = field(repr=False)
    spindle: str = 'left'
    spindle_source: str = 'default'
    tare: CurrentTare | None = None
    orientation: dict = field(default_factory=dict)

    @property
    def name(self) -> str:
        """Folder name, e.g. ``Tool_4_Maryland_L_4``."""
        return self.path.name

    def run(self, key: str) -> RigRun:
        """Return the run named ``key`` (``'11'``, ``'11.TXT'`` or a path ending in it)."""
        stem = Path(key).name
        stem = stem[:-4] if stem.lower().endswith('.txt') else stem
        for run in self.runs:
            if run.name == stem:
                return run
        raise RigDataError(f'{self.path}: no run {key!r} (runs: '
                           f'{", ".join(r.name for r in self.runs)})')


def orient(runs: Sequence[RigRun]) -> tuple[list[RigRun], CurrentTare, dict]:
    """Make closing positive on the motor side from motor-side data, and tare the current.

    Per run, motor-side statistics; per folder, a majority vote:

    1. ``current_vs_command``: the measured current follows the command (a negative
       correlation negates the command);
    2. the current sensor zero (:func:`current_tare`) is removed from the current;
    3. ``mean_current_A`` while the disk moves: the resisting load makes the
       closing branch larger than the opening one, so the mean tared current has the
       sign of the resisting torque; a negative vote negates current and command;
    4. ``current_vs_disk_motion``: friction makes the current push the way the disk
       moves; a negative vote negates the disk angle (and re-references it so the
       folder's most closed disk angle is 0, as on the left spindle);
    5. ``shaft_vs_disk_motion``: the gearbox encoder turns with the disk;
    6. the disk angle's frame: kept unless the strokes lie mostly outside the range the
       spring was fitted on (:func:`_disk_reference`).

    Reads ``t``, ``current``, ``current_command``, ``motor_angle`` and
    ``motor_shaft_angle`` only.

    Returns
    -------
    (list of RigRun, CurrentTare, dict)
        Oriented and tared runs, the tare, and the checks with the flips applied.
    """
    runs = list(runs)
    report: dict = {}
    checks = [np.corrcoef(r.current, r.current_command)[0, 1] if np.std(r.current_command) > 1e-9
              else float('nan') for r in runs]
    sign, plus, minus = _vote(checks)
    report['current_vs_command'] = {'vote': sign, 'runs_plus': plus, 'runs_minus': minus}
    if sign < 0:
        runs = [replace(r, current_command=-r.current_command) for r in runs]
    tare = current_tare(runs)
    stats = [_run_statistics(r, tare.zero_A) for r in runs]
    flips = []
    sign, plus, minus = _vote(s['mean_current_A'] for s in stats)
    report['mean_current_closing'] = {'vote': sign, 'runs_plus': plus, 'runs_minus': minus}
    if sign < 0:
        runs = [replace(r, current=-r.current, current_command=-r.current_command) for r in runs]
        tare = CurrentTare(-tare.zero_A, tare.scale, tare.samples, tare.residual_std_A)
        stats = [dict(s, current_vs_disk_motion=-s['current_vs_disk_motion']) for s in stats]
        flips.append('current')
    sign, plus, minus = _vote(s['current_vs_disk_motion'] for s in stats)
    report['current_vs_disk_motion'] = {'vote': sign, 'runs_plus': plus, 'runs_minus': minus}
    if sign < 0:
        closed = float(np.median([np.max(-r.motor_angle) for r in runs]))
        runs = [replace(r, motor_angle=-r.motor_angle - closed,
                        trajectory_angle=-r.trajectory_angle - closed) for r in runs]
        stats = [dict(s, shaft_vs_disk_motion=-s['shaft_vs_disk_motion']) for s in stats]
        flips.append('disk encoder')
    sign, plus, minus = _vote(s['shaft_vs_disk_motion'] for s in stats)
    report['shaft_vs_disk_motion'] = {'vote': sign, 'runs_plus': plus, 'runs_minus': minus}
    if sign < 0:
        runs = [replace(r, motor_shaft_angle=-r.motor_shaft_angle) for r in runs]
        flips.append('motor encoder')
    report['flips_against_header_convention'] = flips
    runs, shift, overlap = _disk_reference(runs)
    report['disk_stroke_in_trained_range'] = round(overlap, 4)
    report['disk_reference_shift_rad'] = round(shift, 6)
    tared = [replace(r, current=r.current - tare.zero_A) for r in runs]
    return tared, tare, report


#: Below this median fraction of a folder's strokes inside the spring's disk range, the
#: disk angle is taken to be in another frame and is re-referenced.
MIN_STROKE_OVERLAP = 0.5


def _disk_reference(runs: list) -> tuple[list, float, float]:
    """Keep the disk angle's frame, unless the folder's strokes lie outside the spring's range.

    When the strokes lie mostly outside the range the spring was fitted on
    (:data:`.estimator.POSITION_RANGE`), shift the frame so that the folder's median
    most-closed angle is 0, as in the left-spindle folders (a right-spindle
    offset that does not hold, another encoder reference).

    Returns
    -------
    (list, float, float)
        Runs, the shift applied (rad, 0 when none) and the median overlap fraction.
    """
    lo, hi = POSITION_RANGE
    overlaps, closed = [], []
    for r in runs:
        a, b = float(np.min(r.motor_angle)), float(np.max(r.motor_angle))
        span = max(b - a, 1e-9)
        overlaps.append(max(0.0, min(b, hi) - max(a, lo)) / span)
        closed.append(b)
    overlap = float(np.median(overlaps)) if overlaps else 1.0
    if overlap >= MIN_STROKE_OVERLAP:
        return runs, 0.0, overlap
    shift = hi - float(np.median(closed))
    return ([replace(r, motor_angle=r.motor_angle + shift,
                     trajectory_angle=r.trajectory_angle + shift) for r in runs], shift, overlap)


def resolve_folder(folder) -> Path:
    """Return a folder path as given, else the same name under :func:`.reader.data_root`."""
    path = Path(folder)
    if path.is_dir():
        return path
    candidate = data_root() / str(folder)
    if candidate.is_dir():
        return candidate
    raise RigDataError(f'{folder}: not a directory (nor under {data_root()})')


def load_folder(folder) -> Folder:
    """Read, orient and tare one rig folder (see :func:`orient`)."""
    path = resolve_folder(folder)
    raw = read_runs(path)
    runs, tare, report = orient(raw)
    sides = [r.spindle for r in raw]
    spindle = max(set(sides), key=sides.count)
    sources = [r.spindle_source for r in raw if r.spindle == spindle]
    return Folder(path, runs, raw, spindle, max(set(sources), key=sources.count), tare, report)


# -- the model: what transfers, what is calibrated ----------------------------------------------
@dataclass(frozen=True)
class CalibrationGroup:
    """A group of forward coefficients a calibration run may move.

    Attributes
    ----------
    name : str
        ``gain``, ``efficiency``, ``coulomb``, ``spring``, ``zeros``, ``viscous``.
    coefficients : tuple of str
        Forward coefficients (:class:`.estimator.FitResult` names) it moves.
    kind : str
        ``'scale'``: one relative factor on all of them together (dimensionless);
        ``'shift'``: each moves by an additive amount (the coefficient's unit).
    prior_std : float
        Prior standard deviation (relative for ``scale``, coefficient unit for
        ``shift``) before the spread between training folders widens it.
    unit : str
        Unit of the group's parameters.
    meaning : str
        What it is physically.
    splits_branches : bool
        The group moves the closing and opening friction branches apart (efficiency,
        Coulomb friction and its map): the session consistency, which compares the two
        branches, informs it. The others move both branches together (gain, zeros,
        spring, viscous) and are left to the calibration run.
    """

    name: str
    coefficients: tuple
    kind: str
    prior_std: float
    unit: str
    meaning: str
    splits_branches: bool = False


#: The per-instrument groups. Prior widths are engineering tolerances: motor torque
#: constant and pulley radii (Maxon datasheet +-5 %, here +-3 % on their product),
#: friction efficiency of cable over pulleys (+-30 % of the direction-dependent part),
#: Coulomb friction from pretension (+-15 %), its change along the stroke (the same
#: +-15 % of the 0.08 A Coulomb level: +-12 mA on the P1 coefficient), zeros left after
#: the current tare and the jaw sensor zero found against the resisting motor (+-5 mA:
#: 5 mN*m at the jaw), spring from cable pretension (+-5 mA per Legendre coefficient),
#: viscous friction (+-2 mA*s/rad).
GROUPS = (
    CalibrationGroup('gain', ('alpha0', 'alpha1', 'alpha1_quad'), 'scale', 0.03, '1 (relative)',
                     'loss-free current-to-jaw-torque gain G: motor torque constant x gear x '
                     'pulley ratios (all torque terms scale together)'),
    CalibrationGroup('efficiency', ('alpha1', 'alpha1_quad'), 'scale', 0.30, '1 (relative)',
                     'direction-dependent (tension-proportional) cable friction: efficiency eta '
                     'and its fall with load', splits_branches=True),
    CalibrationGroup('coulomb', ('coulomb',), 'scale', 0.15, '1 (relative)',
                     'load-independent friction from cable pretension (Coulomb)',
                     splits_branches=True),
    CalibrationGroup('friction_map', ('friction_P1',), 'shift', 0.012, 'A',
                     'change of the Coulomb friction along the disk stroke (cable pretension '
                     'varying with the stroke), Legendre P1: half the closed-minus-open change',
                     splits_branches=True),
    CalibrationGroup('spring', ('spring_P1', 'spring_P2'), 'shift', 0.005, 'A',
                     'position spring over the stroke (cable pretension, jaw), Legendre P1, P2'),
    CalibrationGroup('zeros', ('offset',), 'shift', 0.005, 'A',
                     'zeros left after the current tare and the jaw sensor zero found against '
                     'the resisting motor (current offset, sensor zero residual)'),
    CalibrationGroup('viscous', ('viscous',), 'shift', 0.002, 'A*s/rad',
                     'viscous friction of the transmission'),
)
GROUP_NAMES = tuple(g.name for g in GROUPS)

#: Units of the forward-model coefficients (I in A, tau in N*m, v in rad/s).
COEFFICIENT_UNITS = {'alpha0': 'A/(N*m)', 'alpha1': 'A/(N*m)', 'alpha2': 'A/(N*m)',
                     'alpha1_quad': 'A/(N*m)^2', 'offset': 'A', 'coulomb': 'A',
                     'coulomb_slow': 'A', 'spring': 'A', 'friction': 'A', 'viscous': 'A*s/rad'}
#: Units of the interpretable parameters (:func:`.estimator._physical`).
PHYSICAL_UNITS = {'gain_Nm_per_A': 'N*m/A', 'efficiency': '1', 'efficiency_at_100mNm': '1',
                  'offset_Nm': 'N*m', 'coulomb_Nm': 'N*m', 'viscous_Nms_per_rad': 'N*m*s/rad',
                  'spring_span_Nm': 'N*m', 'coulomb_change_Nm': 'N*m'}


def coefficient_unit(name: str) -> str:
    """Return the unit of a forward-model coefficient (``spring_P2``, ``friction_P1``: their family's)."""
    family, _, order = name.rpartition('_P')
    return COEFFICIENT_UNITS.get(family if family and order.isdigit() else name, '')


@dataclass
class NoiseModel:
    """How much one calibration run can say: residual statistics of the training fit.

    Attributes
    ----------
    white_std_A : float
        Standard deviation of the forward-model residual on sliding samples (A).
    correlation_s : float
        Integrated correlation time of that residual (s): a run of T s sliding
        holds about T / correlation_s independent residuals.
    run_offset_std_A : float
        Scatter (A) of the per-run, per-branch mean residual: the run-to-run friction
        change one run cannot tell from a parameter change.
    """

    white_std_A: float
    correlation_s: float
    run_offset_std_A: float


def _residuals(est: CableFrictionObserver, run, cache: dict) -> tuple[np.ndarray, np.ndarray]:
    names, a, y, _ = est._rows(run, cache)
    coef = est.coefficients
    resid = y - a @ np.array([coef[k] for k in names])
    sig = est._design(run, cache)[0]
    return resid, np.sign(sig.direction[sig.sliding > 0])


def noise_model(est: CableFrictionObserver, runs: Sequence, cache: dict) -> NoiseModel:
    """Residual statistics of a fitted estimator on its training runs (:class:`NoiseModel`)."""
    resids, offsets = [], []
    for run in runs:
        res, branch = _residuals(est, run, cache)
        resids.append(res)
        for side in (1, -1):
            sel = branch == side
            if sel.sum() > 100:
                offsets.append(float(np.mean(res[sel])))
    e = np.concatenate(resids)
    var = float(np.var(e))
    block = 200
    nb = e.size // block
    tc = C.SAMPLE_PERIOD
    if nb > 10 and var > 0:
        means = e[:nb * block].reshape(nb, block).mean(axis=1)
        tc = float(np.clip(np.var(means) * block / var * C.SAMPLE_PERIOD, C.SAMPLE_PERIOD, 1.0))
    return NoiseModel(math.sqrt(var), tc, float(np.std(offsets)) if len(offsets) > 2 else 0.0)


@dataclass
class TrainedModel:
    """The estimator fitted on training folders, with what calibration needs.

    Attributes
    ----------
    estimator : CableFrictionObserver
        Fitted on every run of the training folders (oriented, tared).
    folders : list of Folder
    noise : NoiseModel
    priors : dict of str to float
        Prior standard deviation per calibration group: the stated tolerance
        widened to the spread between the training folders' own fits.
    per_folder : dict of str to dict
        Coefficients fitted on each training folder alone (when more than one).
    max_torque_Nm : float
        Largest jaw torque in training (the load range the physics was learned on).
    front_end : dict
        The resisting motor as a torque reference: ``gain_Nm_per_A`` (mean jaw torque
        per resisting-motor command, fitted on the training runs with one intercept
        per folder) and each training folder's sensor zero ``zeros_Nm`` (its
        intercept; removed from its jaw torque before the fit).
    front_end_steps : FrontEnd or None
        The front end's closing-minus-opening jaw torque against the load and the
        consistency noise (:func:`.consistency.fit_front_end`), for the session
        consistency of a test folder.
    """

    estimator: CableFrictionObserver
    folders: list
    noise: NoiseModel
    priors: dict
    per_folder: dict
    max_torque_Nm: float
    front_end: dict = field(default_factory=dict)
    cache: dict = field(default_factory=dict, repr=False)
    front_end_steps: FrontEnd | None = None


#: Load (N*m) at which the efficiency group's spread between training folders is measured.
SPREAD_TORQUE = 0.05


def _group_parameter(group: CalibrationGroup, coef: dict, reference: dict) -> list[float]:
    """Return a folder's value of a group relative to the reference fit.

    For ``scale`` groups: the relative change of what the group scales (gain: alpha0;
    efficiency: the friction split alpha1*tau + alpha1_quad*tau^2 at
    :data:`SPREAD_TORQUE`; Coulomb: coulomb); for ``shift`` groups: the coefficient
    differences.
    """
    if group.kind == 'scale':
        if group.name == 'gain':
            value, ref = coef['alpha0'], reference['alpha0']
        elif group.name == 'efficiency':
            def split(c):
                return c.get('alpha1', 0.0) * SPREAD_TORQUE + c.get('alpha1_quad', 0.0) * \
                    SPREAD_TORQUE ** 2
            value, ref = split(coef), split(reference)
        else:
            names = [k for k in group.coefficients if k in coef]
            value = sum(coef[k] for k in names)
            ref = sum(reference[k] for k in names)
        return [value / ref - 1.0] if ref != 0 else [0.0]
    return [coef[k] - reference[k] for k in group.coefficients if k in coef]


def front_end_reference(folders: Sequence[Folder]) -> dict:
    """Jaw torque sensor zeros of folders against the resisting motor (the rig's torque jig).

    Per run, the mean jaw torque against the mean resisting-motor command; least
    squares with one gain for all folders (the same front-end motor) and one
    intercept per folder. The intercept is that folder's sensor zero: a motor at zero
    current holds zero torque. Reads the jaw side: training folders only.

    Returns
    -------
    dict
        ``gain_Nm_per_A``, ``zeros_Nm`` (folder name to N*m), ``residual_std_Nm``.
    """
    x, y, which = [], [], []
    for k, f in enumerate(folders):
        for r in f.runs:
            x.append(abs(float(np.mean(r.load_command))))
            y.append(float(np.mean(r.jaw_torque)))
            which.append(k)
    x, y, which = np.array(x), np.array(y), np.array(which)
    if np.ptp(x) < 1e-9:
        return {'gain_Nm_per_A': float('nan'), 'zeros_Nm': {f.name: 0.0 for f in folders},
                'residual_std_Nm': float('nan')}
    design = np.column_stack([x] + [(which == k).astype(float) for k in range(len(folders))])
    coef = np.linalg.lstsq(design, y, rcond=None)[0]
    res = y - design @ coef
    return {'gain_Nm_per_A': float(coef[0]),
            'zeros_Nm': {f.name: float(c) for f, c in zip(folders, coef[1:])},
            'residual_std_Nm': float(np.std(res))}


def train(folders: Sequence[Folder], settings: ObserverSettings | None = None) -> TrainedModel:
    """Fit the estimator on every run of the training folders, and the calibration priors.

    Each training folder's jaw torque is taken relative to its sensor zero against the
    resisting motor (:func:`front_end_reference`), so that folders recorded with
    different tares share one torque frame.
    """
    if not folders:
        raise EstimatorError('train needs at least one folder')
    cache: dict = {}
    settings = TRANSFER_SETTINGS if settings is None else settings
    front = front_end_reference(folders)
    folders = [replace(f, runs=[replace(r, jaw_torque=r.jaw_torque - front['zeros_Nm'][f.name])
                                for r in f.runs]) for f in folders]
    runs = [r for f in folders for r in f.runs]
    est = CableFrictionObserver(settings).fit(runs, cache=cache)
    coef = est.coefficients
    per_folder, priors = {}, {}
    spreads = {g.name: [] for g in GROUPS}
    if len(folders) > 1:
        for f in folders:
            own = CableFrictionObserver(settings).fit(f.runs, cache=cache).coefficients
            per_folder[f.name] = own
            for g in GROUPS:
                spreads[g.name].extend(_group_parameter(g, own, coef))
    for g in GROUPS:
        spread = float(np.sqrt(np.mean(np.square(spreads[g.name])))) if spreads[g.name] else 0.0
        priors[g.name] = max(g.prior_std, spread)
    noise = noise_model(est, runs, cache)
    max_torque = float(max(np.max(r.jaw_torque) for r in runs))
    return TrainedModel(est, list(folders), noise, priors, per_folder, max_torque, front, cache,
                        fit_front_end(est, runs, cache))


# -- calibration -------------------------------------------------------------------------------
@dataclass
class Calibration:
    """What one or more calibration runs identified (JSON-ready via :meth:`to_json`).

    Attributes
    ----------
    estimator : CableFrictionObserver
        The calibrated estimator.
    runs : list of str
        Calibration run files.
    groups : dict
        Per group: posterior value and standard deviation, prior std, unit, meaning.
    coefficients : dict
        Forward coefficients before and after.
    target_sign : int
        Sign applied to the test folder's jaw torque sensor for scoring (+1: as the
        header's spindle convention reads it).
    target_zero_Nm : float
        The test folder's jaw torque sensor zero found on the calibration runs against
        the resisting motor (mean reading minus front-end gain x command), subtracted
        from the sensor for scoring.
    prior_torque_Nm : float
        Estimate before the first sliding sample of a run (calibration runs' mean).
    shrunk : float
        Factor (0..1] the update was scaled by to keep every branch slope physical.
    physical : dict
        Interpretable parameters before and after (:func:`.estimator._physical`).
    consistency : dict or None
        With a session: its runs and the consistency residual (units of the training
        scatter, RMS over runs and statistics) before and after the update.
    """

    estimator: CableFrictionObserver
    runs: list
    groups: dict
    coefficients: dict
    target_sign: int
    target_zero_Nm: float
    prior_torque_Nm: float
    shrunk: float
    physical: dict
    consistency: dict | None = None

    def to_json(self) -> dict:
        """Return the calibration as plain JSON types, with units."""
        units = {k: coefficient_unit(k) for k in self.coefficients}
        return {'runs': list(self.runs), 'groups': self.groups,
                'coefficients': self.coefficients, 'coefficient_units': units,
                'physical': self.physical,
                'physical_units': {k: PHYSICAL_UNITS.get(k, '') for k in self.physical},
                'target_sign': self.target_sign,
                'target_zero_Nm': round(self.target_zero_Nm, 7),
                'prior_torque_Nm': round(self.prior_torque_Nm, 6),
                'update_shrunk_to': round(self.shrunk, 4),
                'session_consistency': self.consistency}


def _alias(cache: dict, copy, original) -> list:
    """Point ``copy`` (same motor side, another jaw torque) at the original run's cached signals.

    Returns the keys added, to be removed once ``copy`` is done with (a cache is keyed by
    object id, which Python reuses after an object is freed).
    """
    added = []
    for key in [k for k in cache if isinstance(k, tuple) and len(k) == 2 and k[0] == id(original)
                and cache[k][0] is original]:
        new = (id(copy),) + key[1:]
        cache[new] = (copy, cache[key][1])       # the copy owns its alias (estimator._cached)
        added.append(new)
    return added


def _physical_ok(coef: dict, max_torque: float) -> bool:
    """Check the physics: positive branch slopes, and Coulomb friction positive along the stroke.

    Every branch slope dI/dtau stays positive (0 < eta < 1 locally) over 0..max torque, and
    the Coulomb friction stays positive everywhere along the stroke (|P1 term| < level).
    """
    tau = np.linspace(0.0, max_torque, 50)
    split = coef.get('alpha1', 0.0) + 2.0 * coef.get('alpha1_quad', 0.0) * tau
    closing, opening = coef['alpha0'] + split, coef['alpha0'] - split
    return bool(np.all(opening > 0.05 * coef['alpha0']) and np.all(closing >= opening)
                and coef.get('coulomb', 1.0) - abs(coef.get('friction_P1', 0.0)) > 0)


@dataclass
class Session:
    """The runs of a test folder whose motor side the calibration may read (every run).

    Holds the session consistency residuals at the trained coefficients and their
    derivatives along each group parameter, computed once (:func:`_session_jacobian`).

    Attributes
    ----------
    runs : list of RigRun
        Oriented, tared runs; only their motor-side columns are read.
    """

    runs: list
    _jacobians: dict = field(default_factory=dict, repr=False)


#: Gauss-Newton steps of the session consistency (chord method: the derivatives at the
#: trained coefficients, the residuals re-evaluated at each step).
CONSISTENCY_STEPS = 3
#: Finite-difference step of the session consistency derivatives, in prior widths.
CONSISTENCY_EPS = 0.3


def _group_parameters(coef: dict, names: list, groups: Sequence[str], priors: dict) -> list:
    """(group, parameter label, direction in coefficient space, prior std) of each parameter."""
    out = []
    for g in GROUPS:
        present = [k for k in g.coefficients if k in coef]
        if g.name not in groups or not present:
            continue
        if g.kind == 'scale':                     # one relative factor on the group's terms
            v = np.zeros(len(names))
            for k in present:
                v[names.index(k)] = coef[k]
            out.append((g.name, 'scale', v, priors[g.name]))
        else:                                     # each coefficient shifted (its unit)
            for k in present:
                v = np.zeros(len(names))
                v[names.index(k)] = 1.0
                out.append((g.name, k, v, priors[g.name]))
    return out


def _calibration_rows(est: CableFrictionObserver, cache: dict, cal_runs: Sequence[RigRun],
                      target_sign: int, target_zero: float, theta: np.ndarray):
    """Forward-model rows of the calibration runs: (design, residual, branch of each row)."""
    names = list(est.fit_result.names)
    rows, resid, branches = [], [], []
    for run in cal_runs:
        signed = replace(run, jaw_torque=target_sign * run.jaw_torque - target_zero)
        est._design(run, cache)                   # the original's signals, cached first
        added = _alias(cache, signed, run)
        _, a, y, _ = est._rows(signed, cache)
        resid.append(y - a @ theta)
        # one run holds one load: its torque columns enter at the run's mean torque, so the
        # gain and efficiency groups move only the branch levels at that load (what a run
        # can tell), never fit the within-run torque ripple
        a = a.copy()
        mean_tau = float(np.mean(signed.jaw_torque))
        sig = est._design(signed, cache)[0]
        s_sl = sig.direction[sig.sliding > 0]
        for i, k in enumerate(names):
            if k == 'alpha0':
                a[:, i] = mean_tau
            elif k in ('alpha1', 'alpha2'):
                a[:, i] = s_sl * mean_tau
            elif k == 'alpha1_quad':
                a[:, i] = s_sl * mean_tau ** 2
        rows.append(a)
        branches.append(np.sign(s_sl))
        for key in added:
            cache.pop(key, None)
    return np.vstack(rows), np.concatenate(resid), branches


def _session_jacobian(model: TrainedModel, session: Session, params: list) -> tuple:
    """Session consistency residuals at the trained coefficients and their derivatives.

    One column per parameter of ``params`` (finite differences of :data:`CONSISTENCY_EPS`
    prior widths along its direction), cached on the session by parameter label; zero
    for a group that moves both branches together (``splits_branches`` False): the
    consistency compares the branches and does not inform it.
    """
    est = model.estimator
    names = list(est.fit_result.names)
    theta = est.fit_result.values
    if 'base' not in session._jacobians:
        session._jacobians['base'] = session_residuals(est, session.runs, model.front_end_steps,
                                                       model.cache)
    base = session._jacobians['base']
    cols = []
    splits = {g.name for g in GROUPS if g.splits_branches}
    for gname, label, v, prior in params:
        key = (gname, label)
        if gname not in splits:
            cols.append(np.zeros(base.size))
            continue
        if key not in session._jacobians:
            eps = CONSISTENCY_EPS * prior
            moved = est.with_coefficients(dict(zip(names, theta + eps * v)))
            session._jacobians[key] = (session_residuals(moved, session.runs, model.front_end_steps,
                                                         model.cache) - base) / eps
        cols.append(session._jacobians[key])
    return base, np.column_stack(cols) if cols else np.zeros((base.size, 0))


def calibrate(model: TrainedModel, cal_runs: Sequence[RigRun], *,
              groups: Sequence[str] = GROUP_NAMES, target_sign: int | None = None,
              session: Session | None = None) -> Calibration:
    """Update the per-instrument groups on calibration runs and on the session's motor side.

    Bayesian linear regression of the forward model's residual on the calibration
    runs' sliding samples (their jaw torque is read): one column per group parameter
    (a scale column for ``scale`` groups, one per coefficient for ``shift`` groups), two
    run-offset columns (closing and opening branch) per calibration run with the
    training runs' scatter as their prior (marginalised: never applied), prior widths
    :attr:`TrainedModel.priors`, noise :class:`NoiseModel`. With a ``session``, the
    consistency of every run's two friction branches (:mod:`.consistency`, motor side
    only) adds one row per statistic and run, in units of the training scatter,
    linearised at the trained coefficients (:data:`CONSISTENCY_STEPS` chord steps). The
    update is scaled back if it would make a branch slope unphysical.

    Parameters
    ----------
    model : TrainedModel
        The fit on the training folders (its groups' values are the priors).
    cal_runs : sequence of RigRun
        Oriented, tared runs of the test folder whose jaw torque may be read; may be
        empty with a ``session`` (zero-shot: motor side only).
    groups : sequence of str
        Groups to calibrate (others keep the training value).
    target_sign : int, optional
        Sign of the jaw torque sensor; by default fixed on the calibration runs
        (the sign of their mean jaw torque: the jaw holds a closing torque), +1 (the
        header's convention) without calibration runs.
    session : Session, optional
        The test folder's runs whose motor side the update may read.

    Returns
    -------
    Calibration
    """
    if not cal_runs and session is None:
        raise EstimatorError('calibrate needs a calibration run or a session')
    unknown = set(groups) - set(GROUP_NAMES)
    if unknown:
        raise EstimatorError(f'unknown calibration groups {sorted(unknown)}; one of {GROUP_NAMES}')
    est, cache, noise = model.estimator, model.cache, model.noise
    if target_sign is None:
        mean_tau = np.mean([np.mean(r.jaw_torque) for r in cal_runs]) if cal_runs else 1.0
        target_sign = 1 if mean_tau >= 0 else -1
    gain = model.front_end.get('gain_Nm_per_A', float('nan'))
    target_zero = float(np.mean([target_sign * np.mean(r.jaw_torque)
                                 - gain * abs(float(np.mean(r.load_command)))
                                 for r in cal_runs])) if cal_runs and np.isfinite(gain) else 0.0
    coef = est.coefficients
    names = list(est.fit_result.names)
    theta = np.array([coef[k] for k in names])
    params = _group_parameters(coef, names, groups, model.priors)
    n_update = len(params)
    prior = [p[3] for p in params]
    blocks = []                                   # (design, residual, weight) of each row set
    if cal_runs:
        a_all, r_all, branches = _calibration_rows(est, cache, cal_runs, target_sign, target_zero,
                                                   theta)
        cols = [a_all @ v for _, _, v, _ in params]
        start = 0
        for br in branches:                      # run-level offsets per branch, marginalised
            for side in (1, -1):
                col = np.zeros(r_all.size)
                col[start:start + br.size] = (br == side)
                cols.append(col)
                prior.append(max(noise.run_offset_std_A, 1e-6))
            start += br.size
        weight = (C.SAMPLE_PERIOD / noise.correlation_s) / noise.white_std_A ** 2
        blocks.append((np.column_stack(cols), r_all, weight))
    precision = np.diag(1.0 / np.square(prior))
    rhs = np.zeros(len(prior))
    for x, r, w in blocks:
        precision += w * (x.T @ x)
        rhs += w * (x.T @ r)
    full = np.linalg.solve(precision, rhs) if n_update else np.zeros(len(prior))
    consistency = None
    if session is not None and n_update and model.front_end_steps is not None:
        base, jac = _session_jacobian(model, session, params)
        jac = np.column_stack([jac, np.zeros((jac.shape[0], len(prior) - n_update))])
        consistency = {'runs': len(session.runs), 'rms_before': float(np.sqrt(np.mean(base ** 2)))}
        full, current = np.zeros(len(prior)), base
        for _ in range(CONSISTENCY_STEPS):       # chord steps: rows c(full) + J (delta - full) = 0
            full = np.linalg.solve(precision + jac.T @ jac, rhs + jac.T @ (jac @ full - current))
            step = sum((d * p[2] for d, p in zip(full[:n_update], params)), np.zeros(len(names)))
            moved = est.with_coefficients(dict(zip(names, theta + step)))
            current = session_residuals(moved, session.runs, model.front_end_steps, cache)
        consistency['rms_after'] = float(np.sqrt(np.mean(current ** 2)))
        precision = precision + jac.T @ jac
    cov = np.linalg.inv(precision) if n_update else np.zeros((0, 0))
    delta, post_std = full[:n_update], np.sqrt(np.diag(cov))[:n_update]
    step = sum((d * p[2] for d, p in zip(delta, params)), np.zeros(len(names)))
    shrink = 1.0
    while shrink > 1e-3 and not _physical_ok(dict(zip(names, theta + shrink * step)),
                                             model.max_torque_Nm):
        shrink *= 0.5
    if not _physical_ok(dict(zip(names, theta + shrink * step)), model.max_torque_Nm):
        shrink = 0.0
    new = theta + shrink * step
    prior_torque = float(np.mean([target_sign * np.mean(r.jaw_torque) - target_zero
                                  for r in cal_runs])) if cal_runs else est.prior_torque
    calibrated = est.with_coefficients(dict(zip(names, new)), prior_torque=prior_torque)
    report: dict = {}
    for (gname, what, _, _), d, sd in zip(params, delta, post_std):
        g = next(gr for gr in GROUPS if gr.name == gname)
        entry = report.setdefault(gname, {'unit': g.unit, 'kind': g.kind, 'meaning': g.meaning,
                                          'prior_std': model.priors[gname], 'parameters': {}})
        entry['parameters'][what] = {'value': float(shrink * d), 'std': float(sd)}
    coefficients = {k: {'trained': float(t), 'calibrated': float(c)}
                    for k, t, c in zip(names, theta, new)}
    physical = {k: {'trained': float(est.fit_result.physical[k][0]),
                    'calibrated': float(calibrated.fit_result.physical[k][0])}
                for k in est.fit_result.physical}
    return Calibration(calibrated, [r.file or r.name for r in cal_runs], report, coefficients,
                       int(target_sign), target_zero, prior_torque, shrink, physical, consistency)


# -- choosing the calibration run ------------------------------------------------------------------
def _lower_median(values):
    values = sorted(set(values))
    return values[(len(values) - 1) // 2]


def default_calibration_run(runs: Sequence[RigRun]) -> RigRun:
    """Pick the run a lab would record once per instrument: mid frequency, mid load, mid stop.

    From the file names and headers only (never from the data): the lower median of
    the folder's sine frequencies, of its resisting-torque levels and (ZXY folders) of
    its jaw stopping positions. Why: one run at one load cannot separate the gain and
    efficiency from the offsets (a constant load is collinear with a constant), so
    what the calibration gets wrong grows with |tau - tau_cal|: a mid-range load
    halves the worst lever arm over the folder's loads, and stays inside the load
    range the training folders taught; a mid frequency keeps the stroke speed (viscous
    and dynamic effects) typical.
    """
    freq = _lower_median(r.frequency_hz for r in runs)
    level = _lower_median(r.torque_level_percent for r in runs)
    yaws = [r.yaw_step for r in runs if r.yaw_step is not None]
    yaw = _lower_median(yaws) if yaws else None

    def distance(r):
        return (abs(r.frequency_hz - freq) / max(freq, 1e-9) + abs(r.torque_level_percent - level)
                / max(level, 1e-9) + (0 if yaw is None or r.yaw_step is None
                                      else abs(r.yaw_step - yaw)), r.name)
    return min(runs, key=distance)


DEFAULT_RULE = ('lower median of the folder\'s sine frequencies, of its resisting-torque levels '
                'and of its jaw stopping positions (file names and headers only)')


# -- scoring ---------------------------------------------------------------------------------------
#: Seconds at the start of a run left out of the session prior (the estimate there is the prior).
SESSION_PRIOR_SKIP_S = C.STARTUP_S


def predict_session(est: CableFrictionObserver, runs: Sequence[RigRun],
                    cache: dict | None = None, *, offline: bool = False) -> tuple[list, float]:
    """Predictions (N*m) of a folder's runs with the session's start-up estimate.

    Before the first sliding sample of a run nothing is known about its load; the
    estimate there is the mean estimate of the same folder's runs after their first
    second (a first pass, motor side only), not the training folders' mean torque
    (65.7 mN*m in ``Tool_4_Maryland_L_4`` against 29.5 in ``L_2``). After the first
    sliding sample the observer has forgotten its start value, so the second pass
    only rewrites each run's start. ``offline``: the estimate of recorded runs
    (:meth:`.estimator.CableFrictionObserver.predict`), whose start takes the level the
    run shows once it slides; the session's estimate then only fills a run that never
    slides.

    Returns
    -------
    (list of ndarray, float)
        Predictions per run, and the session's start-up estimate (N*m).
    """
    firsts, preds, means = [], [], []
    for run in runs:
        pred = est.predict(run, cache=cache, offline=offline)
        _, weight, _ = est.inversion(run, cache=cache)
        on = np.flatnonzero(weight > 0)
        firsts.append(int(on[0]) if on.size else pred.size)
        preds.append(pred)
        late = pred[np.asarray(run.t) - run.t[0] >= SESSION_PRIOR_SKIP_S]
        if late.size:
            means.append(float(np.mean(late)))
    prior = float(np.mean(means)) if means else est.prior_torque
    out = []
    for pred, first in zip(preds, firsts):
        pred = pred.copy()
        if not offline or first == pred.size:      # offline: the run's own level fills its start
            pred[:first] = prior
        out.append(pred)
    return out, prior


def score(est: CableFrictionObserver, runs: Sequence[RigRun], target_sign: int = 1,
          cache: dict | None = None, *, target_zero: float = 0.0,
          session_prior: bool = True, offline: bool = False) -> dict:
    """Held-out RMSE over every sample of ``runs`` and per run (N*m).

    The target is ``target_sign * jaw_torque - target_zero`` (N*m). ``session_prior``:
    the start of each run at the folder's mean estimate (:func:`predict_session`),
    else at the estimator's own prior. Also the RMSE after each run's first
    :data:`.constants.STARTUP_S` and the start-up's part: the samples before each run's
    first sliding sample (the estimate is the start-up value there) and their share of
    the squared error. ``offline``: the estimate of recorded runs (:func:`predict_session`).
    """
    if session_prior:
        preds, prior = predict_session(est, runs, cache, offline=offline)
    else:
        preds = [est.predict(run, cache=cache, offline=offline) for run in runs]
        prior = est.prior_torque
    se_total, n_total, per_run = 0.0, 0, []
    se_late = n_late = se_start = n_start = 0.0
    for run, pred in zip(runs, preds):
        err = pred - (target_sign * run.jaw_torque - target_zero)
        se, n = float(np.sum(err * err)), int(err.size)
        se_total += se
        n_total += n
        per_run.append({'file': run.file or run.name, 'rmse': math.sqrt(se / n)})
        late = run.t - run.t[0] >= C.STARTUP_S
        se_late += float(np.sum(err[late] ** 2))
        n_late += int(late.sum())
        sliding = np.flatnonzero(est.inversion(run, cache=cache)[1] > 0)
        first = int(sliding[0]) if sliding.size else err.size
        se_start += float(np.sum(err[:first] ** 2))
        n_start += first
    return {'heldout_rmse': math.sqrt(se_total / n_total), 'per_run': per_run,
            'startup_estimate_Nm': prior,
            'heldout_rmse_after_startup': math.sqrt(se_late / max(n_late, 1)),
            'startup': {'fraction_of_samples': n_start / n_total,
                        'share_of_squared_error': se_start / se_total if se_total else 0.0}}


def sweep(model: TrainedModel, test: Folder, *, groups: Sequence[str] = GROUP_NAMES,
          candidates: Sequence[RigRun] | None = None, session: Session | None = None,
          offline: bool = False) -> dict:
    """Held-out RMSE with every single run of ``test`` as the calibration run in turn.

    ``session``: the test folder's motor side in the update as well (:func:`calibrate`).
    Returns mean, worst and best over the candidates, each candidate's figure, and
    the worst single scored run over all candidates (N*m).
    """
    cache = model.cache
    candidates = list(candidates or test.runs)
    rows = []
    worst_run = {'rmse': -1.0}
    for cal in candidates:
        calib = calibrate(model, [cal], groups=groups, session=session)
        scored = [r for r in test.runs if r is not cal]
        res = score(calib.estimator, scored, calib.target_sign, cache,
                    target_zero=calib.target_zero_Nm, offline=offline)
        rows.append({'calibration_run': cal.file or cal.name, 'heldout_rmse': res['heldout_rmse']})
        top = max(res['per_run'], key=lambda p: p['rmse'])
        if top['rmse'] > worst_run['rmse']:
            worst_run = dict(top, calibration_run=cal.file or cal.name)
    values = np.array([r['heldout_rmse'] for r in rows])
    return {'candidates': rows, 'mean': float(values.mean()), 'worst': float(values.max()),
            'best': float(values.min()), 'worst_single_run': worst_run}


def ablation(model: TrainedModel, test: Folder, cal_runs: Sequence[RigRun], *,
             sweep_candidates: Sequence[RigRun] | None = None,
             session: Session | None = None, offline: bool = False) -> list[dict]:
    """Held-out RMSE with each group calibrated alone, and with all but one.

    On the given calibration run(s), and (when ``sweep_candidates``) the mean over
    those candidates as the single calibration run. With a ``session``, every row
    updates on the calibration run and the session consistency together, and two rows
    more take one source away: ``all, calibration run only`` and ``all, session
    consistency only`` (the calibration run then fixes only the sensor's sign and zero).
    """
    configs = [('none (zero-shot)', (), session)] + \
        [(f'only {g}', (g,), session) for g in GROUP_NAMES] + \
        [(f'all but {g}', tuple(x for x in GROUP_NAMES if x != g), session) for g in GROUP_NAMES] + \
        [('all', GROUP_NAMES, session)]
    if session is not None:
        configs += [('all, calibration run only', GROUP_NAMES, None),
                    ('all, session consistency only', GROUP_NAMES, 'consistency only')]
    cal_ids = {id(r) for r in cal_runs}
    scored = [r for r in test.runs if id(r) not in cal_ids]
    out = []
    for label, groups, source in configs:
        if source == 'consistency only':
            jig = calibrate(model, cal_runs, groups=())                 # sign and zero only
            est = calibrate(model, [], groups=groups, session=session).estimator
            sign, zero = jig.target_sign, jig.target_zero_Nm
        else:
            calib = calibrate(model, cal_runs, groups=groups, session=source)
            est, sign, zero = calib.estimator, calib.target_sign, calib.target_zero_Nm
        row = {'groups': label, 'calibrated': list(groups),
               'heldout_rmse': score(est, scored, sign, model.cache, target_zero=zero,
                                     offline=offline)['heldout_rmse']}
        if sweep_candidates and source != 'consistency only':
            sw = sweep(model, test, groups=groups, candidates=sweep_candidates, session=source,
                       offline=offline)
            row['sweep_mean'] = sw['mean']
            row['sweep_worst'] = sw['worst']
        out.append(row)
    return out


def transfer(train_folders: Sequence, test_folder, *, calibrate_runs: Sequence[str] = (),
             groups: Sequence[str] = GROUP_NAMES, with_sweep: bool = False,
             with_ablation: bool = False, settings: ObserverSettings | None = None,
             consistency: bool = True, offline: bool = False, progress=None) -> dict:
    """Run the whole transfer evaluation, JSON-ready (the ``grip-force realdata --train`` result).

    Parameters
    ----------
    train_folders : sequence of str or Path
        Folders whose jaw torque the fit reads.
    test_folder : str or Path
        Folder to judge on.
    calibrate_runs : sequence of str
        Runs of the test folder to calibrate on (names, file names, or ``'auto'``
        for :func:`default_calibration_run`); empty = zero-shot.
    groups : sequence of str
        Calibration groups.
    with_sweep, with_ablation : bool
        Also every single calibration run in turn / the group ablation.
    settings : ObserverSettings, optional
        Observer settings of the fit (default: :data:`TRANSFER_SETTINGS`).
    consistency : bool
        Update on the session consistency of the test folder's runs (motor side only,
        :mod:`.consistency`) as well, zero-shot and calibrated; False: the calibration
        run alone, and zero-shot the trained model as it is.
    offline : bool
        Score the offline estimate of the recorded runs (the observer forward and
        backward in time) instead of the real-time, causal one.
    progress : callable, optional
        ``progress(message)`` at each stage.
    """
    say = progress or (lambda msg: None)
    started = time.perf_counter()
    say('reading and orienting the folders')
    trains = [load_folder(f) for f in train_folders]
    test = load_folder(test_folder)
    if any(t.path.resolve() == test.path.resolve() for t in trains):
        raise RigDataError(f'{test.path}: the test folder is also a training folder')
    say('fitting on the training folders')
    model = train(trains, settings)
    est, cache = model.estimator, model.cache
    zero_shot_sign = 1
    session = Session(test.runs) if consistency else None
    cal_runs: list = []
    for key in calibrate_runs:
        run = default_calibration_run(test.runs) if key == 'auto' else test.run(key)
        if all(run is not c for c in cal_runs):
            cal_runs.append(run)
    cal_ids = {id(r) for r in cal_runs}
    scored = [r for r in test.runs if id(r) not in cal_ids]
    say(f'scoring {len(scored)} runs of {test.name}')
    self_calibrated = calibrate(model, [], groups=groups, session=session) if session else None
    zero = score(self_calibrated.estimator if session else est, scored, zero_shot_sign, cache,
                 offline=offline)
    result = {
        'train': [_folder_json(f) for f in trains],
        'test': _folder_json(test),
        'zero_shot': not cal_runs,
        'estimate': 'offline (forward and backward in time)' if offline else 'real-time (causal)',
        'published_rmse_mNm': C.PUBLISHED_RMSE_NM * 1e3,
        'model': {'settings': {k: getattr(est.settings, k) for k in est.settings.__dataclass_fields__},
                  'coefficients': est.coefficients,
                  'physical': {k: {'value': float(v), 'std': float(s)}
                               for k, (v, s) in est.fit_result.physical.items()},
                  'per_training_folder': model.per_folder,
                  'calibration_priors': model.priors,
                  'noise': vars(model.noise), 'training_max_torque_Nm': model.max_torque_Nm,
                  'front_end_reference': model.front_end,
                  'front_end_steps': model.front_end_steps.to_json(),
                  'prior_torque_Nm': est.prior_torque,
                  # the held load's shape along the stroke (None: off in these settings)
                  'load_model': est.load_model.to_json() if est.load_model is not None else None},
        'session_consistency': {
            'used': session is not None,
            'zero_shot_update': ({'groups': self_calibrated.groups,
                                  'consistency': self_calibrated.consistency,
                                  'physical': self_calibrated.physical}
                                 if self_calibrated else None)},
        'target': {
            'zero_shot': 'jaw torque sensor as recorded (firmware tare at session start), sign '
                         'of the header spindle convention (right spindle negated as upstream)',
            'calibrated': 'sign * sensor - zero: the sign fixed by the calibration run (its '
                          'mean jaw torque is a closing torque, > 0), the zero found on it '
                          'against the resisting motor (mean reading - front-end gain x '
                          'command; the gain fitted on the training folders)',
            'samples': 'every sample of every scored run (start-up included)',
            'startup': 'before the first sliding sample of a run the estimate is the mean '
                       'estimate of the folder\'s runs after their first second (motor side, '
                       'first pass)',
            'session': 'every run\'s motor side (never its jaw side) may move the calibration '
                       'groups through the consistency of its two friction branches'},
    }
    if cal_runs:
        say('calibrating on ' + ', '.join(r.file or r.name for r in cal_runs))
        calib = calibrate(model, cal_runs, groups=groups, session=session)
        res = score(calib.estimator, scored, calib.target_sign, cache,
                    target_zero=calib.target_zero_Nm, offline=offline)
        result['calibration'] = calib.to_json()
        result['calibration']['rule'] = DEFAULT_RULE if 'auto' in calibrate_runs else 'given'
        result['calibration']['default_rule_run'] = default_calibration_run(test.runs).file
        result['heldout_rmse'] = res['heldout_rmse']
        result['per_run'] = res['per_run']
        result['zero_shot_heldout_rmse'] = zero['heldout_rmse']
    else:
        result['calibration'] = None
        res = zero
        result['heldout_rmse'] = zero['heldout_rmse']
        result['per_run'] = zero['per_run']
    result['startup_estimate_Nm'] = res['startup_estimate_Nm']
    result['heldout_rmse_after_startup'] = res['heldout_rmse_after_startup']
    result['startup'] = res['startup']
    result['heldout_rmse_mNm'] = round(result['heldout_rmse'] * 1e3, 3)
    result['worst_run'] = max(result['per_run'], key=lambda p: p['rmse'])
    result['beats_published'] = bool(result['heldout_rmse'] <= C.PUBLISHED_RMSE_NM)
    if with_sweep:
        say(f'sweep: each of the {len(test.runs)} runs as the calibration run')
        result['sweep'] = sweep(model, test, groups=groups, session=session, offline=offline)
        result['sweep']['default_rule_run'] = default_calibration_run(test.runs).file
    if with_ablation:
        say('ablation of the calibration groups')
        base = cal_runs or [default_calibration_run(test.runs)]
        result['ablation'] = {'calibration_runs': [r.file for r in base],
                              'rows': ablation(model, test, base,
                                               sweep_candidates=test.runs if with_sweep else None,
                                               session=session, offline=offline)}
    result['runtime_s'] = round(time.perf_counter() - started, 2)
    return result


def _folder_json(folder: Folder) -> dict:
    return {'folder': folder.name, 'path': str(folder.path), 'runs': len(folder.runs),
            'files': [r.file for r in folder.runs], 'spindle': folder.spindle,
            'spindle_source': folder.spindle_source,
            'current_tare': vars(folder.tare) if folder.tare else None,
            'motor_side_orientation': folder.orientation,
            'load_levels_percent': sorted({r.torque_level_percent for r in folder.runs}),
            'frequencies_hz': sorted({r.frequency_hz for r in folder.runs})}
