"""Offline simulation: a current profile in, a log in the docs/design.md CSV contract out."""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from grip_force_ros.sim.effects import SimError
from grip_force_ros.sim.plant import InstrumentSim

__all__ = ['simulate', 'LOG_COLUMNS']

#: Columns of a log (docs/design.md contract), in order.
LOG_COLUMNS = ('t', 'current', 'motor_angle', 'wrist_angle', 'jaw_angle', 'grip_force', 'object')


def simulate(params: Any, current_profile, dt: float, obj: str = 'needle',
             effects: Mapping[str, float] | None = None, seed: int = 0, wrist_profile=None,
             extra: bool = False) -> dict[str, np.ndarray]:
    """Run the sim open loop on a current-command profile and return its log.

    Parameters
    ----------
    params : ParamSet
        Instrument + sim parameters (see :class:`InstrumentSim`).
    current_profile : array_like, shape (n,)
        Current command (A) held during each step of ``dt``.
    dt : float
        Sample period of the log (s), e.g. 1e-3.
    obj : str
        Object between the jaws.
    effects : dict, optional
        Effect name -> strength (docs/design.md names).
    seed : int
        Noise seed.
    wrist_profile : array_like, shape (n,), optional
        Wrist pitch (rad) per sample; default: ``initial_wrist_angle`` throughout.
    extra : bool
        Also return the noise-free truth: ``true_grip_force`` (N),
        ``current_command`` (A), ``motor_velocity``, ``jaw_velocity`` (rad/s).

    Returns
    -------
    dict of ndarray
        The docs/design.md columns ``t`` (s, time after each step), ``current`` (A,
        measured), ``motor_angle``, ``wrist_angle``, ``jaw_angle`` (rad), ``grip_force``
        (N, load cell), ``object`` (str array), plus the extra columns if asked.

    Raises
    ------
    SimError
        A profile that is not 1-D and finite, or profiles of different lengths.
    """
    currents = np.asarray(current_profile, dtype=float)
    if currents.ndim != 1 or not np.all(np.isfinite(currents)):
        raise SimError('current_profile must be a 1-D array of finite currents (A)')
    n = currents.size
    wrists = None
    if wrist_profile is not None:
        wrists = np.asarray(wrist_profile, dtype=float)
        if wrists.shape != currents.shape or not np.all(np.isfinite(wrists)):
            raise SimError('wrist_profile must be finite and as long as current_profile')
    sim = InstrumentSim(params, obj=obj, effects=effects, seed=seed)
    names = ('t', 'current', 'motor_angle', 'wrist_angle', 'jaw_angle', 'grip_force')
    out = {name: np.empty(n) for name in names}
    if extra:
        for name in ('true_grip_force', 'current_command', 'motor_velocity', 'jaw_velocity'):
            out[name] = np.empty(n)
    cols = [out[name] for name in names]
    step, measure = sim.step, sim.measure
    dt = float(dt)
    last_wrist = None
    for k in range(n):
        if wrists is not None and wrists[k] != last_wrist:
            last_wrist = float(wrists[k])
            sim.set_wrist_angle(last_wrist)
        step(currents[k], dt)
        m = measure()
        cols[0][k] = m.t
        cols[1][k] = m.current
        cols[2][k] = m.motor_angle
        cols[3][k] = m.wrist_angle
        cols[4][k] = m.jaw_angle
        cols[5][k] = m.grip_force
        if extra:
            truth = sim.truth()
            out['true_grip_force'][k] = truth['grip_force']
            out['current_command'][k] = currents[k]
            out['motor_velocity'][k] = truth['motor_velocity']
            out['jaw_velocity'][k] = truth['jaw_velocity']
    out['object'] = np.full(n, obj, dtype=object)
    return out
