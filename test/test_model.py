"""The grip-force model: each equation against hand-computed values, the limits, the round trip."""
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.integrate import quad, solve_ivp

from grip_force_ros.model import OBJECTS, GripForceModel, ModelError, check_instrument
from grip_force_ros.model import angle, contact, friction, transmission
from grip_force_ros.params import ParameterError, load_params_file, make_params

CONFIGS = ['config/paper_needle_driver.yaml', 'config/long_jaw_grasper.yaml',
           'config/four_pulley_needle_driver.yaml']
PAPER = make_params()


def paper_exponents(mu, R, r):
    """a, b exactly as printed in the paper (with the cancellation)."""
    rho = (R - r) / r
    root = math.sqrt((1 + rho) ** 2 + 4 * mu ** 2 * rho)
    return (-1 - rho + root) / (2 * mu), (-1 - rho - root) / (2 * mu)


# ----------------------------------------------------------------------------- friction
def test_exponents_match_the_paper_formula():
    a, b = friction.exponents(0.15, 0.003, 0.0002)
    pa, pb = paper_exponents(0.15, 0.003, 0.0002)
    assert a == pytest.approx(pa, rel=1e-12) and b == pytest.approx(pb, rel=1e-12)
    # rho = 14: a = (-15 + sqrt(225 + 4*0.0225*14)) / 0.3 by hand
    assert a == pytest.approx((-15 + math.sqrt(226.26)) / 0.3, rel=1e-12)
    assert friction.exponents_scalar(0.15, 0.003, 0.0002) == pytest.approx((a, b), rel=1e-15)


def test_eta_is_the_tension_ratio_of_c1_c2_form():
    mu, R, r, theta, f_in = 0.15, 0.003, 0.0002, math.pi / 2, 10.0
    a, b = paper_exponents(mu, R, r)
    c1, c2 = b * f_in / (b - a), a * f_in / (a - b)
    tension = c1 * math.exp(a * theta) + c2 * math.exp(b * theta)       # paper F(theta)
    assert float(friction.tension_along_wrap(f_in, mu, R, r, theta)) == pytest.approx(tension, rel=1e-12)
    assert float(friction.pulley_ratio(mu, R, r, theta)) == pytest.approx(tension / f_in, rel=1e-12)
    assert friction.pulley_ratio_scalar(a, b, theta) == pytest.approx(tension / f_in, rel=1e-12)


def test_tension_solves_the_wrap_equilibrium_ode():
    # the exponents are the roots of mu s^2 + (1 + rho) s - mu rho = 0, with F(0) = F_i, F'(0) = 0
    mu, R, r = 0.2, 0.003, 0.0004
    rho = (R - r) / r
    sol = solve_ivp(lambda t, y: [y[1], (mu * rho * y[0] - (1 + rho) * y[1]) / mu], (0, 2.0),
                    [1.0, 0.0], rtol=1e-11, atol=1e-13, dense_output=True)
    angles = np.linspace(0, 2.0, 9)
    np.testing.assert_allclose(friction.pulley_ratio(mu, R, r, angles), sol.sol(angles)[0], rtol=1e-8)


def test_eta_is_at_least_one_and_grows_with_wrap():
    eta = friction.pulley_ratio(0.15, 0.003, 0.0002, np.linspace(0, 2 * np.pi, 50))
    assert eta[0] == 1.0 and np.all(np.diff(eta) > 0)


def test_paper_lambda3_with_the_assumed_cable_radius():
    a, b = paper_exponents(0.15, 0.003, 0.0002)
    eta = [(a * math.exp(b * t) - b * math.exp(a * t)) / (a - b)
           for t in (math.pi / 2, math.pi / 4, math.pi / 4)]
    by_hand = 1 / (eta[0] * eta[1] * eta[2])
    assert by_hand == pytest.approx(0.6472, abs=1e-4)
    lam = friction.chain_efficiency(0.15, (0.003,) * 3, 0.0002, (math.pi / 2, math.pi / 4, math.pi / 4))
    assert float(lam) == pytest.approx(by_hand, rel=1e-12)
    assert float(GripForceModel(PAPER).efficiency()) == pytest.approx(by_hand, rel=1e-12)


@given(theta=st.floats(0.0, 2 * math.pi), radius_ratio=st.floats(0.01, 0.5))
def test_no_friction_no_loss(theta, radius_ratio):
    assert float(friction.pulley_ratio(0.0, 0.003, 0.003 * radius_ratio, theta)) == 1.0
    assert float(friction.pulley_ratio(1e-12, 0.003, 0.003 * radius_ratio, theta)) \
        == pytest.approx(1.0, abs=1e-11)
    assert float(friction.wrap_excess_integral(0.0, 0.003, 0.003 * radius_ratio, theta)) == 0.0


@given(mu=st.floats(0.01, 0.6), theta=st.floats(0.0, 2 * math.pi))
def test_thin_cable_gives_the_capstan_law(mu, theta):
    # r/R -> 0: eta -> e^(mu theta); the error shrinks like r/R
    eta = float(friction.pulley_ratio(mu, 1.0, 1e-9, theta))
    assert eta == pytest.approx(math.exp(mu * theta), rel=1e-6)
    a, b = friction.exponents(mu, 1.0, 1e-9)
    assert float(a) == pytest.approx(mu, rel=1e-6) and float(b) < -1e8


def test_wrap_excess_integral_matches_quadrature():
    mu, R, r, theta = 0.15, 0.003, 0.0002, math.pi / 2
    ref, _ = quad(lambda x: float(friction.pulley_ratio(mu, R, r, x)) - 1.0, 0, theta, epsabs=1e-14)
    assert float(friction.wrap_excess_integral(mu, R, r, theta)) == pytest.approx(ref, rel=1e-9)


def test_tension_dependent_friction_lowers_efficiency_with_tension():
    radii, wraps = (0.003,) * 3, (math.pi / 2, math.pi / 4, math.pi / 4)
    lam = friction.chain_efficiency(0.15, radii, 0.0002, wraps, drum_tension=[0.0, 100.0, 200.0], gain=1e-3)
    assert lam[0] == pytest.approx(float(friction.chain_efficiency(0.15, radii, 0.0002, wraps)), rel=1e-12)
    assert lam[0] > lam[1] > lam[2]
    # pulley 1 at 200 N sees mu = 0.15 * 1.2 = 0.18
    t = friction.chain_tensions(200.0, 0.15, radii, 0.0002, wraps, gain=1e-3)
    assert float(t[1]) == pytest.approx(
        200.0 / float(friction.pulley_ratio(0.18, 0.003, 0.0002, math.pi / 2)))


# ----------------------------------------------------------------------------- transmission
def test_drum_tension_and_drive_torque_by_hand():
    f0 = float(transmission.drum_tension(0.35, 1.44, 1.23, 0.004))
    assert f0 == pytest.approx(1.44 * 1.23 * 0.35 / 0.004)          # 154.98 N, paper 1.77 I / r0
    assert float(transmission.drive_torque(f0, 0.765, 0.0025, 0.5)) == pytest.approx(f0 * 0.0025 * 0.265)
    assert float(transmission.static_resistance(f0, 0.0025, 1.0)) == pytest.approx(0.0025 * f0)
    # r_n (m_n thd_n - m0 thd_0) / 2 = 0.0025 * (0.001*16 - 0.0025*10) / 2
    assert float(transmission.inertial_moment(16.0, 10.0, 0.0025, 0.001, 0.0025)) == pytest.approx(-1.125e-5)


def test_model_torque_slope_by_hand():
    slope, offset = GripForceModel(PAPER).torque_coefficients()
    lam = float(GripForceModel(PAPER).efficiency())
    assert slope == pytest.approx(1.44 * 1.23 / 0.004 * 0.0025 * (lam - 0.5), rel=1e-12)
    assert offset == 0.0
    ideal = GripForceModel(PAPER, losses=False)
    assert ideal.torque_coefficients()[0] == pytest.approx(1.44 * 1.23 / 0.004 * 0.0025)


# ----------------------------------------------------------------------------- contact
def test_contact_forces_by_hand():
    torque, opening = 0.1, math.pi / 6
    assert float(contact.contact_gain('rigid', opening, 0.012, 0.0095)) * torque == pytest.approx(
        torque / 0.012 * math.cos(opening))
    assert float(contact.contact_gain('tissue', opening, 0.012, 0.0095)) * torque == pytest.approx(
        2 * torque * math.cos(opening) / 0.0215)
    assert float(contact.contact_gain('needle', opening, 0.012, 0.0095)) == pytest.approx(1 / 0.012)
    assert float(contact.contact_gain('free', opening, 0.012, 0.0095)) == 0.0
    assert float(contact.contact_gain('rigid', 2.0, 0.012, 0.0095)) == 0.0      # open past pi/2
    for obj in OBJECTS:
        assert contact.contact_gain_scalar(obj, 0.3, 0.012, 0.0095) == pytest.approx(
            float(contact.contact_gain(obj, 0.3, 0.012, 0.0095)), rel=1e-15)


def test_needle_three_point_contact():
    f1, f2, f3 = contact.needle_normal_forces(10.0)
    assert float(f1) == pytest.approx((float(f2) + float(f3)) * math.cos(math.pi / 4))   # force balance
    pull = float(contact.needle_pull_out(10.0, 0.15))
    assert pull == pytest.approx(0.15 * (f1 + f2 + f3)) and pull == pytest.approx((math.sqrt(2) + 1) * 1.5)


def test_unknown_object_is_a_model_error():
    with pytest.raises(ModelError, match='unknown object'):
        GripForceModel(PAPER).forward(0.3, 0, 0, obj='suture')
    with pytest.raises(ValueError):
        GripForceModel(PAPER).grip_force_scalar(0.3, 0, 0, 'bone')


# ----------------------------------------------------------------------------- angle
def test_creep_by_hand():
    f0, lam = 100.0, 0.8
    ea = angle.cable_section_stiffness(1.25e11, 0.0002)
    assert ea == pytest.approx(1.25e11 * math.pi * 4e-8)
    got = float(angle.wrap_creep_angle(f0, 0.15, (0.003,), 0.0002, (math.pi / 2,), ea, 0.0025))
    lam1 = 1 / float(friction.pulley_ratio(0.15, 0.003, 0.0002, math.pi / 2))
    integral, _ = quad(lambda x: float(friction.pulley_ratio(0.15, 0.003, 0.0002, x)) - 1, 0, math.pi / 2)
    assert got == pytest.approx(f0 * lam1 * 0.003 / ea * integral / 0.0025, rel=1e-9)
    assert lam != lam1   # (the slack-end tension is F0 lambda_1, not a free number)


def test_jaw_angle_coupling_and_inverse():
    m = GripForceModel(PAPER)
    assert float(m.jaw_angle(0.1, 0.0, 0.0)) == pytest.approx(-1.6 * 0.1)       # r0 / r_n
    assert float(m.jaw_angle(0.0, 0.5, 0.0)) == pytest.approx(0.6 * 0.5)        # 3/5 coupling
    assert float(m.jaw_angle(0.0, 0.0, 0.3)) > 0.0                               # creep opens the jaw
    assert float(GripForceModel(PAPER, losses=False).jaw_angle(0.0, 0.0, 0.3)) == 0.0
    jaw = m.jaw_angle(np.array([-0.3, 0.2]), 0.4, np.array([0.1, 0.45]))
    np.testing.assert_allclose(m.motor_angle(jaw, 0.4, [0.1, 0.45]), [-0.3, 0.2], rtol=1e-12)
    # the coefficient in the paper's convention is small and negative
    assert -0.05 < m.creep_coefficient() < 0.0


# ----------------------------------------------------------------------------- forward / inverse
def test_forward_by_hand_and_shapes():
    m = GripForceModel(PAPER)
    lam = float(m.efficiency())
    r = m.forward(np.array([0.0, 0.2, 0.5]), 0.0, math.pi / 6, 'rigid')
    expect = 442.8 * np.array([0.0, 0.2, 0.5]) * 0.0025 * (lam - 0.5) / 0.012 * math.cos(math.pi / 6)
    np.testing.assert_allclose(r.grip_force, expect, rtol=1e-12)
    assert r.grip_force.shape == r.efficiency.shape == r.drum_tension.shape == (3,)
    assert np.all(np.isnan(r.pull_out_force))
    grid = m.forward(np.linspace(0, .5, 4)[:, None], np.linspace(0, 1, 5)[None, :], 0.0, 'needle')
    assert grid.grip_force.shape == (4, 5)
    np.testing.assert_allclose(grid.pull_out_force, (math.sqrt(2) + 1) * 0.15 * grid.grip_force)
    assert np.all(m.forward(0.4, 0.1, 0.2, 'free').grip_force == 0.0)
    assert float(m.forward(-0.3, 0.0, 0.0, 'needle').grip_force) == 0.0     # opening current: no grip


def test_velocity_term_changes_torque_a_little():
    m = GripForceModel(PAPER)
    still = float(m.forward(0.3, 0, 0.1, 'needle').jaw_torque)
    moving = float(m.forward(0.3, 0, 0.1, 'needle', motor_velocity=10.0, jaw_velocity=-16.0).jaw_torque)
    assert moving - still == pytest.approx(0.5 * 0.0025 * (0.001 * 16.0 - 0.0025 * 10.0))


@pytest.mark.parametrize('path', CONFIGS)
@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_inverse_of_forward_is_identity(path, data):
    params = load_params_file(path)
    m = GripForceModel(params)
    obj = data.draw(st.sampled_from(['rigid', 'tissue', 'needle']))
    current = data.draw(st.floats(0.005, params.max_current))
    wrist = data.draw(st.floats(-params.wrist_angle_limit, params.wrist_angle_limit))
    # operating range: up to the mechanical open stop pi/2 (jaw_angle_max adds a noise margin)
    jaw = data.draw(st.floats(params.jaw_angle_min, min(params.jaw_angle_max, math.pi / 2) - 0.05))
    mv, jv = data.draw(st.floats(-20, 20)), data.draw(st.floats(-20, 20))
    force = m.forward(current, wrist, jaw, obj, mv, jv).grip_force
    assert float(m.inverse(force, wrist, jaw, obj, mv, jv)) == pytest.approx(current, rel=1e-9)
    scalar_force = m.grip_force_scalar(current, wrist, jaw, obj)
    assert scalar_force == pytest.approx(float(m.forward(current, wrist, jaw, obj).grip_force), rel=1e-12)
    assert m.current_for_force_scalar(scalar_force, wrist, jaw, obj) == pytest.approx(current, rel=1e-9)


def test_inverse_vectorised_over_a_grid():
    for path in CONFIGS:
        m = GripForceModel(load_params_file(path))
        currents = np.linspace(0.01, 0.5, 7)[:, None]
        jaws = np.linspace(0, 1.4, 5)[None, :]
        force = m.forward(currents, 0.3, jaws, 'tissue').grip_force
        np.testing.assert_allclose(m.inverse(force, 0.3, jaws, 'tissue'),
                                   np.broadcast_to(currents, force.shape), rtol=1e-9)


def test_inverse_errors():
    m = GripForceModel(PAPER)
    with pytest.raises(ModelError, match='no contact'):
        m.inverse(1.0, 0, 0, 'free')
    with pytest.raises(ModelError, match='no contact'):
        m.current_for_force_scalar(1.0, 0, 2.0, 'rigid')
    with pytest.raises(ModelError, match='>= 0'):
        m.inverse(-1.0, 0, 0, 'needle')
    with pytest.raises(ModelError, match='>= 0'):
        m.current_for_force_scalar(float('nan'), 0, 0, 'needle')
    assert m.current_for_force_scalar(0.0, 0, 0, 'free') == 0.0
    weak = GripForceModel(PAPER.replace(drive_resistance_fraction=0.9))
    with pytest.raises(ModelError, match='no grip force at any current'):
        weak.current_for_force_scalar(1.0, 0, 0, 'needle')
    nonlinear = GripForceModel(PAPER.replace(tension_friction_gain=0.005))
    with pytest.raises(ModelError, match='beyond the largest'):
        nonlinear.current_for_force_scalar(50.0, 0, 0, 'needle')


def test_ideal_model_has_no_friction_loss():
    ideal = GripForceModel(PAPER.replace(tension_friction_gain=0.01), losses=False)
    assert float(ideal.efficiency(0.5)) == 1.0
    f = ideal.grip_force_scalar(0.5, 0.7, 0.0, 'needle')
    assert f == pytest.approx(0.5 * 442.8 * 0.0025 / 0.012)


def test_wrist_wrap_gain_lowers_efficiency_with_wrist_angle():
    m = GripForceModel(PAPER.replace(wrist_wrap_gain=0.5))
    lam = m.efficiency(0.0, np.array([0.0, 0.5, -0.5, 1.0]))
    assert lam[0] > lam[1] > lam[3] and lam[1] == pytest.approx(lam[2])
    assert m.grip_force_scalar(0.3, 1.0, 0.1, 'rigid') == pytest.approx(
        float(m.forward(0.3, 1.0, 0.1, 'rigid').grip_force), rel=1e-12)


def test_inconsistent_geometry_is_rejected():
    with pytest.raises(ParameterError, match='cable_radius'):
        PAPER.replace(cable_radius=0.004)
    with pytest.raises(ParameterError, match='guide_pulley_wrap_angles'):
        PAPER.replace(guide_pulley_radii=[0.003, 0.003])
    with pytest.raises(ModelError, match='cable_radius'):  # built without the schema
        check_instrument(dict(PAPER, cable_radius=0.004))


@given(mu=st.floats(0.02, 0.5), theta=st.floats(0.1, 2 * math.pi),
       r1=st.floats(1e-5, 2.9e-3), r2=st.floats(1e-5, 2.9e-3))
def test_thicker_cable_loses_less(mu, theta, r1, r2):
    # rho falls as r grows, so eta falls towards 1: the capstan e^(mu theta) is the worst case
    thin, thick = sorted((r1, r2))
    eta_thin = float(friction.pulley_ratio(mu, 0.003, thin, theta))
    eta_thick = float(friction.pulley_ratio(mu, 0.003, thick, theta))
    assert 1.0 <= eta_thick <= eta_thin * (1 + 1e-12) <= math.exp(mu * theta) * (1 + 1e-12)


@given(motor=st.floats(-2, 2), wrist=st.floats(-1.5, 1.5), current=st.floats(-0.5, 0.5))
def test_motor_angle_inverts_jaw_angle(motor, wrist, current):
    m = GripForceModel(load_params_file('config/long_jaw_grasper.yaml'))
    jaw = m.jaw_angle(motor, wrist, current)
    assert float(m.motor_angle(jaw, wrist, current)) == pytest.approx(motor, abs=1e-12)


def test_creep_grows_with_current_and_is_odd():
    m = GripForceModel(PAPER)
    finger, wrist = m.creep_angles(np.array([-0.4, 0.0, 0.2, 0.4]))
    assert finger[1] == 0.0 and finger[3] == pytest.approx(2 * finger[2]) \
        and finger[0] == pytest.approx(-finger[3])
    assert np.all(wrist[2:] > 0.0)
