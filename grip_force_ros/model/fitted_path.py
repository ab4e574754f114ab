"""The table-backed path of the grip-force model: fitted maps instead of exact solves.

With tension-dependent friction and no wrist-dependent wrap the chain is nonlinear but
one-dimensional: lambda_n depends on the drum tension F0 (N) alone and the inverse on
the drive torque M (N*m) alone. Both are fitted once (:mod:`grip_force_ros.model.tables`):
lambda_n(F0) as one polynomial on the first vectorised forward, I(M) as a piecewise cubic
at construction (the control step's inverse reads its rows too). Each is checked against
the exact computation when it is built (:attr:`FittedPath.EFFICIENCY_FIT_TOLERANCE`,
:attr:`FittedPath.CURRENT_FIT_TOLERANCE`); beyond a table the exact path takes over.
docs/model.md, speed.

:class:`FittedPath` is a part of :class:`~grip_force_ros.model.GripForceModel` (a mixin:
it shares the model's constants), not a model on its own.
"""
from __future__ import annotations

import numpy as np

from grip_force_ros.model import tables as _tables
from grip_force_ros.model.contact import ModelError

__all__ = ['FittedPath']


class FittedPath:
    """Fitted-table methods of :class:`~grip_force_ros.model.GripForceModel`.

    Reads the model's constants (``params.max_current`` (A), ``tension_per_amp``
    (N/A), ``affine``, ``mu``) and the vectorised path's (``_wrist_matters``,
    ``_efficiency_at_rest``, ``_torque_per_amp_at_rest``, the exact chain and solve);
    its own state comes from :meth:`_init_fitted_path`.
    """

    def _init_fitted_path(self) -> None:
        """Whether the tables apply; I(M) is built now, lambda_n(F0) on first use."""
        # nonlinear but wrist-independent: lambda_n(F0) and I(M) are 1-D maps, fitted
        # (docs/model.md, speed; grip_force_ros.model.tables): I(M) now, lambda_n(F0) on
        # the first vectorised forward
        self._one_dimensional = not self.affine and self.mu > 0.0 and not self._wrist_matters
        self._efficiency_fit = None               # (coefficients in F0, top F0 (N)), built lazily
        self._current_fit = None                  # PiecewisePolynomial of I(M) per position, see below
        self._current_rows = None                 # its coefficients per interval, Python floats
        self._rising = None                       # see _rising_current
        if self._one_dimensional:                 # built now: the scalar inverse of the control step uses it
            self._current_fit_built()

    # Tolerances of the fitted maps (relative, checked when they are built): the exact
    # chain itself rounds at ~1e-15, the Newton solve it replaces stops at ~1e-15.
    EFFICIENCY_FIT_TOLERANCE = 1e-14
    CURRENT_FIT_TOLERANCE = 5e-14
    CURRENT_FIT_INTERVALS, CURRENT_FIT_DEGREE = 2048, 3     # cubics: the gather costs a pass per row

    def _rising_current(self) -> float:
        """Return a current (A) safely below the peak of M(I) at zero wrist (or 2 max_current).

        Two nodes short of the last rising node of a 2049-node grid over [0, 2 max_current],
        refined on a second grid up to the first falling node when the peak comes early
        (vectorised exact torque, ~0.3 ms). 0 when M does not rise.
        """
        if self._rising is not None:
            return self._rising
        high = 2.0 * max(self.params.max_current, 1e-3)                     # A
        zero = np.zeros(())
        for _ in range(2):
            grid = np.linspace(0.0, high, 2049)                                # A
            with np.errstate(all='ignore'):
                falling = np.flatnonzero(~(np.diff(self._torque_array(grid, zero)) > 0.0))
            if falling.size == 0:
                self._rising = high
                return high
            if falling[0] >= 256:
                break
            high = grid[falling[0] + 1]                                        # the peak is before this
        self._rising = float(grid[max(falling[0] - 2, 0)])
        return self._rising

    def _efficiency_fit_built(self):
        """(coefficients in F0 (increasing powers, N^-k), top F0 (N)) of lambda_n(F0); None if no fit.

        Over F0 at [0, 2 max_current], or if no polynomial of degree <= 16 fits there
        (steep tension gains), over [0, 2 I_rising] and [0, I_rising] (:meth:`_rising_current`).
        """
        if self._efficiency_fit is None:
            zero = np.zeros(())

            def exact(f0):
                return self._chain_efficiency(np.asarray(f0, float), zero)
            full = 2.0 * max(self.params.max_current, 1e-3)                    # A
            rising = self._rising_current()
            self._efficiency_fit = (False,)
            for current in sorted({full, min(full, 2.0 * rising), rising}, reverse=True):
                if current <= 0.0:
                    continue
                top = self.tension_per_amp * current                            # N
                with np.errstate(all='ignore'):
                    coefficients = _tables.fit_polynomial(exact, 0.0, top, self.EFFICIENCY_FIT_TOLERANCE)
                if coefficients is not None:
                    self._efficiency_fit = (coefficients, top)
                    break
        return None if len(self._efficiency_fit) == 1 else self._efficiency_fit

    def _efficiency_from_fit(self, drum_tension, out):
        """lambda_n (-) at drum tensions F0 (N) into ``out``, wrist-independent chain.

        The fitted polynomial on (0, top]; the constant-friction value where F0 <= 0 (or
        NaN), the exact chain above ``top``. Equal to :meth:`_chain_efficiency` within
        :attr:`EFFICIENCY_FIT_TOLERANCE`.
        """
        fit = self._efficiency_fit_built()
        if fit is None or drum_tension.size == 0:
            out[...] = self._chain_efficiency(drum_tension, np.zeros(()))
            return out
        coefficients, top = fit
        low, high = drum_tension.min(), drum_tension.max()
        inside = low > 0.0 and high <= top
        # samples outside are replaced below; clipped, they cannot overflow on the way
        _tables.horner(coefficients, drum_tension if inside else np.clip(drum_tension, 0.0, top), out=out)
        if not low > 0.0:                                         # unloaded (or NaN): lambda at zero
            np.copyto(out, self._efficiency_at_rest, where=~(drum_tension > 0.0))
        if not high <= top:                                       # beyond the fit (or NaN)
            beyond = drum_tension > top
            out[beyond] = self._chain_efficiency(drum_tension[beyond], np.zeros(()))
        return out

    def _current_fit_built(self):
        """Build (once) the PiecewisePolynomial of I(M) / (M / step) (A) over [0, M(I_rising)).

        None if there is none.

        ``I_rising`` from :meth:`_rising_current`; the table may end earlier (the first
        interval that misses :attr:`CURRENT_FIT_TOLERANCE`).

        Divided by the position ``M / step`` (intervals, -), not by M: the caller has
        the position at hand and multiplies by it (``I = fit * position``).
        """
        if self._current_fit is None:
            per_amp = self._torque_per_amp_at_rest
            fit = None
            rising = self._rising_current() if per_amp > 0.0 else 0.0   # A
            if rising > 0.0:
                top = self._torque_scalar(rising, 0.0)                   # N*m, clear of the peak
                step = top / self.CURRENT_FIT_INTERVALS                  # N*m
                zero = np.zeros(())

                def exact(torque):
                    return self._solve_current_array(torque, zero, per_amp) / (torque / step)
                try:
                    with np.errstate(all='ignore'):
                        fit = _tables.fit_piecewise(exact, top, self.CURRENT_FIT_INTERVALS,
                                                    self.CURRENT_FIT_DEGREE, self.CURRENT_FIT_TOLERANCE)
                except ModelError:          # the exact solve failed somewhere: no table, exact path
                    fit = None
            self._current_fit = (False,) if fit is None else (fit,)
            if fit is not None:
                self._current_rows = fit.coefficients.T.tolist()
        return self._current_fit[0] or None

    def _current_from_fit(self, torque, per_amp):
        """Currents (A) with M(I) = torque (N*m), wrist-independent chain, all samples at once.

        From the fitted table (:meth:`_current_fit_built`); ``torque / per_amp`` where
        torque <= 0 (linear), :meth:`_solve_current_array` above the table (which
        raises for unreachable torques). Equal to the exact solve within
        :attr:`CURRENT_FIT_TOLERANCE`.
        """
        fit = self._current_fit_built()
        if fit is None or torque.size == 0:
            return self._solve_current_array(torque, np.zeros(()), per_amp)
        position = np.multiply(torque, 1.0 / fit.step)             # M / step (-)
        low, high = position.min(), position.max()
        beyond = None if high < fit.intervals else ~(position < fit.intervals)
        if not (low > 0.0 and beyond is None):                    # replaced below; clipped, no overflow
            np.clip(position, 0.0, fit.last_position, out=position)
        current = fit.at_positions(position)
        current *= position                                       # I (A)
        if not low > 0.0:                                         # linear below zero torque
            idle = ~(torque > 0.0)
            current[idle] = torque[idle] / per_amp
        if beyond is not None:                                    # beyond the table: Newton
            current[beyond] = self._solve_current_array(torque[beyond], np.zeros(()), per_amp)
        return current

    def _current_for_force_from_fit(self, force, gain, largest):
        """Currents (A) for grip forces (N) >= 0 at a constant contact gain (1/m), at rest.

        As :meth:`_current_from_fit` on ``force / gain`` without forming the torques:
        one array pass fewer. ``largest`` is ``force.max()`` (N).
        """
        fit = self._current_fit_built()
        if fit is None:
            return self._solve_current_array(force / gain, np.zeros(()), self._torque_per_amp_at_rest)
        per_position = 1.0 / (gain * fit.step)                    # positions per newton (1/N)
        position = np.multiply(force, per_position)               # M / step (-), >= 0
        beyond = None
        if not largest * per_position < fit.intervals:            # = position.max() < intervals
            beyond = ~(position < fit.intervals)
            np.minimum(position, fit.last_position, out=position)   # replaced below; clipped, no overflow
        current = fit.at_positions(position)
        current *= position                                       # I (A); 0 at zero force
        if beyond is not None:                                    # beyond the table: Newton
            current[beyond] = self._solve_current_array(force[beyond] / gain, np.zeros(()),
                                                        self._torque_per_amp_at_rest)
        return current
