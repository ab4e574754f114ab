"""The vectorised forward/inverse fast paths equal the straightforward computation.

The reference is built from the module functions (friction.chain_efficiency,
transmission.drive_torque, contact.contact_gain), one plain numpy expression per
equation, and for the nonlinear inverse the per-sample bracketed solve.
"""
import numpy as np
import pytest

from grip_force_ros.model import OBJECTS, GripForceModel, ModelError
from grip_force_ros.model import contact, friction, transmission
from grip_force_ros.params import load_params_file, make_params

PAPER = make_params()
MODELS = {
    'paper': lambda: GripForceModel(PAPER),
    'paper_wrist_gain': lambda: GripForceModel(PAPER.replace(wrist_wrap_gain=0.4)),
    'ideal': lambda: GripForceModel(PAPER.replace(wrist_wrap_gain=0.4), losses=False),
    'long_jaw': lambda: GripForceModel(load_params_file('config/long_jaw_grasper.yaml')),
    'four_pulley': lambda: GripForceModel(load_params_file('config/four_pulley_needle_driver.yaml')),
    'frictionless_with_gain': lambda: GripForceModel(PAPER.replace(pulley_friction_coefficient=0.0,
                                                                   tension_friction_gain=0.001)),
    'nonlinear_wrist_gain': lambda: GripForceModel(PAPER.replace(tension_friction_gain=0.0008,
                                                                 wrist_wrap_gain=0.3)),
}


def reference_forward(m, current, wrist, jaw, obj, mv=0.0, jv=0.0):
    """Straightforward forward: every equation on broadcast arrays, no shortcut."""
    p = m.params
    current, wrist, jaw, mv, jv = np.broadcast_arrays(
        *(np.asarray(x, float) for x in (current, wrist, jaw, mv, jv)))
    f0 = m.tension_per_amp * current
    wraps = [*m.wraps[:-1], m.wraps[-1] + m.wrist_wrap_gain * np.abs(wrist)]
    lam = friction.chain_efficiency(m.mu, m.radii, p.cable_radius, wraps, f0, m.friction_gain)
    inertial = transmission.inertial_moment(-jv, mv, p.drive_pulley_radius, p.jaw_mass, p.drum_mass)
    torque = transmission.drive_torque(f0, lam, p.drive_pulley_radius, m.resistance_fraction, inertial)
    gain = contact.contact_gain(obj, jaw, p.jaw_moment_arm_tip, p.jaw_moment_arm_inner)
    grip = np.maximum(torque, 0.0) * gain
    return grip, np.broadcast_to(lam, grip.shape), torque, f0


def inputs(seed, shape_current, shape_wrist, shape_jaw):
    rng = np.random.default_rng(seed)
    current = rng.uniform(-0.1, 0.5, shape_current)                 # A, some opening
    wrist = rng.uniform(-0.8, 0.8, shape_wrist)                     # rad, both signs
    jaw = rng.uniform(0.0, 1.7, shape_jaw)                          # rad, a few past pi/2
    return current, wrist, jaw


SHAPES = [((), (), ()), ((50,), (50,), (50,)), ((50,), (), ()), ((), (40,), ()),
          ((6, 1), (1, 7), (7,)), ((3, 1, 1), (1, 4, 1), (1, 1, 5))]


@pytest.mark.parametrize('name', MODELS)
@pytest.mark.parametrize('shapes', SHAPES, ids=str)
def test_forward_equals_the_straightforward_computation(name, shapes):
    m = MODELS[name]()
    current, wrist, jaw = inputs(1, *shapes)
    for obj in OBJECTS:
        for mv, jv in ((0.0, 0.0), (12.0, -7.0)):
            r = m.forward(current, wrist, jaw, obj, mv, jv)
            grip, lam, torque, f0 = reference_forward(m, current, wrist, jaw, obj, mv, jv)
            shape = np.broadcast_shapes(*shapes)
            for got in (r.grip_force, r.pull_out_force, r.jaw_torque, r.efficiency, r.drum_tension):
                assert np.shape(got) == shape
            np.testing.assert_allclose(r.efficiency, lam, rtol=1e-12)
            np.testing.assert_allclose(r.drum_tension, f0, rtol=1e-12)
            np.testing.assert_allclose(r.jaw_torque, torque, rtol=1e-12, atol=1e-15)
            np.testing.assert_allclose(r.grip_force, grip, rtol=1e-12, atol=1e-13)
            if obj == 'needle':
                pull = contact.PULL_OUT_PER_MU * m.params.needle_friction_coefficient * grip
                np.testing.assert_allclose(r.pull_out_force, pull, rtol=1e-12)
            elif obj == 'free':
                assert np.all(r.pull_out_force == 0.0) and np.all(r.grip_force == 0.0)
            else:
                assert np.all(np.isnan(r.pull_out_force))


def test_forward_outputs_are_writable_and_independent():
    r = GripForceModel(PAPER).forward(np.linspace(0, 0.5, 5), 0.0, 0.1, 'needle')
    before = r.drum_tension.copy()
    r.grip_force[:] = -1.0
    r.efficiency[:] = 2.0
    np.testing.assert_array_equal(r.drum_tension, before)
    assert np.all(r.pull_out_force >= 0.0)


def test_efficiency_with_wrist_gain_is_even_and_falls_with_the_wrist():
    m = MODELS['paper_wrist_gain']()
    wrist = np.linspace(-1.0, 1.0, 21)
    lam = m.forward(0.3, wrist, 0.0).efficiency
    np.testing.assert_allclose(lam, lam[::-1], rtol=1e-15)
    assert np.all(np.diff(lam[10:]) < 0.0)
    assert lam[10] == pytest.approx(GripForceModel(PAPER).forward(0.3, 0.0, 0.0).efficiency, rel=1e-14)


@pytest.mark.parametrize('name', MODELS)
@pytest.mark.parametrize('shapes', SHAPES, ids=str)
def test_inverse_equals_the_straightforward_computation(name, shapes):
    m = MODELS[name]()
    current, wrist, jaw = inputs(2, *shapes)
    current = np.abs(current) + 0.01                                 # closing currents (A)
    jaw = np.minimum(jaw, 1.4)                                       # in contact
    for obj in ('rigid', 'tissue', 'needle'):
        for mv, jv in ((0.0, 0.0), (12.0, -7.0)):
            grip, _, torque, _ = reference_forward(m, current, wrist, jaw, obj, mv, jv)
            got = m.inverse(grip, wrist, jaw, obj, mv, jv)
            assert np.shape(got) == grip.shape
            # the straightforward inverse: per sample, the bracketed scalar solve
            _, w_b, _, mv_b, jv_b = np.broadcast_arrays(grip, wrist, jaw, mv, jv)
            inertial = transmission.inertial_moment(-jv_b, mv_b, m._rn, m.params.jaw_mass, m.params.drum_mass)
            expect = [m._solve_current(float(t), float(w), float(i)) if t > 0 else float(c)
                      for t, w, i, c in zip(np.ravel(torque), np.ravel(w_b), np.ravel(inertial),
                                            np.ravel(np.broadcast_to(current, grip.shape)))]
            np.testing.assert_allclose(np.ravel(got), expect, rtol=1e-11)
            np.testing.assert_allclose(got, np.broadcast_to(current, grip.shape), rtol=1e-9)


def test_nonlinear_inverse_zero_and_unreachable_forces():
    m = MODELS['four_pulley']()
    assert float(m.inverse(0.0, 0.2, 0.1, 'needle')) == 0.0
    got = m.inverse(np.array([0.0, 1.0, 2.0]), 0.0, 0.0, 'needle')
    assert got[0] == 0.0 and 0.0 < got[1] < got[2]
    steep = GripForceModel(PAPER.replace(tension_friction_gain=0.005))
    with pytest.raises(ModelError, match='beyond the largest'):
        steep.inverse(np.array([1.0, 50.0]), 0.0, 0.0, 'needle')


def test_inverse_errors_on_arrays():
    m = GripForceModel(PAPER)
    with pytest.raises(ModelError, match='>= 0'):
        m.inverse(np.array([1.0, np.nan]), 0.0, 0.0)
    with pytest.raises(ModelError, match='>= 0'):
        m.inverse(np.array([1.0, np.inf]), 0.0, 0.0)
    with pytest.raises(ModelError, match='no contact'):
        m.inverse(np.array([0.0, 1.0]), 0.0, np.array([0.1, 1.8]), 'rigid')
    with pytest.raises(ModelError, match='no contact'):
        m.inverse(np.array([0.0, 1.0]), 0.0, 0.0, 'free')
    np.testing.assert_array_equal(m.inverse(np.zeros(3), 0.0, 0.0, 'free'), np.zeros(3))
    assert m.inverse(np.array([]), 0.0, 0.0).shape == (0,)
    weak = GripForceModel(PAPER.replace(drive_resistance_fraction=0.9, wrist_wrap_gain=0.3))
    with pytest.raises(ModelError, match='no grip force at any current'):
        weak.inverse(np.array([1.0, 2.0]), np.array([0.0, 0.5]), 0.0)


def test_scalar_inputs_keep_their_result_types():
    """Scalar inputs give numpy scalars (grip, torque, drum tension, needle pull-out) as before."""
    for m in (GripForceModel(PAPER), MODELS['four_pulley']()):
        r = m.forward(0.3, 0.1, 0.2, 'needle')
        for value in (r.grip_force, r.pull_out_force, r.jaw_torque, r.drum_tension):
            assert isinstance(value, np.float64)
        assert isinstance(r.efficiency, np.ndarray) and r.efficiency.shape == ()
        assert float(m.inverse(r.grip_force, 0.1, 0.2, 'needle')) == pytest.approx(0.3, rel=1e-12)


@pytest.mark.parametrize('name', ['paper', 'four_pulley'])
def test_velocity_and_shape_shortcuts_change_nothing(name):
    """Float velocities skip the array check; other kinds of zero (and nonzero) give the same results."""
    m = MODELS[name]()
    current, wrist, jaw = inputs(3, (30,), (30,), ())
    base = m.forward(current, wrist, jaw, 'rigid')
    for zero in (0, np.float64(0.0), np.zeros(()), np.zeros(30), [0.0] * 30):
        other = m.forward(current, wrist, jaw, 'rigid', zero, zero)
        np.testing.assert_array_equal(other.jaw_torque, base.jaw_torque)
    moving = m.forward(current, wrist, jaw, 'rigid', 12.0, -7.0).jaw_torque
    for mv, jv in ((np.float64(12.0), np.float64(-7.0)), (np.full(30, 12.0), np.full(30, -7.0)), (12, -7)):
        np.testing.assert_array_equal(m.forward(current, wrist, jaw, 'rigid', mv, jv).jaw_torque, moving)
    assert np.all(np.isnan(m.forward(current, wrist, jaw, 'rigid', float('nan'), 0.0).jaw_torque))
    force = base.grip_force
    back = m.inverse(force, wrist, jaw, 'rigid')
    np.testing.assert_array_equal(m.inverse(force, wrist, jaw, 'rigid', np.zeros(30), 0), back)
    # shapes: (30,) with (1, 30) and (30, 1) broadcast as numpy does
    grid = m.forward(current[None, :], wrist[:, None], jaw, 'rigid').grip_force
    assert grid.shape == (30, 30)
    np.testing.assert_allclose(np.diagonal(grid), base.grip_force, rtol=1e-15)
