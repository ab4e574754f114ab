"""Gain schedule on the state rate: the loops' bandwidth follows what the sampling allows.

The instrument YAML's gains are designed at ``gain_design_rate`` (1 kHz, the crtk profile's
state rate; ``grip-force tune``). A PID sampled at the state period ``T`` with one period of
transport delay and a zero-order hold loses about ``1.5 w T`` rad of phase at the crossover
``w``; the plant's own lag near the crossover acts like a further delay ``tau``. For the
phase margin the design had, the crossover must keep the phase the two delays take:
``w * (tau + 1.5 T)`` constant. So at an expected state rate ``f`` below the design rate
``f_d`` the crossover shrinks by

    s(f) = (tau + 1.5 / f_d) / (tau + 1.5 / f) = (1 / f_k + 1 / f_d) / (1 / f_k + 1 / f),

``f_k = 1.5 / tau`` the loop's knee (Hz, ``force_schedule_knee``, ``jaw_schedule_knee``):
the state rate at which the sampling loses as much phase as the plant. Far below the knee
the crossover is proportional to the rate, far above it hardly moves. At and above the
design rate ``s = 1``: the gains stay as designed. ``tune`` finds each knee (the smallest
that keeps the design margins at every rate of its grid, every plant variant) and checks
the schedule's margins over the whole range (docs/control.md, "Gain schedule").

The gains move so that the crossover, the PI zero ``ki / kp`` and the derivative time
``kd / kp`` all scale with ``s``; how much ``kp`` must change for the crossover to move by
``s`` is the plant's magnitude slope over the crossover band, :data:`PLANT_SLOPE`:

- force (grip force per ampere: static over the band, the cable and contact modes are far
  above it; slope 0): ``kp``, ``ki * s``, ``kd / s``;
- jaw in free motion (an integrator over the band: the drum's damping, 6e-3 N*m*s/rad over
  its 1e-5 kg*m^2, puts the inertia's corner at ~95 Hz, above the 3..30 Hz crossovers;
  slope 1): ``kp * s``, ``ki * s**2``, ``kd``.

The derivative filter keeps its number of state periods: ``tf * f_d / f`` (never fewer
periods than designed). The controller integrates on the measured step time whatever the
schedule (control/pid.py); the schedule sets the gains from the *expected* rate.
"""
from __future__ import annotations

from typing import NamedTuple

#: Magnitude slope n of each loop's plant over its crossover band (|P| ~ w**-n): the gains
#: scale as kp * s**n, ki * s**(n + 1), kd * s**(n - 1) (module docstring).
PLANT_SLOPE = {'force': 0, 'jaw': 1}
#: Controller parameters of one loop's PID, in the order of :class:`LoopGains`.
GAIN_KEYS = {loop: (f'{loop}_kp', f'{loop}_ki', f'{loop}_kd', f'{loop}_derivative_filter_time')
             for loop in PLANT_SLOPE}


class LoopGains(NamedTuple):
    """The PID gains of one loop (force: A/N, A/(N*s), A*s/N; jaw: A/rad, ...; filter s)."""

    kp: float
    ki: float
    kd: float
    filter_time: float      # s, derivative filter time constant


class ScheduledGains(NamedTuple):
    """The gains the controller runs at ``rate``, and how they came from the designed ones."""

    rate: float             # Hz, the expected state rate
    design_rate: float      # Hz, gain_design_rate
    force_scale: float      # -, s of the force loop (1: as designed)
    jaw_scale: float        # -, s of the jaw loop
    force: LoopGains
    jaw: LoopGains

    def as_params(self) -> dict:
        """Return the effective gains under their controller parameter names."""
        return {key: value for loop in PLANT_SLOPE
                for key, value in zip(GAIN_KEYS[loop], getattr(self, loop))}

    def describe(self) -> str:
        """One line for the log and /diagnostics: the scale and the effective gains."""
        loops = '; '.join(
            f'{loop} x{getattr(self, loop + "_scale"):.3f}: kp {g.kp:.4g} ki {g.ki:.4g} '
            f'kd {g.kd:.4g} tf {g.filter_time * 1e3:.3g} ms'
            for loop, g in (('force', self.force), ('jaw', self.jaw)))
        return (f'gains designed at {self.design_rate:g} Hz, states expected at {self.rate:g} Hz: '
                f'{loops}')


def bandwidth_scale(rate: float, design_rate: float, knee: float) -> float:
    """Return the crossover scale s (-) at ``rate`` (Hz) of gains designed at ``design_rate``.

    ``s = (1/knee + 1/design_rate) / (1/knee + 1/rate)`` below the design rate, 1 at and
    above it (module docstring); ``knee`` in Hz.

    Raises
    ------
    ValueError
        A rate or the knee not positive.
    """
    if not (rate > 0.0 and design_rate > 0.0 and knee > 0.0):
        raise ValueError(f'rates and knee must be > 0 Hz, got rate {rate!r}, design rate '
                         f'{design_rate!r}, knee {knee!r}')
    if rate >= design_rate:
        return 1.0
    return (1.0 / knee + 1.0 / design_rate) / (1.0 / knee + 1.0 / rate)


def scale_loop(gains: LoopGains, loop: str, scale: float, period_ratio: float) -> LoopGains:
    """Return ``gains`` with the crossover moved by ``scale``; the filter by ``period_ratio``.

    ``period_ratio``: the state period over the design's (>= 1 below the design rate).
    """
    n = PLANT_SLOPE[loop]
    return LoopGains(gains.kp * scale ** n, gains.ki * scale ** (n + 1),
                     gains.kd * scale ** (n - 1), gains.filter_time * period_ratio)


def scheduled_gains(params, rate: float | None = None) -> ScheduledGains:
    """Return the gains the controller runs at the state rate ``rate`` (Hz).

    Parameters
    ----------
    params : ParamSet or mapping
        The controller parameters: the designed gains (``force_kp`` .. ``jaw_derivative_
        filter_time``), ``gain_design_rate``, ``force_schedule_knee``, ``jaw_schedule_knee``
        and ``expected_state_rate`` (Hz).
    rate : float, optional
        State rate (Hz); default ``expected_state_rate``.

    Returns
    -------
    ScheduledGains
    """
    rate = float(params['expected_state_rate'] if rate is None else rate)
    design_rate = float(params['gain_design_rate'])
    period_ratio = max(design_rate / rate, 1.0)
    out = {}
    for loop in PLANT_SLOPE:
        scale = bandwidth_scale(rate, design_rate, float(params[f'{loop}_schedule_knee']))
        designed = LoopGains(*(float(params[key]) for key in GAIN_KEYS[loop]))
        out[loop] = (scale, scale_loop(designed, loop, scale, period_ratio))
    return ScheduledGains(rate, design_rate, out['force'][0], out['jaw'][0],
                          out['force'][1], out['jaw'][1])
