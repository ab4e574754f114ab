"""Adopt what a diagnosis found: its effects as instrument terms, in a new instrument file.

``grip-force diagnose ... --adopt OUT.yaml`` maps the verdict's effects to the transmission
terms of ``model/jaw_friction.py`` (the physics the controller, the sim and the diagnosis'
own nominal share), takes the force gain of the winning fit into the torque constant, keeps
the parameters the diagnosis re-identified, and writes the ``--config`` file with those
values (:func:`grip_force_ros.params.rewrite_instrument_file`). The maps (``c`` the fitted
coefficients in N*m of jaw torque, ``x`` in [-1, 1] the jaw angle over the training logs'
stroke [lo, hi], ``h = (hi - lo)/2``, mid = (lo + hi)/2):

======================  =====================================================================
effect                  instrument terms
======================  =====================================================================
pivot_coulomb_friction  ``jaw_coulomb_friction`` += -force_step (the friction takes torque
                        from the grip while closing); ``jaw_friction_width`` = the play
                        width when the direction follows the motor angle
position_spring         on the jaw angle: the diagnosis' spring adds c0 + c1 P1(x) + c2 P2(x) to
                        the jaw torque, the model's K takes from it: ``jaw_spring_rest_angle``
                        = mid, ``jaw_spring_torque`` += -(c0 - c2/2), ``jaw_spring_slope`` +=
                        -c1/h, ``jaw_spring_curvature`` += -1.5 c2/h^2 (the file's spring
                        re-centred on mid first)
viscous_friction        ``jaw_viscous_friction`` += force_per_jaw_velocity (when >= 0)
======================  =====================================================================

The terms add to the file's own (the diagnosis measures what its nominal misses). Every
other effect has no instrument term yet: :func:`adopt` says so in ``not_adopted``.
"""
from __future__ import annotations

from typing import Mapping

from grip_force_ros.params import rewrite_instrument_file

#: First line of an adopted file (an earlier adoption's header is replaced).
HEADER = '# Adopted from a diagnosis ('


def effect_parameters(result: Mapping) -> dict:
    """Return the described parameters of each named effect of a diagnosis result, by effect name."""
    verdict = result['verdict']
    named = [e for e in verdict['effects'] if e != 'none']
    out = {}
    if named:
        first = next(r for r in result['ranking'] if r['effect'] == named[0])
        out[named[0]] = first['params']
    if len(named) > 1:
        out[named[1]] = verdict['second_effect_params']
    return out


def _spring_terms(c, stroke, base: Mapping, where: str) -> dict:
    """Return the file's spring plus the diagnosis' (Legendre ``c`` over ``stroke``), about mid-stroke.

    The file's Coulomb friction along the stroke is re-centred on the new rest angle too
    (``coulomb_at`` is C0 + C1 (phi - rest)), so that the friction is unchanged.
    """
    lo, hi = stroke
    half, mid = 0.5 * (hi - lo), 0.5 * (hi + lo)
    get = (lambda k: float(base.get(k, 0.0)))
    e = mid - get('jaw_spring_rest_angle')                       # rad: new rest - old rest
    k0, k1, k2 = get('jaw_spring_torque'), get('jaw_spring_slope'), get('jaw_spring_curvature')
    k0, k1 = k0 + k1 * e + k2 * e * e, k1 + 2.0 * k2 * e           # the file's spring about mid
    out = {'jaw_spring_rest_angle': (round(mid, 6), f'{where}: mid-stroke of the training logs'),
           'jaw_spring_torque': (round(k0 - (c[0] - 0.5 * c[2]), 8), where),
           'jaw_spring_slope': (round(k1 - c[1] / half, 8), where),
           'jaw_spring_curvature': (round(k2 - 1.5 * c[2] / half ** 2, 8), where)}
    if get('jaw_coulomb_friction_slope') and e:
        out['jaw_coulomb_friction'] = (round(get('jaw_coulomb_friction')
                                             + get('jaw_coulomb_friction_slope') * e, 6),
                                       "the file's, at the new rest angle")
    return out


def terms(result: Mapping, base: Mapping) -> tuple[dict, list]:
    """Instrument values (name -> (value, source)) for a diagnosis result, and what has no term.

    Parameters
    ----------
    result : mapping
        ``run_diagnosis(...).result``.
    base : mapping
        The diagnosed instrument file's values (``read_params_yaml``).

    Returns
    -------
    (dict, list of dict)
        The values to write, and ``{effect, reason}`` for each named effect not adopted.
    """
    values: dict = {}
    skipped = []
    measured = result['measured']
    for effect, params in effect_parameters(result).items():
        where = f'adopted from the diagnosis ({effect} on {measured})'
        if effect == 'pivot_coulomb_friction':
            step = params['force_step']
            if step['value'] >= 0:
                skipped.append({'effect': effect, 'reason': f"force_step {step['value']:.4g} >= 0: "
                                'not a friction opposing the motion'})
                continue
            values['jaw_coulomb_friction'] = (
                round(float(base.get('jaw_coulomb_friction', 0.0)) - step['value'], 6),
                f"{where}: the file's + (-force_step) +- {step['std']:.2g}")
            grid = params.get('friction_torque_grid', {})
            if grid.get('direction_state_of') == 'motor_angle':
                values['jaw_friction_width'] = (float(grid['value']), f'{where}: the play width on the drive')
        elif effect == 'position_spring':
            angle = params.get('spring_angle', {}).get('value')
            if angle != 'jaw_angle':
                skipped.append({'effect': effect, 'reason': f'the spring follows the {angle}; the '
                                "instrument's spring follows the jaw angle"})
                continue
            c = [params[f'spring_legendre_{k}']['value'] for k in range(3)]
            values.update(_spring_terms(c, result['strokes']['jaw'], base, where))
        elif effect == 'viscous_friction':
            c = params['force_per_jaw_velocity']['value']
            if c < 0:
                skipped.append({'effect': effect, 'reason': f'{c:.4g} N*m*s/rad < 0: not a damping'})
                continue
            values['jaw_viscous_friction'] = (round(float(base.get('jaw_viscous_friction', 0.0)) + c, 8),
                                              f"{where}: the file's + {c:.4g}")
        else:
            skipped.append({'effect': effect, 'reason': 'no instrument term for this effect yet'})
    for name, p in result['calibration'].get('parameters', {}).items():
        if p.get('std') is not None and not p.get('off'):
            values[name] = (float(f"{p['fitted']:.6g}"), f"re-identified by the diagnosis +- {p['std']:.2g}")
    named = [e for e in result['verdict']['effects'] if e != 'none']
    if named:
        gain = next(r for r in result['ranking'] if r['effect'] == named[0])['gain']
        k = values.get('torque_constant', (base['torque_constant'], ''))[0]
        values['torque_constant'] = (float(f'{k * gain:.6g}'),
                                     f'x {gain:.4g}, the force gain of the {named[0]} fit')
    return values, skipped


def write(result: Mapping, base_path, out, base: Mapping) -> tuple[dict, list]:
    """Write ``out``: the diagnosed file with the adopted terms; return :func:`terms`' answer."""
    values, skipped = terms(result, base)
    verdict = result['verdict']
    header = (f"{HEADER}`grip-force diagnose --adopt`, verdict {' + '.join(verdict['effects'])}, "
              f"held-out gap {verdict['gap_before']:.4g} -> {verdict['gap_after']:.4g} "
              f"{verdict['unit']}): {', '.join(values) or 'nothing'} adopted; every other number "
              f"as in the diagnosed file")
    rewrite_instrument_file(base_path, out, values, header, replaces=HEADER)
    return values, skipped
