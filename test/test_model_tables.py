"""Fitted tables of the nonlinear model (grip_force_ros.model.tables) and their use.

The tables replace exact computations on the vectorised fast path; every result here is
held to the exact computation (the chain of pulleys, the bracketed scalar solve).
"""
import math

import numpy as np
import pytest
from hypothesis import example, given, settings, strategies as st

from grip_force_ros.model import GripForceModel, ModelError, tables
from grip_force_ros.model import friction
from grip_force_ros.params import load_params_file, make_params

FOUR = load_params_file('config/four_pulley_needle_driver.yaml')


def test_horner_equals_polyval():
    rng = np.random.default_rng(3)
    coefficients = rng.normal(size=6)
    x = rng.uniform(-2.0, 2.0, 200)
    np.testing.assert_allclose(tables.horner(coefficients, x),
                               np.polynomial.polynomial.polyval(x, coefficients), rtol=1e-13, atol=1e-13)
    out = np.empty_like(x)
    assert tables.horner(coefficients, x, out=out) is out


def test_fit_polynomial_takes_the_lowest_degree_within_tolerance():
    coefficients = tables.fit_polynomial(np.exp, 0.0, 0.5, 1e-14)
    assert coefficients is not None
    x = np.linspace(0.0, 0.5, 3001)
    error = np.max(np.abs(tables.horner(coefficients, x) / np.exp(x) - 1.0))
    assert error <= 1e-14
    # one degree lower misses the tolerance: the degree is the lowest that makes it
    lower = tables.fit_polynomial(np.exp, 0.0, 0.5, 1e-14, degrees=[coefficients.size - 2])
    assert lower is None


def test_fit_polynomial_gives_up_on_a_singular_map():
    assert tables.fit_polynomial(np.sqrt, 0.0, 1.0, 1e-12) is None     # sqrt is not smooth at 0


def test_piecewise_fit_stops_before_a_singularity():
    def singular(x):
        return 1.0 / np.sqrt(1.0 - x)                                   # blows up at x = 1
    fit = tables.fit_piecewise(singular, 1.0, 64, 3, 1e-7)
    assert fit is not None and 0.5 < fit.top < 1.0 and fit.intervals < 64
    x = np.linspace(0.0, fit.top, 5001, endpoint=False)
    np.testing.assert_allclose(fit(x), singular(x), rtol=1e-7)
    assert tables.fit_piecewise(singular, 1.0, 1, 3, 1e-7) is None       # one cubic cannot


@settings(max_examples=50, deadline=None)
@given(x=st.lists(st.floats(0.0, 0.999), min_size=1, max_size=20))
def test_piecewise_fit_matches_the_map_everywhere_inside(x):
    fit = _COSINE_FIT
    x = np.array(x) * fit.top
    # the fit is checked to 2e-14 at 7 points per interval; between them its error can be a
    # few ulps more (a developer's random example: 2.009e-14): 4e-14 (~180 ulps at 2.9)
    np.testing.assert_allclose(fit(x), np.cos(x) + 2.0, rtol=4e-14)


_COSINE_FIT = tables.fit_piecewise(lambda x: np.cos(x) + 2.0, 3.0, 128, 4, 2e-14)


# ----------------------------------------------------------------------------- in the model
def exact_efficiency(m, current):
    f0 = m.tension_per_amp * np.asarray(current, float)
    return friction.chain_efficiency(m.mu, m.radii, m.params.cable_radius, m.wraps, f0, m.friction_gain)


def test_the_four_pulley_model_uses_both_tables_beyond_max_current():
    m = GripForceModel(FOUR)
    assert m._one_dimensional
    m.forward(np.array([0.1, 0.2]), 0.0, 0.0)
    m.inverse(np.array([0.1, 0.2]), 0.0, 0.0)
    coefficients, top = m._efficiency_fit_built()
    assert top == pytest.approx(2.0 * FOUR.max_current * m.tension_per_amp)
    assert coefficients.size <= 12
    fit = m._current_fit_built()
    assert fit.top > m._torque_scalar(FOUR.max_current, 0.0)             # covers the whole current range


def test_paper_and_wrist_dependent_models_use_no_tables():
    assert not GripForceModel(make_params())._one_dimensional           # constant friction: closed form
    assert not GripForceModel(make_params().replace(tension_friction_gain=0.0008,
                                                    wrist_wrap_gain=0.3))._one_dimensional


def test_fitted_efficiency_equals_the_chain_inside_outside_and_at_the_edges():
    m = GripForceModel(FOUR)
    top_current = 2.0 * FOUR.max_current
    current = np.concatenate([np.linspace(-0.3, 3.0, 4001),
                              [0.0, -0.0, top_current, np.nextafter(top_current, 9.0), 1e-300, np.nan]])
    got = m.forward(current, 0.4, 0.1, 'rigid').efficiency
    expect = exact_efficiency(m, current)
    # NaN current: lambda at zero, as the chain
    np.testing.assert_allclose(got, expect, rtol=2e-14)
    assert got[-1] == m._efficiency_at_rest


@settings(max_examples=60, deadline=None)
@given(currents=st.lists(st.floats(1e-6, 1.25), min_size=1, max_size=30),
       obj=st.sampled_from(['needle', 'rigid', 'tissue']), jaw=st.floats(0.0, 1.4))
def test_fitted_inverse_recovers_the_current_up_to_near_the_peak(currents, obj, jaw):
    """Up to 1.25 A (the peak of M(I) is at ~1.29 A): table inside, Newton beyond, 1e-12."""
    m = _FOUR_MODEL
    current = np.array(currents)
    force = m.forward(current, 0.2, jaw, obj).grip_force
    np.testing.assert_allclose(m.inverse(force, 0.2, jaw, obj), current, rtol=1e-12)


_FOUR_MODEL = GripForceModel(FOUR)


def test_fitted_inverse_equals_the_bracketed_scalar_solve():
    m = GripForceModel(FOUR)
    torque = np.linspace(0.0, 1.05 * m._current_fit_built().top, 3001)    # N*m, past the table's end
    gain = 1.0 / m._tip                                                   # needle: F_J = M / tip
    got = m.inverse(torque * gain, 0.0, 0.0, 'needle')
    expect = [m._solve_current(float(t), 0.0, 0.0) for t in torque]
    np.testing.assert_allclose(got, expect, rtol=1e-13, atol=0.0)
    assert got[0] == 0.0
    with_velocity = m.inverse(torque * gain, 0.0, 0.0, 'needle', motor_velocity=0.0, jaw_velocity=-3.0)
    inertial = 0.5 * m._rn * FOUR.jaw_mass * 3.0                          # added to M (N*m)
    expect = [m._solve_current(float(t), 0.0, inertial) if t > inertial
              else (t - inertial) / m._torque_per_amp_at_rest for t in torque]
    np.testing.assert_allclose(with_velocity, expect, rtol=1e-13, atol=1e-18)


def test_fitted_inverse_still_refuses_unreachable_forces():
    m = GripForceModel(FOUR)
    peak = max(m._torque_scalar(i, 0.0) for i in np.linspace(1.0, 2.5, 1501))    # N*m, at ~1.58 A
    with pytest.raises(Exception, match='beyond the largest'):
        m.inverse(np.array([0.1, 1.01 * peak / m._tip]), 0.0, 0.0, 'needle')
    assert math.isfinite(float(m.inverse(np.array([0.99 * peak / m._tip]), 0.0, 0.0, 'needle')[0]))


def test_scalar_inverse_uses_the_table_and_equals_the_bracketed_solve():
    m = GripForceModel(FOUR)
    assert m._current_rows is not None and len(m._current_rows) == m._current_fit_built().intervals
    top = m._current_fit_built().top
    rng = np.random.default_rng(5)
    for torque in np.concatenate([rng.uniform(0.0, top, 300),
                                  [1e-12, np.nextafter(top, 0.0), top, 1.03 * top]]):
        for obj, jaw in (('needle', 0.0), ('rigid', 0.4), ('tissue', 0.9)):
            gain = float(m._contact_gain(obj, np.asarray(jaw)))
            got = m.current_for_force_scalar(torque * gain, 0.3, jaw, obj)
            assert got == pytest.approx(m._solve_current(torque * gain / gain, 0.3, 0.0), rel=1e-13)
    assert m.current_for_force_scalar(0.0, 0.3, 0.0, 'needle') == 0.0


def test_samples_outside_the_tables_raise_no_numpy_warnings():
    """Far outside the fits the clipped evaluation cannot overflow; those samples take the exact path."""
    m = GripForceModel(FOUR)
    current = np.array([1e40, -1e300, -1e40, np.nan, 0.3, 3.0])                 # A
    with np.errstate(all='ignore'):
        expect = exact_efficiency(m, current)
    with np.errstate(all='raise'):
        got = m.forward(current, 0.0, 0.0).efficiency
        np.testing.assert_allclose(got, expect, rtol=2e-14)
        with pytest.raises(Exception, match='beyond the largest'):
            m.inverse(np.array([1e20, 1.0]), 0.0, 0.0, 'needle')
        # torque < 0 first
        moving = m.inverse(np.array([0.0, 1.0, 6.2]), 0.0, 0.0, 'needle', jaw_velocity=-1e3)
        assert moving[0] < 0.0 < moving[1] < moving[2]


@settings(max_examples=25, deadline=None)
@given(mu=st.floats(0.03, 0.3), gain=st.floats(-5.0, -1.3), max_current=st.floats(0.05, 5.0),
       seed=st.integers(0, 2 ** 31))
@example(mu=0.2397755385726311, gain=-3.0, max_current=0.5, seed=0)
@example(mu=0.23828125, gain=-5.0, max_current=1.0, seed=0)   # lambda_n only 0.4 % above 0.5
def test_any_nonlinear_instrument_equals_the_exact_chain_and_solve(mu, gain, max_current, seed):
    """Random friction, tension gain (1e-5..0.05 1/N) and current range: tables or not, the same answers.

    ``gain`` is the log10 of ``tension_friction_gain`` (-5: 1e-5 1/N, a positive gain). With
    mu near 0.24 the paper's chain efficiency lambda_n is barely above the static resistance
    fraction (0.5): a physical, if useless, instrument (0.17 N of grip at 0.5 A), where the
    jaw torque r_n F0 (lambda_n - 0.5) is the small difference of two large terms.
    """
    m = GripForceModel(make_params().replace(pulley_friction_coefficient=mu,
                                             tension_friction_gain=10.0 ** gain, max_current=max_current))
    assert m._one_dimensional
    current = np.random.default_rng(seed).uniform(0.0, 2.0 * max_current, 40)      # A
    got = m.forward(current, 0.1, 0.0, 'needle')
    np.testing.assert_allclose(got.efficiency, exact_efficiency(m, current), rtol=2e-14)
    if m._torque_per_amp_at_rest <= 0.0:                          # lambda_n below the resistance: no grip
        with pytest.raises(ModelError, match='no grip force at any current'):
            m.inverse(np.array([0.0, 0.1]), 0.1, 0.0, 'needle')
        return
    rising = np.array([m._torque_scalar(i * (1 + 1e-6), 0.0) > m._torque_scalar(i, 0.0) for i in current])
    current = current[rising & (got.jaw_torque > 0.0)]                            # M(I) invertible there
    force = m.forward(current, 0.1, 0.0, 'needle').grip_force
    expect = np.array([m._solve_current(float(t), 0.1, 0.0) for t in force * m._tip])
    # near the peak of M(I) the inverse is ill-conditioned: a relative change of M moves I by
    # M / (I dM/dI) times as much, for the exact solvers as for the table
    slope = np.array([(m._torque_scalar(i * (1 + 1e-7), 0.1) - m._torque_scalar(i, 0.1)) / (i * 1e-7)
                      for i in expect])
    condition = force * m._tip / (expect * slope)
    # and the torque M = r_n F0 (lambda_n - fraction) turns a relative error of the fitted
    # lambda_n into lambda_n / (lambda_n - fraction) times as much of M (found by hypothesis:
    # mu 0.238, lambda_n 0.5015 at 1.46 A, 260x; the tables' lambda_n was within 2.2e-15)
    lam = exact_efficiency(m, expect)
    cancellation = lam / (lam - m.resistance_fraction)
    # plus a floor of 1e-14 of the current range: the cubics are fitted over the whole range,
    # so near 0 A their error is a few ulps of max_current, not of the sample (found by
    # hypothesis: 8e-16 A at 2.7 mA with max_current 0.5 A)
    allowed = 1e-13 * (1.0 + condition) * cancellation * expect + 1e-14 * max_current
    assert np.all(np.abs(m.inverse(force, 0.1, 0.0, 'needle') - expect) <= allowed)
    scalar = np.array([m.current_for_force_scalar(float(f), 0.1, 0.0) for f in force])
    assert np.all(np.abs(scalar - expect) <= allowed)


def test_scalar_solve_reaches_torques_just_below_the_peak():
    """Regression: the 1.5x bracket step could jump the peak of M(I): a reachable torque refused."""
    m = GripForceModel(make_params().replace(pulley_friction_coefficient=0.19615398009993856,
                                             tension_friction_gain=0.00026278885991678537,
                                             max_current=4.986189182156594))
    from scipy.optimize import minimize_scalar
    top = minimize_scalar(lambda i: -m._torque_scalar(i, 0.0), bounds=(1.0, 1.3), method='bounded',
                          options={'xatol': 1e-12})
    peak, at_peak = -top.fun, top.x                                         # N*m, A (~1.16 A)
    for fraction in (1 - 1e-3, 1 - 6e-6, 1 - 1e-7, 1 - 1e-9):     # the old code failed from ~1 - 6e-6
        current = m._solve_current(fraction * peak, 0.0, 0.0)
        assert m._torque_scalar(current, 0.0) == pytest.approx(fraction * peak, rel=1e-13)
        assert current <= at_peak + 1e-9                                    # the rising side
    with pytest.raises(ModelError, match='beyond the largest'):
        m._solve_current(1.001 * peak, 0.0, 0.0)


def test_table_errors_and_their_figure(tmp_path):
    from grip_force_ros.lab.figures.model_tables import plot_table_errors
    from grip_force_ros.model.tables import table_errors
    m = GripForceModel(FOUR)
    errors = table_errors(m, np.linspace(0.01, 1.0, 60))
    assert errors['efficiency'].max() <= m.EFFICIENCY_FIT_TOLERANCE
    assert errors['inverse'].max() <= m.CURRENT_FIT_TOLERANCE
    # the inverse table covers the current range (to 2 max_current = 1 A), not stopping short
    # at the torque peak (before 1 A with a 0.3 mm cable)
    assert FOUR.max_current < errors['table_end_current'] <= 2 * FOUR.max_current * (1 + 1e-12)
    # M concave, far from the peak
    assert np.all((errors['condition'] >= 1.0) & (errors['condition'] < 10.0))
    path = plot_table_errors('config/four_pulley_needle_driver.yaml', tmp_path / 'e.png', samples=40)
    assert path.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
