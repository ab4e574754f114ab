"""Cable-pulley friction: tension along a wrap, pulley ratio eta, chain efficiency lambda.

A cable of radius ``r`` wrapped over a pulley of radius ``R`` by an angle ``theta``
with friction coefficient ``mu``. Seen from its slack (output) end the tension grows
along the wrap as (paper, eq. of F(theta))::

    F(theta) = C1 e^(a theta) + C2 e^(b theta),  C1 = b F_i/(b - a),  C2 = a F_i/(a - b)
    a, b = (-1 - rho +- sqrt((1 + rho)^2 + 4 mu^2 rho)) / (2 mu),  rho = (R - r)/r

so ``F(theta)/F_i = eta(theta) = (a e^(b theta) - b e^(a theta))/(a - b) >= 1`` is the
tight/slack ratio of one pulley, and a chain of pulleys passes ``lambda_n = 1/(eta_1 ...
eta_n) <= 1`` of the drum tension to the jaw.

Limits (tested): mu -> 0 gives eta = 1 (no loss); r/R -> 0 (rho -> inf) gives a -> mu,
b -> -inf, eta -> e^(mu theta) (the capstan law).

Everything here takes plain floats or numpy arrays (broadcast) in SI units.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ['exponents', 'exponents_scalar', 'pulley_ratio', 'pulley_ratio_scalar',
           'tension_along_wrap', 'wrap_excess_integral', 'chain_efficiency',
           'chain_tensions', 'friction_at_tension']


def exponents(mu, pulley_radius, cable_radius):
    """Exponents a >= 0 and b < 0 of the tension along a wrap.

    Parameters
    ----------
    mu : float or array
        Cable-pulley friction coefficient (-), > 0.
    pulley_radius : float or array
        Effective pulley radius R (m).
    cable_radius : float or array
        Cable radius r (m), r < R.

    Returns
    -------
    a, b : arrays (1/rad)
        ``a`` is computed in the cancellation-free form
        ``2 mu rho / ((1 + rho) + sqrt(...))`` so it stays exact as mu -> 0.
    """
    mu = np.asarray(mu, dtype=float)
    cable = np.asarray(cable_radius, float)
    rho = (np.asarray(pulley_radius, float) - cable) / cable
    root = np.sqrt((1.0 + rho) ** 2 + 4.0 * mu ** 2 * rho)
    a = 2.0 * mu * rho / ((1.0 + rho) + root)            # paper: a = (-1 - rho + sqrt(.))/(2 mu)
    with np.errstate(divide='ignore'):
        b = -((1.0 + rho) + root) / (2.0 * mu)           # paper: b = (-1 - rho - sqrt(.))/(2 mu)
    return a, b


def exponents_scalar(mu: float, pulley_radius: float, cable_radius: float) -> tuple[float, float]:
    """Scalar :func:`exponents` (pure math). ``b = -inf`` when ``mu == 0``."""
    rho = (pulley_radius - cable_radius) / cable_radius
    root = math.sqrt((1.0 + rho) ** 2 + 4.0 * mu * mu * rho)
    a = 2.0 * mu * rho / ((1.0 + rho) + root)
    b = -((1.0 + rho) + root) / (2.0 * mu) if mu > 0.0 else -math.inf
    return a, b


def pulley_ratio(mu, pulley_radius, cable_radius, wrap_angle):
    """Tight/slack tension ratio eta of one pulley (-), >= 1.

    ``eta = (a e^(b theta) - b e^(a theta)) / (a - b)`` (paper, eta_i); exactly 1 for
    mu == 0 or theta == 0.

    Parameters
    ----------
    mu, pulley_radius, cable_radius : float or array
        See :func:`exponents`.
    wrap_angle : float or array
        Wrap angle theta (rad), >= 0.
    """
    mu = np.asarray(mu, dtype=float)
    theta = np.asarray(wrap_angle, dtype=float)
    a, b = exponents(np.where(mu > 0.0, mu, 1.0), pulley_radius, cable_radius)
    # divide (a e^(b th) - b e^(a th)) by -b: well conditioned even for b -> -inf
    weight = a / (a - b)                                  # in [0, 1)
    eta = weight * np.exp(b * theta) + (1.0 - weight) * np.exp(a * theta)
    return np.where(mu > 0.0, eta, 1.0)


def pulley_ratio_scalar(a: float, b: float, wrap_angle: float) -> float:
    """Scalar eta from precomputed exponents (pure math, control-loop fast path)."""
    if b == -math.inf:
        return 1.0
    weight = a / (a - b)
    return weight * math.exp(b * wrap_angle) + (1.0 - weight) * math.exp(a * wrap_angle)


def tension_along_wrap(slack_tension, mu, pulley_radius, cable_radius, angle):
    """Tension F(alpha) at angle ``alpha`` from the slack end (N): ``F_i * eta(alpha)``.

    Same as the paper's ``C1 e^(a alpha) + C2 e^(b alpha)`` with ``F_i`` the slack tension.
    """
    return np.asarray(slack_tension, float) * pulley_ratio(mu, pulley_radius, cable_radius, angle)


def wrap_excess_integral(mu, pulley_radius, cable_radius, wrap_angle):
    """``int_0^theta (eta(alpha) - 1) d alpha`` (rad), >= 0, in closed form.

    ``int eta = [w (e^(b th) - 1)/b + (1 - w)(e^(a th) - 1)/a]`` with ``w = a/(a - b)``.
    This is minus the paper's ``int (1 - eta_i)``; the creep of the wrapped cable is
    proportional to it (see :mod:`grip_force_ros.model.angle`). 0 when mu == 0.
    """
    mu = np.asarray(mu, dtype=float)
    theta = np.asarray(wrap_angle, dtype=float)
    a, b = exponents(np.where(mu > 0.0, mu, 1.0), pulley_radius, cable_radius)
    weight = a / (a - b)
    with np.errstate(divide='ignore', invalid='ignore'):
        rise = np.where(a > 0.0, np.expm1(a * theta) / np.where(a > 0.0, a, 1.0), theta)
    fall = np.expm1(b * theta) / b
    excess = weight * fall + (1.0 - weight) * rise - theta
    return np.where(mu > 0.0, np.maximum(excess, 0.0), 0.0)


def friction_at_tension(mu, tension, gain):
    """Tension-dependent friction ``mu (1 + gain * max(F, 0))`` (-).

    ``gain`` (1/N) = 0 is the paper's constant-mu model. The paper reports that
    friction losses grow with tension (efficiency down by up to 25% at maximum
    current) without a law; this linear law is our assumption.
    """
    return np.asarray(mu, float) * (1.0 + np.asarray(gain, float) * np.maximum(tension, 0.0))


def chain_tensions(drum_tension, mu, pulley_radii, cable_radius, wrap_angles, gain=0.0):
    """Tension entering each pulley and leaving the last one (N).

    Parameters
    ----------
    drum_tension : float or array
        Tension F0 leaving the drum (N).
    mu : float
        Friction coefficient at zero tension (-).
    pulley_radii, wrap_angles : sequence of float or arrays
        Per pulley, in order from the drum (m, rad). Elements may be arrays that
        broadcast with ``drum_tension`` (e.g. a wrap angle that depends on the wrist).
    cable_radius : float
        Cable radius (m).
    gain : float
        Tension-dependent friction gain (1/N), see :func:`friction_at_tension`.
        Each pulley sees the friction of the tension entering it.

    Returns
    -------
    list of arrays
        ``[F0, F0 lambda_1, ..., F0 lambda_n]``.
    """
    tensions = [np.asarray(drum_tension, float)]
    for radius, wrap in zip(pulley_radii, wrap_angles):
        mu_here = friction_at_tension(mu, tensions[-1], gain)
        tensions.append(tensions[-1] / pulley_ratio(mu_here, radius, cable_radius, wrap))
    return tensions


def chain_efficiency(mu, pulley_radii, cable_radius, wrap_angles, drum_tension=0.0, gain=0.0):
    """Total efficiency ``lambda_n = 1/(eta_1 ... eta_n)`` of a pulley chain (-).

    With ``gain > 0`` the efficiency depends on ``drum_tension`` (N); at zero
    tension, and always for ``gain == 0``, it is the paper's constant-mu lambda_n.
    """
    if np.all(np.asarray(gain) == 0.0):
        out = np.ones(np.broadcast(np.asarray(drum_tension, float), *map(np.asarray, wrap_angles)).shape)
        for radius, wrap in zip(pulley_radii, wrap_angles):
            out = out / pulley_ratio(mu, radius, cable_radius, wrap)
        return out
    f0 = np.asarray(drum_tension, float)
    probe = np.where(f0 > 0.0, f0, 1.0)
    chain = chain_tensions(probe, mu, pulley_radii, cable_radius, wrap_angles, gain)
    at_zero = chain_efficiency(mu, pulley_radii, cable_radius, wrap_angles)
    return np.where(f0 > 0.0, chain[-1] / probe, at_zero)
