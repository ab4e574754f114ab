"""Sample-by-sample jaw torque observer: the scalar fast path of :class:`CableFrictionObserver`.

Gives the same numbers as :meth:`CableFrictionObserver.predict` (to rounding), one
sample at a time, with plain floats: fit offline, then call :meth:`step` in a 1 kHz loop.

>>> est = CableFrictionObserver().fit(train_runs)                       # doctest: +SKIP
>>> live = StreamingJawTorqueObserver(est, dt=0.001)                    # doctest: +SKIP
>>> tau = live.step(current=0.12, motor_angle=-0.4, motor_shaft_angle=-0.41)   # doctest: +SKIP
"""
from __future__ import annotations

import math
from collections import deque

import numpy as np
from scipy.signal import butter, lfilter_zi

from grip_force_ros.lab.rig.estimator import POSITION_RANGE, CableFrictionObserver, EstimatorError
from grip_force_ros.model.jaw_friction import dahl_step


class _Lowpass:
    """Second-order Butterworth, transposed direct form II, started at rest on the first input."""

    def __init__(self, cutoff_hz: float, dt: float):
        nyquist = 0.5 / dt
        self.passthrough = not 0 < cutoff_hz < nyquist
        if not self.passthrough:
            b, a = butter(2, cutoff_hz / nyquist)
            self.b0, self.b1, self.b2 = (float(v) for v in b)
            self.a1, self.a2 = float(a[1]), float(a[2])
            self.zi = [float(v) for v in lfilter_zi(b, a)]
        self.z0 = self.z1 = None

    def __call__(self, x: float) -> float:
        if self.passthrough:
            return x
        if self.z0 is None:
            self.z0, self.z1 = self.zi[0] * x, self.zi[1] * x
        y = self.b0 * x + self.z0
        self.z0 = self.b1 * x - self.a1 * y + self.z1
        self.z1 = self.b2 * x - self.a2 * y
        return y


class StreamingJawTorqueObserver:
    """Online jaw torque estimate (N*m) from measured current and motor-side angles.

    Parameters
    ----------
    estimator : CableFrictionObserver
        A fitted estimator; its settings and coefficients are copied.
    dt : float
        Sample period (s) of the calls to :meth:`step`.
    """

    def __init__(self, estimator: CableFrictionObserver, dt: float = 0.001):
        if estimator.fit_result is None:
            raise EstimatorError('StreamingJawTorqueObserver needs a fitted estimator')
        if not dt > 0:
            raise EstimatorError(f'dt must be > 0 s, got {dt!r}')
        s = estimator.settings
        self.settings, self.dt = s, float(dt)
        coef = dict(zip(estimator.fit_result.names, (float(v) for v in estimator.fit_result.values)))
        self._alpha = (coef['alpha0'], coef.get('alpha1', 0.0), coef.get('alpha2', 0.0))
        self._quad = coef.get('alpha1_quad', 0.0)
        self._alpha_max = sum(abs(a) for a in self._alpha)
        self._offset, self._coulomb = coef['offset'], coef.get('coulomb', 0.0)
        self._coulomb_slow, self._viscous = coef.get('coulomb_slow', 0.0), coef.get('viscous', 0.0)
        # sum of Legendre terms as one power series in the scaled position (Horner below)
        spring = [0.0] + [coef[f'spring_P{k}'] for k in range(1, s.spring_order + 1)]
        friction = [0.0] + [coef[f'friction_P{k}'] for k in range(1, s.friction_map_order + 1)]
        self._spring = [float(c) for c in np.polynomial.legendre.leg2poly(spring)[::-1]]
        self._friction = [float(c) for c in np.polynomial.legendre.leg2poly(friction)[::-1]]
        self._delay = int(round(s.current_delay_s / dt)) if s.current_delay_s > 0 else 0
        self._window = max(1, int(round(s.velocity_window_s / dt)))
        tc = s.observer_time_constant
        self._gain = 1.0 if tc <= 0 else 1.0 - math.exp(-dt / tc)
        self._prior = float(estimator._prior)
        self._load = estimator.load_model
        if self._load is not None:
            self._level_gain = 1.0 - math.exp(-dt / s.level_time_constant)
        self.reset()

    def reset(self) -> None:
        """Forget the past (new run): filters restart on the next sample."""
        s = self.settings
        self._current_filter = _Lowpass(s.current_filter_hz, self.dt)
        self._velocity_filter = _Lowpass(s.current_filter_hz, self.dt)
        self._delayed = deque(maxlen=self._delay + 1)
        self._angles = deque(maxlen=self._window + 1)
        self._first_angle = None
        self._samples = 0
        self._direction = self._slow = 0.0
        self._last_angle = None
        self._estimate, self._seen = self._prior, 0.0
        self._level = None                      # load level (N*m), with a load model

    @staticmethod
    def _horner(coeffs, x: float) -> float:
        out = 0.0
        for c in coeffs:
            out = out * x + c
        return out

    #: One Dahl step of the friction state (the instrument's, model/jaw_friction.py).
    _dahl = staticmethod(dahl_step)

    def step(self, current: float, motor_angle: float, motor_shaft_angle: float | None = None) -> float:
        """Advance one sample and return the jaw torque estimate (N*m).

        Parameters
        ----------
        current : float
            Measured motor current (A), positive closes.
        motor_angle : float
            Input-disk (drum) angle (rad), positive closing.
        motor_shaft_angle : float, optional
            Gearbox output angle (rad); drives the friction state when the settings
            say so (the default), else ``motor_angle`` is used.
        """
        s = self.settings
        current, motor_angle = float(current), float(motor_angle)
        if motor_shaft_angle is not None:
            motor_shaft_angle = float(motor_shaft_angle)
        # current: delay (sensor_delay candidate), then the causal low-pass
        if self._delay:
            if not self._delayed:
                self._delayed.extend([current] * self._delay)
            self._delayed.append(current)
            current = self._delayed[0]
        i_f = self._current_filter(current)
        angle = motor_shaft_angle if (s.backlash_angle == 'motor_shaft_angle'
                                      and motor_shaft_angle is not None) else motor_angle
        # velocity: backward difference over the window (shorter at the start), low-pass
        k = self._samples
        if self._first_angle is None:
            self._first_angle = angle
        self._angles.append(angle)
        if k == 0:
            raw_v = 0.0
        elif k < self._window:
            raw_v = (angle - self._first_angle) / (k * self.dt)
        else:
            raw_v = (angle - self._angles[0]) / (self._window * self.dt)
        velocity = self._velocity_filter(raw_v)
        self._samples = k + 1
        # friction direction (Dahl) and whether it is known
        d = 0.0 if self._last_angle is None else angle - self._last_angle
        self._last_angle = angle
        if s.hysteresis:
            self._direction = self._dahl(self._direction, d, s.hysteresis_width)
            known = min(max((abs(self._direction) - s.sliding_threshold)
                            / (1.0 - s.sliding_threshold), 0.0), 1.0)
            sliding = known if abs(velocity) > s.stick_speed else 0.0
            direction = self._direction
        else:
            direction = float((velocity > 0) - (velocity < 0))
            sliding = 1.0
        slow = 0.0
        if s.slow_hysteresis_width > 0:
            self._slow = self._dahl(self._slow, d, s.slow_hysteresis_width)
            slow = self._slow
        lo, hi = POSITION_RANGE
        x = min(max(2.0 * (motor_angle - lo) / (hi - lo) - 1.0, -1.0), 1.0)
        beta = (self._offset + (self._coulomb if s.coulomb else 0.0) * direction
                + self._coulomb_slow * slow + self._horner(self._spring, x)
                + direction * self._horner(self._friction, x)
                + (self._viscous * velocity if s.viscous else 0.0))
        a0, a1, a2 = self._alpha
        alpha = a0 + a1 * direction + a2 * slow
        if abs(alpha) < 1e-6:
            alpha = 1e-6
        quad = self._quad * direction
        y = i_f - beta
        if quad == 0.0 and self._quad == 0.0:
            inverted, slope = y / alpha, abs(alpha)   # tau = (I - b(s, x, v)) / alpha(s)
        else:                                          # I - b = alpha*tau + quad*tau^2
            alpha = max(alpha, 1e-6)
            slope = math.sqrt(max(alpha * alpha + 4.0 * quad * y, 0.0))
            inverted = 2.0 * y / (alpha + slope)
        if not s.hysteresis:
            return inverted
        weight = sliding * min(slope / self._alpha_max, 1.0) ** 2   # information of this sample
        if self._load is not None:
            return self._level_step(inverted, weight, direction, x)
        if weight > 0.0:
            self._seen += weight
            g = max(self._gain * weight, weight / self._seen)
            self._estimate += g * (inverted - self._estimate)
        return self._estimate

    def _level_step(self, inverted: float, weight: float, direction: float, x: float) -> float:
        """Level observer with the load model (batch: ``CableFrictionObserver._predict_level``)."""
        offset, scale = self._load.terms([direction], [x])
        offset, scale = float(offset[0]), float(scale[0])
        if weight > 0.0:
            measured = (inverted - offset) / scale
            self._seen += weight
            if self._level is None:
                self._level = measured
            else:
                g = max(self._level_gain * weight, weight / self._seen)
                self._level += g * (measured - self._level)
        return self._prior if self._level is None else self._level * scale + offset


def benchmark(samples: int = 20000) -> dict:
    """Time :meth:`StreamingJawTorqueObserver.step` on a real run; returns microseconds per step.

    ``python -m grip_force_ros.lab.rig.streaming`` prints the figures (needs the rig data).
    """
    import time

    from grip_force_ros.lab.rig import default_data_dir, read_runs
    runs = read_runs(default_data_dir())
    est = CableFrictionObserver().fit([r for r in runs if r.torque_step in (0, 2)])
    run = next(r for r in runs if r.name == '11')
    live = StreamingJawTorqueObserver(est, dt=0.001)
    cur, disk, shaft = (run.current.tolist(), run.motor_angle.tolist(),
                        run.motor_shaft_angle.tolist())
    n = min(samples, len(cur))
    start = time.perf_counter()
    for i in range(n):
        live.step(cur[i], disk[i], shaft[i])
    per_step = (time.perf_counter() - start) / n * 1e6
    start = time.perf_counter()
    est.predict(run)
    batch = (time.perf_counter() - start) / len(run) * 1e6
    return {'streaming_us_per_step': per_step, 'batch_us_per_sample': batch, 'samples': n}


if __name__ == '__main__':  # pragma: no cover - a benchmark that prints figures
    fig = benchmark()
    print(f"streaming step: {fig['streaming_us_per_step']:.1f} us per sample "
          f"({fig['samples']} samples); batch predict: {fig['batch_us_per_sample']:.2f} us per sample")
