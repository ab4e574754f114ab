"""Step-response metrics of the simulated instrument (rise, overshoot, 2 % settling)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from grip_force_ros.sim.plant import InstrumentSim

__all__ = ['StepMetrics', 'step_response_metrics', 'metrics_of_signal', 'simulate_step']


@dataclass(frozen=True)
class StepMetrics:
    """Metrics of a step response.

    Attributes
    ----------
    final_value : float
        Mean of the last 10 % of the record (unit of the signal, N for grip force).
    rise_time : float
        10 % to 90 % of the change (s).
    overshoot : float
        Peak beyond the final value, as a fraction of the change (-), >= 0.
    settling_time : float
        Time after the step after which the signal stays within 2 % of the change around
        the final value (s); NaN if it never settles in the record.
    """

    final_value: float
    rise_time: float
    overshoot: float
    settling_time: float


def metrics_of_signal(t, y, t_step: float = 0.0, band: float = 0.02) -> StepMetrics:
    """Step metrics of a recorded signal ``y(t)`` with the step at ``t_step`` (s).

    Raises
    ------
    ValueError
        If the signal does not change.
    """
    t = np.asarray(t, float)
    y = np.asarray(y, float)
    before = y[t < t_step]
    initial = float(before[-1]) if before.size else float(y[0])
    after = t >= t_step
    t, y = t[after] - t_step, y[after]
    final = float(np.mean(y[-max(1, y.size // 10):]))
    change = final - initial
    if change == 0.0:
        raise ValueError('the signal does not change: no step response')
    rel = (y - initial) / change
    rise_time = float(t[np.argmax(rel >= 0.9)] - t[np.argmax(rel >= 0.1)])
    overshoot = max(float(np.max(rel)) - 1.0, 0.0)
    outside = np.nonzero(np.abs(rel - 1.0) > band)[0]
    if outside.size == 0:
        settling = 0.0
    elif outside[-1] + 1 >= t.size:
        settling = float('nan')
    else:
        settling = float(t[outside[-1] + 1])
    return StepMetrics(final, rise_time, overshoot, settling)


def simulate_step(params: Any, current: float = 0.35, obj: str = 'needle', duration: float = 0.3,
                  dt: float = 1e-4, pre_time: float = 0.05, pre_current: float = 0.0):
    """Noise-free current step on the sim; returns ``(t, grip_force, jaw_angle)`` arrays.

    The jaw starts closed on the object (contact angle), the current jumps from
    ``pre_current`` to ``current`` (A) at ``t = pre_time`` (s).
    """
    quiet = {name: 0.0 for name in ('current_noise_std', 'motor_angle_noise_std',
                                    'motor_velocity_noise_std', 'wrist_angle_noise_std',
                                    'jaw_angle_noise_std', 'jaw_velocity_noise_std',
                                    'grip_force_noise_std')}
    contact = {'needle': params.needle_contact_angle, 'rigid': params.rigid_contact_angle,
               'tissue': params.tissue_contact_angle}.get(obj, params.initial_jaw_angle)
    sim = InstrumentSim(params.replace(initial_jaw_angle=contact, **quiet), obj=obj)
    n = int(round((pre_time + duration) / dt))
    t = np.empty(n)
    force = np.empty(n)
    jaw = np.empty(n)
    for k in range(n):
        sim.step(pre_current if sim.t < pre_time - 1e-12 else current, dt)
        truth = sim.truth()
        t[k], force[k], jaw[k] = truth['t'], truth['grip_force'], truth['jaw_angle']
    return t, force, jaw


def step_response_metrics(params: Any, current: float = 0.35, obj: str = 'needle',
                          duration: float = 0.3, dt: float = 1e-4) -> StepMetrics:
    """Grip-force step response of the sim: current step 0 -> ``current`` (A) onto ``obj``.

    Returns
    -------
    StepMetrics
        Rise time, overshoot and 2 % settling time of the load-cell grip force
        (noise off). The paper reports transients damped within 0.1 s.
    """
    pre = 0.05
    t, force, _ = simulate_step(params, current, obj, duration, dt, pre_time=pre)
    return metrics_of_signal(t, force, t_step=pre)
