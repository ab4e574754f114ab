"""Polynomial tables for the nonlinear model's one-dimensional maps (vectorised fast path).

With tension-dependent friction and a wrist-independent chain (``wrist_wrap_gain == 0``)
the chain efficiency lambda_n depends on the drum tension F0 (N) alone, and the
inverse torque -> current on the drive torque M (N*m) alone. Computing them exactly
costs, per sample and pulley, a square root, two divisions and an exponential (the
forward) and a Newton solve of that chain (the inverse). Both maps are smooth, so:

* :func:`fit_polynomial`: one polynomial of the lowest degree (~8) that matches the
  exact map within a tolerance (~1e-14 relative) over an interval, checked on a dense
  grid when it is built. Evaluated by Horner's rule: two array passes per degree.
* :class:`PiecewisePolynomial`: one polynomial of low degree per interval of a uniform
  grid, for maps a single polynomial fits badly (the inverse, whose slope grows without
  bound towards the peak of M(I)). Each interval is checked when built; the table ends
  before the first interval that misses the tolerance.

Outside the fitted range the caller computes the exact map. :func:`table_errors`
measures a model's tables against the exact computation. Plain numpy, no rclpy.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from numpy.polynomial import Chebyshev, Polynomial

__all__ = ['fit_polynomial', 'horner', 'PiecewisePolynomial', 'fit_piecewise', 'table_errors']

ArrayMap = Callable[[np.ndarray], np.ndarray]


def horner(coefficients, x: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``sum_k coefficients[k] x^k`` (Horner's rule, in place into ``out``).

    Parameters
    ----------
    coefficients : sequence of float
        Increasing powers of ``x``, at least two.
    x : ndarray
        Points (any units; the coefficients carry the inverse units).
    out : ndarray, optional
        Output of ``x``'s shape, not ``x`` itself; a fresh array if omitted.

    Returns
    -------
    ndarray
        ``out``. ``2 (len(coefficients) - 1)`` passes over the array, no temporaries.
    """
    out = np.multiply(x, coefficients[-1], out=out)
    out += coefficients[-2]
    for c in coefficients[-3::-1]:
        out *= x
        out += c
    return out


def _relative_error(approx: np.ndarray, exact: np.ndarray) -> float:
    scale = np.maximum(np.abs(exact), np.finfo(float).tiny)
    return float(np.max(np.abs(approx - exact) / scale))


def fit_polynomial(exact: ArrayMap, low: float, high: float, tolerance: float,
                   degrees=range(2, 17), checks: int = 1001) -> np.ndarray | None:
    """Lowest-degree polynomial within ``tolerance`` (relative) of ``exact`` on [low, high].

    Least-squares Chebyshev fit on ``4 (degree + 1)`` Chebyshev points, converted to
    monomial coefficients in ``x`` itself (not a scaled variable: one pass fewer per
    call). Checked on ``checks`` equispaced points, both ends included.

    Parameters
    ----------
    exact : callable
        Vectorised map, ndarray -> ndarray of the same shape, nonzero on the interval.
    low, high : float
        Interval (units of ``x``), ``low < high``.
    tolerance : float
        Largest relative error accepted (-).
    degrees : iterable of int
        Degrees tried, in order.
    checks : int
        Equispaced points (ends included) on which the fit is checked.

    Returns
    -------
    ndarray or None
        Coefficients, increasing powers of ``x``; None if no degree is good enough.
    """
    check = np.linspace(low, high, checks)
    expect = exact(check)
    for degree in degrees:
        nodes = 0.5 * (low + high) + 0.5 * (high - low) * np.cos(
            np.pi * (np.arange(4 * (degree + 1)) + 0.5) / (4 * (degree + 1)))
        series = Chebyshev.fit(nodes, exact(nodes), degree, domain=[low, high])
        coefficients = series.convert(kind=Polynomial, domain=[-1.0, 1.0], window=[-1.0, 1.0]).coef
        if coefficients.size < 2:
            coefficients = np.append(coefficients, 0.0)
        if _relative_error(horner(coefficients, check), expect) <= tolerance:
            return coefficients
    return None


@dataclass(frozen=True)
class PiecewisePolynomial:
    """A polynomial per interval of a uniform grid on [0, ``top``).

    Attributes
    ----------
    coefficients : ndarray, shape (degree + 1, intervals)
        Per interval, increasing powers of the position ``s`` in [0, 1) within it.
    step : float
        Interval width (units of x).
    top : float
        End of the fitted range (units of x): ``step * intervals``.
    """

    coefficients: np.ndarray
    step: float
    top: float

    @property
    def intervals(self) -> int:
        """Number of intervals of the table (-)."""
        return self.coefficients.shape[1]

    @property
    def last_position(self) -> float:
        """Largest position inside the table (-), just below ``intervals``.

        Clipping to it leaves every position inside unchanged.
        """
        return float(np.nextafter(float(self.intervals), 0.0))

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Values at ``x`` (fresh array); see :meth:`at_positions`."""
        return self.at_positions(np.multiply(x, 1.0 / self.step))

    def at_positions(self, position: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Values at ``position = x / step`` (intervals from 0, -), into ``out`` (or a fresh array).

        Only meaningful for ``0 <= position < intervals``: elsewhere some interval's
        polynomial is evaluated (the caller replaces those samples). ``position``
        is read only. One gather of ``degree + 1`` coefficient rows and Horner's rule,
        both in one scratch block (one allocation, not ``degree + 2``).
        """
        degree = self.coefficients.shape[0] - 1
        index = position.astype(np.intp)                             # truncation = floor for x >= 0
        scratch = np.empty((degree + 2,) + position.shape)
        rows, within = scratch[:degree + 1], scratch[degree + 1]
        np.subtract(position, index, out=within)                     # s in [0, 1) (-)
        coefficients = self.coefficients
        for k in range(degree + 1):                                  # row by row: the fastest gather
            # mode='wrap': an index out of range (a sample the caller replaces) wraps round;
            # the method, not np.take: ~1 us less a call
            coefficients[k].take(index, out=rows[k], mode='wrap')
        value = rows[degree]
        for k in range(degree - 1, 0, -1):
            value *= within
            value += rows[k]
        value *= within
        return np.add(value, rows[0], out=out)


def fit_piecewise(exact: ArrayMap, top: float, intervals: int, degree: int,
                  tolerance: float) -> PiecewisePolynomial | None:
    """Fit ``exact`` on ``intervals`` uniform intervals of [0, top), each checked.

    Per interval a least-squares fit on ``2 (degree + 1)`` Chebyshev points; checked
    at 7 other points inside it. The table stops before the first interval whose
    relative error exceeds ``tolerance``.

    Parameters
    ----------
    exact : callable
        Vectorised map, nonzero on [0, top).
    top : float
        End of the range (units of x), > 0.
    intervals, degree : int
        Grid size and per-interval degree (>= 1).
    tolerance : float
        Largest relative error accepted (-).

    Returns
    -------
    PiecewisePolynomial or None
        None when even the first interval misses the tolerance.
    """
    if degree < 1 or intervals < 1 or not top > 0.0:
        raise ValueError(f'need degree >= 1, intervals >= 1, top > 0; got {degree}, {intervals}, {top}')
    step = top / intervals
    count = 2 * (degree + 1)
    nodes = 0.5 + 0.5 * np.cos(np.pi * (np.arange(count) + 0.5) / count)       # in (0, 1)
    starts = np.arange(intervals)[:, None]
    values = exact(((starts + nodes) * step).ravel()).reshape(intervals, count)
    vandermonde = np.vander(nodes, degree + 1, increasing=True)
    coefficients = np.linalg.lstsq(vandermonde, values.T, rcond=None)[0]         # (degree + 1, intervals)
    inside = (np.arange(7) + 0.5) / 7.0
    check = ((starts + inside) * step).ravel()
    expect = exact(check).reshape(intervals, inside.size)
    got = np.empty_like(expect)
    for k, s in enumerate(inside):
        got[:, k] = horner(coefficients, np.full(intervals, s))
    error = np.max(np.abs(got - expect) / np.maximum(np.abs(expect), np.finfo(float).tiny), axis=1)
    bad = np.flatnonzero(~(error <= tolerance))
    good = bad[0] if bad.size else intervals
    if good == 0:
        return None
    return PiecewisePolynomial(np.ascontiguousarray(coefficients[:, :good]), step, step * good)


def table_errors(model, currents: np.ndarray) -> dict:
    """Relative errors (-) of a model's vectorised fast path at ``currents`` (A), zero wrist.

    The accuracy check behind docs/model.md (speed) and its figure
    (``python -m grip_force_ros.lab.figures.model_tables``).

    Parameters
    ----------
    model : GripForceModel
        A nonlinear, wrist-independent instrument (its fitted tables are what is checked).
    currents : ndarray
        Motor currents (A), positive.

    Returns
    -------
    dict
        ``efficiency``: fitted lambda_n against the exact pulley chain;
        ``inverse``: the vectorised inverse of the needle grip force against the
        bracketed scalar solve; ``condition``: ``M / (I dM/dI)``, how much a relative
        error of the torque grows in the current (the floor any solver shares);
        ``table_end_current`` (A): where the inverse table ends (past it: Newton).
    """
    currents = np.asarray(currents, float)
    zero = np.zeros(())
    forward = model.forward(currents, zero, zero, 'needle')
    exact_efficiency = model._chain_efficiency(model.tension_per_amp * currents, zero)
    torque = forward.grip_force * model._tip                                  # N*m (needle: F_J = M / tip)
    exact_current = np.array([model._solve_current(float(t), 0.0, 0.0) for t in torque])
    inverse = model.inverse(forward.grip_force, zero, zero, 'needle')
    slope = np.array([(model._torque_scalar(i * (1 + 1e-7), 0.0) - model._torque_scalar(i, 0.0)) / (i * 1e-7)
                      for i in exact_current])                                 # dM/dI (N*m/A)
    fit = model._current_fit_built()
    return {'efficiency': np.abs(forward.efficiency / exact_efficiency - 1.0),
            'inverse': np.abs(inverse / exact_current - 1.0),
            'condition': torque / (exact_current * slope),
            'table_end_current': None if fit is None else model._solve_current(fit.top, 0.0, 0.0)}
