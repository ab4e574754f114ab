"""Re-identify the instrument's own parameters before looking for an unmodelled effect.

A real instrument never matches its YAML. A pulley friction 15 % off changes the width of
the capstan stick band (the unloading branch sits at ``1/lambda^2`` of the loading one), and
a calibrated force gain alone cannot follow that: the residual then looks like a cable
hysteresis. So the diagnosis first fits the instrument's parameters to the logs
(:data:`REIDENTIFIED`: pulley friction, cable stiffness, torque gain, wrist-finger coupling)
with the one fitter of schema parameters (:func:`grip_force_ros.identify.fit_parameters`),
and every effect must then beat the re-identified model on held-out data.

What each parameter moves (units of the schema):

- ``pulley_friction_coefficient`` mu: the chain efficiency lambda, so the loading gain
  ``r_n F0 (lambda - f)`` and the stick band ``lambda T0 <= Tn <= T0/lambda``;
- ``torque_constant`` K: the drum tension per ampere (the force gain);
- ``cable_modulus`` E (the cable stiffness ``E A / L``; A and L held): the jaw angle the
  cable's stretch adds, ``(L_d T0 + L_j Tn) / (E A r_n)``, and how fast the wrist moves a
  stuck cable across the band;
- ``wrist_finger_coupling`` c: the jaw angle per rad of wrist (and the cable the wrist pulls).

Each channel fits what it sees (:func:`reidentify`): the jaw angle the stiffness and the
coupling (linear in them), the measured column the friction and the torque constant
(robust nonlinear least squares), on the training samples the fits may use. Standard
errors: a moving-block bootstrap over time blocks (20 per log; the residuals of a time
series are not independent), of the fit linearised at the solution for the nonlinear pair.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from grip_force_ros.lab.diagnosis.fitting import HUBER_K
from grip_force_ros.lab.diagnosis.frame import nominal
from grip_force_ros.identify import CalibrationError, block_bootstrap_std, fit_parameters
from grip_force_ros.params import SPECS

__all__ = ['REIDENTIFIED', 'RELATIVE', 'MAX_FACTOR', 'MAX_COUPLING_CHANGE', 'MIN_WRIST_STD', 'OFF_FRACTION',
           'OFF_SIGMAS', 'BOOTSTRAP_BLOCKS', 'Reidentified', 'reidentify', 'robust_scale']

#: The instrument parameters the diagnosis re-identifies (schema names, report order).
REIDENTIFIED = ('pulley_friction_coefficient', 'cable_modulus', 'torque_constant', 'wrist_finger_coupling')
#: Fitted as a log factor of the YAML value (positive, scale-like); the coupling is fitted additively.
RELATIVE = ('pulley_friction_coefficient', 'cable_modulus', 'torque_constant')
#: Largest factor a scale-like parameter may move away from the YAML: a shipped YAML is off by
#: tens of percent, not by factors (a fit at this bound says the model misses something).
MAX_FACTOR = 2.0
#: Largest change of the wrist-finger coupling from the YAML (rad/rad).
MAX_COUPLING_CHANGE = 0.5
#: The jaw angle identifies the stiffness and the coupling only when, after their fit, it departs
#: from the model's kinematics by less than this fraction of the stretch it should show (std):
#: otherwise the angle follows something else (a cable of another length, a jaw encoder of
#: another instrument) and what the fit reads as a stretch is not one.
MAX_ANGLE_RESIDUAL = 0.5
#: Least wrist motion (rad, std over the training samples) that identifies the coupling.
MIN_WRIST_STD = 0.01
#: A parameter is named off when its fitted value differs from the YAML by more than this
#: fraction of the YAML value and by more than OFF_SIGMAS of its standard error.
OFF_FRACTION = 0.05
OFF_SIGMAS = 3.0
#: Time blocks per log of the bootstrap of the standard errors.
BOOTSTRAP_BLOCKS = 20


def robust_scale(r: np.ndarray) -> float:
    """Return the MAD of ``r`` times 1.4826 (a standard deviation for Gaussian noise), unit of r."""
    return float(1.4826 * np.median(np.abs(r - np.median(r)))) if r.size else 0.0


@dataclass
class Reidentified:
    """The re-identified instrument: fitted values, standard errors, what was held at the YAML."""

    params: object                      # ParamSet: the YAML with the fitted values
    yaml: object                        # ParamSet: as given
    values: dict = field(default_factory=dict)      # name -> fitted value (schema unit)
    std: dict = field(default_factory=dict)         # name -> standard error (schema unit)
    fixed: dict = field(default_factory=dict)       # name -> why it was held at the YAML
    evaluations: int = 0

    def polish(self, **values: float) -> None:
        """Move fitted parameters (name=value) where the engine's refinement of the same fit puts them."""
        values = {k: float(v) for k, v in values.items() if k in self.values}
        self.values.update(values)
        self.params = self.params.replace(**values)

    @property
    def off(self) -> list[str]:
        """Fitted parameters off the YAML (:data:`OFF_FRACTION`, :data:`OFF_SIGMAS`), largest first."""
        out = []
        for name, value in self.values.items():
            yaml = float(self.yaml[name])
            change = abs(value - yaml)
            if change > OFF_FRACTION * abs(yaml) and not change <= OFF_SIGMAS * self.std[name]:
                out.append((change / max(abs(yaml), 1e-12), name))
        return [name for _, name in sorted(out, reverse=True)]

    def as_json(self) -> dict:
        """Return the result's ``calibration`` entries: parameters, parameters_off, reidentification."""
        parameters = {}
        off = self.off
        for name in REIDENTIFIED:
            yaml = float(self.yaml[name])
            entry = {'yaml': yaml, 'fitted': yaml, 'std': None, 'unit': SPECS[name].unit}
            if name in self.values:
                entry.update(fitted=self.values[name], std=self.std[name], off=name in off)
            else:
                entry['note'] = f'held at the YAML value: {self.fixed.get(name, "not fitted")}'
            parameters[name] = entry
        how = {'method': 'before any effect is considered: the cable stiffness and the coupling from the '
                         'jaw angle (linear in them: the stretch and the wrist), the pulley friction and the '
                         'torque constant from the measured column by robust (Huber) nonlinear least squares '
                         'against the direction-aware nominal, on the training samples; every effect is then '
                         'fitted on top of the re-identified model',
               'std': f'moving-block bootstrap over time blocks ({BOOTSTRAP_BLOCKS} per log, 200 draws); '
                      'friction and torque constant: of the fit linearised at the solution',
               'bounds': f'x{1 / MAX_FACTOR:g}..x{MAX_FACTOR:g} of the YAML (friction, modulus, torque '
                         f'constant), +-{MAX_COUPLING_CHANGE:g} rad/rad (coupling); a parameter the fit '
                         'puts at or beyond a bound is held at the YAML value (not identified)',
               'off_rule': f'fitted differs from the YAML by > {100 * OFF_FRACTION:g} % and > '
                           f'{OFF_SIGMAS:g} std',
               'evaluations': self.evaluations}
        return {'parameters': parameters, 'parameters_off': off, 'reidentification': how}


def _bounds(params, name: str) -> tuple[float, float]:
    value = float(params[name])
    if name in RELATIVE:
        return value / MAX_FACTOR, value * MAX_FACTOR
    spec = SPECS[name]
    return max(value - MAX_COUPLING_CHANGE, spec.min), min(value + MAX_COUPLING_CHANGE, spec.max)


def reidentify(inputs: list, rows: list, params, model_of, *, force_scale: float, rng,
               jaw_side_cable_length: float | None = None) -> Reidentified:
    """Fit :data:`REIDENTIFIED` to the training samples of the logs.

    The cable stiffness and the wrist-finger coupling enter the jaw angle linearly (the
    stretch ``(L_d T0 + L_j Tn) / (E A r_n)`` scales with 1/E, the wrist term with c): a
    least-squares fit of the angle residual, beside the encoder zero and the lag. The
    pulley friction and the torque constant set the measured column: robust nonlinear
    least squares (:func:`~grip_force_ros.identify.fit_parameters`), with the stiffness
    and coupling just fitted; then the angle fit again at the fitted friction. Each
    channel fits the parameters it sees, so a jaw angle the model does not describe (a
    cable of another length, a backlash) cannot bend the friction, nor the force the
    stiffness.

    Parameters
    ----------
    inputs : list of dict
        :func:`~grip_force_ros.lab.diagnosis.frame.frame_inputs` of each log.
    rows : list of ndarray of int
        The training samples of each log (may be empty).
    params : ParamSet
        The instrument as given (the YAML).
    model_of : callable
        ``model_of(ParamSet) -> GripForceModel``.
    force_scale : float
        Robust scale of the measured column's residual (its unit): the Huber loss' scale.
    rng : numpy.random.Generator
        Draws the bootstraps.
    jaw_side_cable_length : float, optional
        As :func:`~grip_force_ros.lab.diagnosis.frame.nominal`.

    Returns
    -------
    Reidentified
        The YAML where nothing can be identified.
    """
    used = [(inp, r) for inp, r in zip(inputs, rows) if r.size]
    if not used:
        return Reidentified(params, params, fixed={n: 'no training samples' for n in REIDENTIFIED})
    wrist = np.concatenate([inp['wrist'][r] for inp, r in used])
    velocity = np.concatenate([inp['jaw_velocity'][r] for inp, r in used])
    y = np.concatenate([inp['y'][r] for inp, r in used])
    # the bootstrap's blocks: BOOTSTRAP_BLOCKS time blocks per log
    block = np.concatenate([k * BOOTSTRAP_BLOCKS + np.minimum(
        (r - r[0]) * BOOTSTRAP_BLOCKS // max(int(r[-1] - r[0]) + 1, 1), BOOTSTRAP_BLOCKS - 1)
        for k, (_, r) in enumerate(used)])
    fixed = {}
    angle_names = ['cable_modulus', 'wrist_finger_coupling']
    if float(np.std(wrist)) < MIN_WRIST_STD:
        angle_names.remove('wrist_finger_coupling')
        fixed['wrist_finger_coupling'] = f'the wrist moves less than {MIN_WRIST_STD} rad (std) in training'

    def nominals(p):
        model = model_of(p)
        return [nominal(inp, model, jaw_side_cable_length=jaw_side_cable_length) for inp, _ in used]

    def pick(noms, key):
        return np.concatenate([nom[key][r] for nom, (_, r) in zip(noms, used)])

    def angle_fit(p, with_std=True):
        """Return the angle parameters' values and std at ``p`` (linear: 1/E and c), and those off bounds."""
        noms = nominals(p)
        stretch = pick(noms, 'stretch')
        target = np.concatenate([inp['jaw'][r] for inp, r in used]) - pick(noms, 'jaw_model') - stretch
        with_wrist = 'wrist_finger_coupling' in angle_names
        X = np.column_stack([np.ones_like(y), velocity, stretch] + ([wrist] if with_wrist else []))
        coef, *_ = np.linalg.lstsq(X, target, rcond=None)
        std = block_bootstrap_std(X, target, rng, labels=block) if with_std else np.full(X.shape[1], np.nan)
        left = float(np.std(target - X @ coef))
        if not left < MAX_ANGLE_RESIDUAL * float(np.std(stretch)):
            # the jaw angle does not follow the drum through the model's kinematics to within the
            # stretch it should show: neither the stiffness nor the coupling can be read from it
            reason = (f'the jaw angle departs from the model by {left:.3g} rad rms, more than '
                      f'{MAX_ANGLE_RESIDUAL:g} x the stretch it should show '
                      f'({float(np.std(stretch)):.3g} rad)')
            return {}, {}, {name: reason for name in angle_names}
        # jaw - model = ... + (a - 1) stretch(E): a = E / E_true, so E_true = E / a
        scale = 1.0 + float(coef[2])
        modulus = float(p.cable_modulus)
        fitted = {'cable_modulus': (modulus / scale, modulus * float(std[2]) / scale) if scale > 0
                  else (np.inf, np.inf)}
        if with_wrist:
            fitted['wrist_finger_coupling'] = (float(p.wrist_finger_coupling) + float(coef[3]), float(std[3]))
        values, stds, outside = {}, {}, {}
        for name, (value, sd) in fitted.items():
            low, high = _bounds(params, name)
            if low < value < high:
                values[name], stds[name] = value, sd
            else:
                outside[name] = (f'the jaw angle puts it at {value:.4g} {SPECS[name].unit}, beyond the '
                                 'bounds: the angle does not follow the stretch and coupling model')
        return values, stds, outside

    angle_values, _, _ = angle_fit(params, with_std=False)
    current = params.replace(**angle_values)

    # the force channel: friction and torque constant, with the stiffness and coupling just fitted
    noms = nominals(current)
    f0 = pick(noms, 'nominal')
    gain = float(f0 @ y / (f0 @ f0)) if f0 @ f0 > 0 else 1.0
    scale = force_scale if force_scale > 0 else robust_scale(y - gain * f0)
    if not scale > 0:
        return Reidentified(params, params,
                            fixed={n: 'no residual scale (a noise-free log)' for n in REIDENTIFIED})

    def residuals(trial):
        return (y - pick(nominals(trial), 'nominal')) / scale

    # a fit that drives the friction or the torque constant to a bound says the measured column
    # holds something the nominal does not describe (the rig's Coulomb friction, larger than its
    # load): both are held at the YAML, for the effects to explain (refitting one alone would let
    # it take over the other's part)
    force_names = ['pulley_friction_coefficient', 'torque_constant']
    try:
        fit = fit_parameters(current, force_names, residuals, relative=force_names,
                             bounds={n: _bounds(params, n) for n in force_names}, loss='huber',
                             f_scale=HUBER_K, labels=block, rng=rng)
    except CalibrationError as exc:
        fixed.update({n: str(exc) for n in force_names})
        fit = None
    if fit is not None and fit.at_bound:
        gone = ', '.join(f'{n} {fit.values[n]:.4g} {SPECS[n].unit}'.rstrip() for n in fit.at_bound)
        fixed.update({n: f'the force fit went to a bound ({gone}): not identified by these logs'
                      for n in force_names})
        fit = None
    values, std = {}, {}
    if fit is not None:
        current = current.replace(**fit.values)
        values, std = dict(fit.values), dict(fit.std_errors)
    angle_values, angle_std, outside = angle_fit(current)
    for name, reason in outside.items():
        fixed[name] = f'{reason}; not identified'
    current = current.replace(**angle_values)
    return Reidentified(current, params, values={**values, **angle_values}, std={**std, **angle_std},
                        fixed=fixed, evaluations=fit.evaluations if fit is not None else 0)
