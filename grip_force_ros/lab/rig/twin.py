"""An instrument twin from rig runs: the transmission terms of the schema, fitted, with their std.

``grip-force twin --rig DIR [DIR ...] --base X.yaml --out Y.yaml`` fits the rig's
forward model (:class:`~grip_force_ros.lab.rig.estimator.CableFrictionObserver` with the
transfer model's terms: direction- and load-dependent efficiency, Coulomb friction and its
change along the stroke, Dahl state, position spring, viscous friction) on every run of the
folders, maps its coefficients to the instrument parameters of ``model/jaw_friction.py`` and
the pulley chain, and writes the base file with those values. The map (G the loss-free gain
in N*m/A, eta the one-way efficiency, b1, P1, P2, f1, c, q the fitted coefficients in A,
A*s/rad and A/(N*m)^2; x in [-1, 1] the Legendre argument of the disk angle over
:data:`~grip_force_ros.lab.rig.estimator.POSITION_RANGE`, x = -(phi - phi_r)/h with h the jaw
angle over half the disk range and phi_r the jaw angle mid-range):

====================================  ==========================================
parameter                             from the fit
====================================  ==========================================
``drum_radius``                       K N rn / G (K, N, rn from the base file)
``pulley_friction_coefficient``       the mu whose chain efficiency (base routing) is eta
``jaw_coulomb_friction``              G b1 (at phi_r)
``jaw_coulomb_friction_slope``        -G f1 / h
``jaw_spring_torque``                 -G P2 / 2
``jaw_spring_slope``                  -G P1 / h
``jaw_spring_curvature``              1.5 G P2 / h^2
``jaw_spring_rest_angle``             phi_r
``jaw_viscous_friction``              G c / slope (0 when the fit is negative: not a damping)
``jaw_efficiency_load_gain``          2 G q / (eta + 1/eta)
``jaw_friction_width``                the Dahl width chosen by cross-validation on the
                                      training runs (grid :data:`WIDTH_GRID`)
====================================  ==========================================

Standard deviations: leave-one-run-out jackknife of each mapped parameter. The held-out
RMSE: fitted on the even load steps of every folder, scored (causal estimate, every sample)
on the odd ones. What the rig cannot give (the jaw's moment arms: it measures torque, not
force; the cable routing; the motor constants; the limits and gains) stays the base file's
and is listed as assumed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Callable, Mapping, Sequence

import numpy as np
from scipy.optimize import brentq

from grip_force_ros.lab.rig.estimator import POSITION_RANGE, CableFrictionObserver, EstimatorError
from grip_force_ros.lab.rig.transfer import TRANSFER_SETTINGS, load_folder
from grip_force_ros.model.friction import chain_efficiency
from grip_force_ros.params import SPECS, specs_in

#: The forward model identified: the transfer model's terms, without the rig's load model
#: (that is the rig's resisting motor, not the instrument).
TWIN_SETTINGS = replace(TRANSFER_SETTINGS, load_model=False)
#: Dahl widths tried (rad of the drive angle).
WIDTH_GRID = (0.01, 0.02, 0.03, 0.05, 0.08)
#: The parameters a twin identifies, in the order they are written.
IDENTIFIED = ('drum_radius', 'pulley_friction_coefficient', 'jaw_coulomb_friction',
              'jaw_coulomb_friction_slope', 'jaw_friction_width', 'jaw_spring_torque',
              'jaw_spring_slope', 'jaw_spring_curvature', 'jaw_spring_rest_angle',
              'jaw_viscous_friction', 'jaw_efficiency_load_gain')


@dataclass
class Twin:
    """An identified instrument.

    Attributes
    ----------
    parameters : dict of str to dict
        Name -> ``{'value', 'std', 'unit', 'source'}`` for every :data:`IDENTIFIED` parameter
        (``std`` None where it is not a statistical figure: a grid choice).
    heldout_rmse : float
        Jaw torque RMSE (N*m) on the odd load steps of a twin fitted on the even ones.
    heldout_rmse_after_startup : float
        The same without each run's first second (N*m).
    cross_validation : dict
        RMSE (N*m) of every candidate term structure and Dahl width (:func:`choose_structure`).
    folders : list of str
        The rig folders, with their runs and the current sensor zero removed from each.
    assumed : list of str
        Instrument parameters the rig cannot give: kept from the base file.
    notes : list of str
        What a fitted value means beyond its line (a clipped term, a session quantity).
    """

    parameters: dict
    heldout_rmse: float
    heldout_rmse_after_startup: float
    cross_validation: dict = field(default_factory=dict)
    folders: list = field(default_factory=list)
    assumed: list = field(default_factory=list)
    notes: list = field(default_factory=list)

    def to_json(self) -> dict:
        """Return the ``--json`` answer: ``{parameters, heldout_rmse, ...}`` (SI units, N*m for RMSE)."""
        return {'parameters': self.parameters, 'heldout_rmse': self.heldout_rmse,
                'heldout_rmse_after_startup': self.heldout_rmse_after_startup,
                'cross_validation': self.cross_validation,
                'folders': self.folders, 'assumed': self.assumed, 'notes': self.notes}


def _geometry(runs: Sequence) -> tuple[float, float]:
    """Jaw angle per disk angle (rad/rad, > 0) and the jaw angle mid-range (rad), mean of the runs."""
    mid = 0.5 * (POSITION_RANGE[0] + POSITION_RANGE[1])
    fits = [np.polyfit(r.motor_angle, r.jaw_angle, 1) for r in runs]
    slope = float(np.mean([-f[0] for f in fits]))
    rest = float(np.mean([f[1] + f[0] * mid for f in fits]))
    return slope, rest


def _mu_for_efficiency(eta: float, base: Mapping) -> float:
    """Pulley friction coefficient (-) whose zero-load chain efficiency is ``eta`` on the base routing."""
    radii = base['guide_pulley_radii']
    wraps = list(base['guide_pulley_wrap_angles'])

    def gap(mu: float) -> float:
        return float(chain_efficiency(mu, radii, base['cable_radius'], wraps)) - eta
    hi = SPECS['pulley_friction_coefficient'].max or 1.0
    if not 0.0 < eta < 1.0 or gap(0.0) * gap(hi) > 0:
        raise EstimatorError(f'one-way efficiency {eta:.3f} cannot be given by a pulley friction '
                             f'coefficient in [0, {hi}] on the base routing')
    return brentq(gap, 0.0, hi, xtol=1e-7)


def schema_terms(est: CableFrictionObserver, base: Mapping, slope: float, rest: float) -> dict:
    """Map one fit's coefficients to instrument parameters (SI units; see the module table)."""
    coef = est.coefficients
    phys = {k: v[0] for k, v in est.fit_result.physical.items()}
    gain, eta = phys['gain_Nm_per_A'], phys['efficiency']
    half = slope * 0.5 * (POSITION_RANGE[1] - POSITION_RANGE[0])     # rad of jaw per unit of x
    p1, p2 = coef.get('spring_P1', 0.0), coef.get('spring_P2', 0.0)
    quad = coef.get('alpha1_quad', 0.0)
    viscous = coef.get('viscous', 0.0) * gain / slope
    return {
        'drum_radius': base['torque_constant'] * base['gear_ratio'] * base['drive_pulley_radius'] / gain,
        'pulley_friction_coefficient': _mu_for_efficiency(eta, base),
        'jaw_coulomb_friction': coef.get('coulomb', 0.0) * gain,
        'jaw_coulomb_friction_slope': -gain * coef.get('friction_P1', 0.0) / half,
        'jaw_friction_width': est.settings.hysteresis_width,
        'jaw_spring_torque': -gain * p2 / 2.0,
        'jaw_spring_slope': -gain * p1 / half,
        'jaw_spring_curvature': 1.5 * gain * p2 / half ** 2,
        'jaw_spring_rest_angle': rest,
        'jaw_viscous_friction': max(viscous, 0.0),
        'jaw_efficiency_load_gain': 2.0 * gain * quad / (eta + 1.0 / eta),
        '_viscous_fitted': viscous,
    }


def _rmse(est: CableFrictionObserver, runs: Sequence, cache: dict, skip_s: float = 0.0) -> float:
    se, n = 0.0, 0
    for r in runs:
        err = (est.predict(r, cache=cache) - r.jaw_torque)[r.t - r.t[0] >= skip_s]
        se += float(np.sum(err ** 2))
        n += err.size
    return math.sqrt(se / n)


#: Relative cross-validated RMSE a term must save to be kept.
MIN_GAIN = 0.02
#: Term structures tried: (load-dependent efficiency, order of the friction along the stroke).
STRUCTURES = ((False, 0), (True, 0), (False, 1), (True, 1))


def _terms(settings) -> int:
    return int(settings.load_dependent_efficiency) + int(settings.friction_map_order > 0)


def choose_structure(train: Sequence, cache: dict) -> tuple:
    """Choose the terms and the Dahl width with the best cross-validated RMSE on ``train``.

    Each candidate (:data:`STRUCTURES` x :data:`WIDTH_GRID`) is fitted with one run of
    ``train`` left out at a time and scored on it (causal estimate, every sample); the
    held-out runs of the twin never take part. A term is kept only when it lowers the
    cross-validated RMSE by :data:`MIN_GAIN` or more (the simpler structure otherwise).

    Returns
    -------
    (ObserverSettings, dict)
        The chosen settings and every candidate's RMSE (N*m) keyed by
        ``'efficiency_load=<bool> friction_map=<order> width=<rad>'``.
    """
    folds = [[r] for r in train]
    scores = {}
    for quad, order in STRUCTURES:
        for width in WIDTH_GRID:
            settings = replace(TWIN_SETTINGS, load_dependent_efficiency=quad,
                               friction_map_order=order, hysteresis_width=width)
            se, n = 0.0, 0
            for fold in folds:
                held = {id(r) for r in fold}
                est = CableFrictionObserver(settings).fit([r for r in train if id(r) not in held],
                                                          cache=cache)
                for r in fold:
                    err = est.predict(r, cache=cache) - r.jaw_torque
                    se += float(np.sum(err ** 2))
                    n += err.size
            scores[settings] = math.sqrt(se / n)
    best = None
    for settings in sorted(scores, key=lambda s: (s.load_dependent_efficiency + (s.friction_map_order > 0))):
        if best is None or scores[settings] < (1.0 - MIN_GAIN) * scores[best] or (
                _terms(settings) == _terms(best) and scores[settings] < scores[best]):
            best = settings
    return best, {f'efficiency_load={s.load_dependent_efficiency} friction_map='
                  f'{s.friction_map_order} width={s.hysteresis_width}': v for s, v in scores.items()}


def identify(directories: Sequence, base: Mapping, *,
             progress: Callable[[str], None] | None = None) -> Twin:
    """Identify an instrument twin from rig folders.

    Parameters
    ----------
    directories : sequence of path-like or str
        Rig folders (paths, or names under the data set's root).
    base : mapping
        The base instrument's parameter values (``read_params_yaml`` of ``--base``): the
        motor constants and routing the map needs, and what the rig cannot give.
    progress : callable, optional
        Called with one line per stage.

    Returns
    -------
    Twin
    """
    say = progress or (lambda msg: None)
    folders = [load_folder(d) for d in directories]
    runs = [r for f in folders for r in f.runs]
    train = [r for r in runs if r.torque_step % 2 == 0]
    test = [r for r in runs if r.torque_step % 2 == 1]
    if not train or not test:
        raise EstimatorError('a twin needs runs at two load steps at least (even ones to fit, '
                             'odd ones to score)')
    cache: dict = {}
    say(f'{len(runs)} runs in {len(folders)} folders; choosing the terms and the Dahl width '
        f'by leave-one-run-out cross-validation on the {len(train)} training runs')
    settings, cv = choose_structure(train, cache)
    held = CableFrictionObserver(settings).fit(train, cache=cache)
    heldout = _rmse(held, test, cache)
    heldout_late = _rmse(held, test, cache, skip_s=1.0)
    say(f'width {settings.hysteresis_width} rad, load-dependent efficiency '
        f'{settings.load_dependent_efficiency}, friction map order {settings.friction_map_order}; '
        f'held-out RMSE {heldout * 1e3:.2f} mN*m; fitting every run '
        f'and its jackknife')
    slope, rest = _geometry(runs)
    full = schema_terms(CableFrictionObserver(settings).fit(runs, cache=cache), base, slope, rest)
    jack = []
    for i in range(len(runs)):
        rest_runs = runs[:i] + runs[i + 1:]
        s_i, r_i = _geometry(rest_runs)
        jack.append(schema_terms(CableFrictionObserver(settings).fit(rest_runs, cache=cache),
                                 base, s_i, r_i))
    n = len(jack)
    names = ', '.join(f.name for f in folders)
    parameters = {}
    for name in IDENTIFIED:
        values = np.array([j[name] for j in jack])
        std = math.sqrt((n - 1) / n * float(np.sum((values - values.mean()) ** 2)))
        source = f'TWIN of {names}'
        if name == 'jaw_friction_width':
            std = None
            source += (f': cross-validated on the training runs over the grid '
                       f'{", ".join(map(str, WIDTH_GRID))} rad')
        if name == 'jaw_efficiency_load_gain' and not settings.load_dependent_efficiency:
            source += ': not chosen by the cross-validation (0)'
        if name == 'jaw_coulomb_friction_slope' and not settings.friction_map_order:
            source += ': not chosen by the cross-validation (0)'

        parameters[name] = {'value': float(full[name]), 'std': std, 'unit': SPECS[name].unit,
                            'source': source}
    notes = ['current sensor zero removed per folder: ' + ', '.join(
        f'{f.name} {f.tare.zero_A * 1e3:.1f} mA' for f in folders) + ' (a per-session tare, not '
        'an instrument parameter)']
    if full['_viscous_fitted'] < 0:
        notes.append(f"jaw_viscous_friction: the fit gives {full['_viscous_fitted']:.4g} N*m*s/rad "
                     '(friction falling with speed, Stribeck-like): not a damping, written as 0')
    assumed = [s.name for s in specs_in('instrument') if s.name not in IDENTIFIED]
    return Twin(parameters, heldout, heldout_late, cv,
                [{'folder': f.name, 'runs': len(f.runs), 'current_zero_A': f.tare.zero_A}
                 for f in folders], assumed, notes)


def write(twin: Twin, base, out) -> None:
    """Write the twin's instrument file: ``base`` with the identified values (validated)."""
    from grip_force_ros.params import rewrite_instrument_file
    from pathlib import Path
    values = {'instrument_name': (Path(out).stem, 'the twin file name')}
    for name, p in twin.parameters.items():
        spread = '' if p['std'] is None else f" +- {p['std']:.3g}"
        values[name] = (float(f"{p['value']:.6g}"), f"{p['source']}{spread}")
    header_start = '# Instrument twin ('
    header = (f"{header_start}`grip-force twin`, held-out jaw torque RMSE "
              f"{twin.heldout_rmse * 1e3:.2f} mN*m): {', '.join(IDENTIFIED)} fitted on "
              f"{', '.join(f['folder'] for f in twin.folders)}; every other number ASSUMED as "
              f"in the base file (the jaw's moment arms among them: the rig measures torque)")
    rewrite_instrument_file(base, out, values, header, replaces=header_start)
