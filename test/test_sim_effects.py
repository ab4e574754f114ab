"""Effects of the simulated instrument: each off by default, invisible at 0, and each
changes what it should (its signature) and nothing it should not."""
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from grip_force_ros.model import GripForceModel
from grip_force_ros.params import SPECS, make_params
from grip_force_ros.sim import EFFECT_NAMES, InstrumentSim, simulate

QUIET = {name: 0.0 for name in ('current_noise_std', 'motor_angle_noise_std', 'motor_velocity_noise_std',
                                'wrist_angle_noise_std', 'jaw_angle_noise_std', 'jaw_velocity_noise_std',
                                'grip_force_noise_std')}
DT = 1e-3
T = np.arange(2500) * DT
#: up, hold, down, hold: a loading and an unloading (back-driven) branch
PROFILE = np.interp(T, [0.0, 0.8, 1.2, 2.0, 2.5], [0.0, 0.4, 0.4, 0.05, 0.05])
SIGNALS = ('current', 'motor_angle', 'wrist_angle', 'jaw_angle', 'grip_force')


def quiet(**changes):
    return make_params({**QUIET, **changes})


@pytest.fixture(scope='module')
def base():
    return {obj: simulate(quiet(), PROFILE, DT, obj=obj, extra=True) for obj in ('needle', 'tissue')}


def hold_force(sim, current, seconds, dt=DT):
    for _ in range(int(round(seconds / dt))):
        sim.step(current, dt)
    return sim.truth()


def loading_ramp(sim, current, seconds=1.0):
    n = int(round(seconds / DT))
    for k in range(n):
        sim.step(current * 0.5 * (1 - math.cos(math.pi * (k + 1) / n)), DT)
    return sim.truth()


def test_every_effect_is_a_parameter_that_defaults_to_off():
    for name in EFFECT_NAMES:
        assert SPECS[name].group == 'effects' and SPECS[name].default == 0.0
        assert SPECS[name].unit is not None and SPECS[name].description


@pytest.mark.parametrize('name', EFFECT_NAMES)
def test_an_effect_at_zero_is_invisible(name, base):
    log = simulate(quiet(), PROFILE, DT, obj='needle', effects={name: 0.0}, extra=True)
    for column in SIGNALS:
        np.testing.assert_array_equal(log[column], base['needle'][column])


def test_force_sensor_offset_shifts_only_the_load_cell(base):
    log = simulate(quiet(), PROFILE, DT, effects={'force_sensor_offset': 0.3})
    np.testing.assert_allclose(log['grip_force'] - base['needle']['grip_force'], 0.3, atol=1e-12)
    for column in ('current', 'motor_angle', 'jaw_angle'):
        np.testing.assert_array_equal(log[column], base['needle'][column])


def test_sensor_delay_delays_only_the_load_cell(base):
    delay = 0.025
    log = simulate(quiet(), PROFILE, DT, effects={'sensor_delay': delay})
    ref = base['needle']
    expected = np.interp(ref['t'] - delay, ref['t'], ref['grip_force'], left=0.0)
    np.testing.assert_allclose(log['grip_force'], expected, atol=1e-9)
    assert np.max(np.abs(log['grip_force'] - ref['grip_force'])) > 0.1
    for column in ('current', 'motor_angle', 'jaw_angle'):
        np.testing.assert_array_equal(log[column], ref[column])


def test_pivot_coulomb_friction_lowers_loading_and_raises_unloading_force_by_torque_over_arm(base):
    torque = 0.004   # N*m at the jaw pivot -> 0.004/0.012 = 0.33 N on the needle
    log = simulate(quiet(), PROFILE, DT, effects={'pivot_coulomb_friction': torque})
    ref = base['needle']
    loading = (T > 0.6) & (T < 0.8)
    unloading = (T > 2.2) & (T < 2.5)          # held low after the pulley chain slipped back
    gap = log['grip_force'] - ref['grip_force']
    assert np.median(gap[loading]) == pytest.approx(-torque / 0.012, rel=0.05)
    assert np.median(gap[unloading]) == pytest.approx(torque / 0.012, rel=0.05)
    np.testing.assert_array_equal(log['current'], ref['current'])


def test_viscous_friction_acts_with_velocity_only(base):
    c = 5e-3     # N*m*s/rad
    log = simulate(quiet(), PROFILE, DT, obj='tissue', effects={'viscous_friction': c}, extra=True)
    ref = base['tissue']
    still = (T > 1.1) & (T < 1.2)      # held: no velocity, no change
    np.testing.assert_allclose(log['grip_force'][still], ref['grip_force'][still], rtol=2e-3)
    # in free closing, before contact, the jaw lags
    closing = T < 0.3
    assert np.max(np.abs(log['jaw_velocity'][closing])) < np.max(np.abs(ref['jaw_velocity'][closing]))
    # while squeezing tissue the damping moment c*w takes load off the contact
    squeeze = (T > 0.3) & (T < 0.8) & (ref['true_grip_force'] > 0.5)
    expected = c * np.abs(log['jaw_velocity'][squeeze]) * 2 * math.cos(0.2) / (0.012 + 0.0095)
    gap = ref['true_grip_force'][squeeze] - log['true_grip_force'][squeeze]
    assert np.median(gap) > 0.5 * np.median(expected) > 0


def test_cable_hysteresis_takes_a_fraction_of_the_moment_on_loading_and_gives_it_back_on_unloading():
    p = quiet()
    h = 0.1
    sim = InstrumentSim(p, 'needle', effects={'cable_hysteresis': h})
    ref = InstrumentSim(p, 'needle')
    loaded = loading_ramp(sim, 0.4)
    loaded_ref = loading_ramp(ref, 0.4)
    assert loaded['grip_force'] == pytest.approx((1 - h) * loaded_ref['grip_force'], rel=0.02)
    # proportional to the load: the same fraction at a lower current
    low = loading_ramp(InstrumentSim(p, 'needle', effects={'cable_hysteresis': h}), 0.15)
    low_ref = loading_ramp(InstrumentSim(p, 'needle'), 0.15)
    assert low['grip_force'] == pytest.approx((1 - h) * low_ref['grip_force'], rel=0.02)
    # and the cable stretch / drum angle are those of the same tension: no angle signature
    assert loaded['motor_angle'] == pytest.approx(loaded_ref['motor_angle'], abs=2e-3)
    # on the way down (pulley chain slipping back) the loop gives the fraction back
    for k in range(1000):
        level = 0.4 - 0.35 * 0.5 * (1 - math.cos(math.pi * (k + 1) / 1000))
        sim.step(level, DT)
        ref.step(level, DT)
    down, down_ref = hold_force(sim, 0.05, 0.2), hold_force(ref, 0.05, 0.2)
    assert down['grip_force'] == pytest.approx((1 + h) * down_ref['grip_force'], rel=0.03)


def test_backlash_is_lost_motion_not_lost_force():
    p = quiet()
    play = 0.06  # rad at the jaw
    sim = InstrumentSim(p, 'needle', effects={'backlash': play})
    ref = InstrumentSim(p, 'needle')
    loaded = loading_ramp(sim, 0.3)
    loaded_ref = loading_ramp(ref, 0.3)
    assert loaded['grip_force'] == pytest.approx(loaded_ref['grip_force'], rel=2e-3)
    # the drum must turn half the play further (cable r_n*play/2 on a drum of r0) to take up the slack
    shift = 0.5 * play * p.drive_pulley_radius / p.drum_radius
    assert loaded['motor_angle'] - loaded_ref['motor_angle'] == pytest.approx(shift, rel=0.02)


def test_tension_dependent_friction_is_the_models_tension_gain_unknown_to_the_yaml():
    gain = 4e-4  # 1/N
    p = quiet()
    truth = loading_ramp(InstrumentSim(p, 'needle', effects={'tension_dependent_friction': gain}), 0.35)
    knows = GripForceModel(p.replace(tension_friction_gain=gain))
    blind = GripForceModel(p)
    assert truth['grip_force'] == pytest.approx(
        float(knows.forward(0.35, 0.0, truth['jaw_angle']).grip_force), rel=5e-3)
    assert truth['grip_force'] < 0.95 * float(blind.forward(0.35, 0.0, truth['jaw_angle']).grip_force)


def test_viscoelastic_creep_relaxes_held_force_with_its_time_constant_and_recovers():
    c, tau = 0.3, 0.2
    p = quiet()
    sim = InstrumentSim(p, 'needle',
                        effects={'viscoelastic_creep': c, 'viscoelastic_creep_time_constant': tau})
    ref = InstrumentSim(p, 'needle')
    loading_ramp(sim, 0.3, seconds=0.05)
    loading_ramp(ref, 0.3, seconds=0.05)
    f_ref = hold_force(ref, 0.3, 1.5)['grip_force']
    start = sim.truth()['grip_force']
    after_tau = hold_force(sim, 0.3, tau)['grip_force']
    late = hold_force(sim, 0.3, 1.5 - tau)['grip_force']
    assert start == pytest.approx(f_ref, rel=0.05)                 # fast loading: barely relaxed yet
    assert late == pytest.approx((1 - c) * f_ref, rel=0.02)       # fully relaxed
    relaxed_share = (start - after_tau) / (start - late)
    assert relaxed_share == pytest.approx(1 - math.exp(-1), abs=0.08)
    # unloaded for many time constants it recovers: a fresh grasp is as strong as the reference
    hold_force(sim, -0.05, 8 * tau)
    hold_force(ref, -0.05, 8 * tau)
    again = loading_ramp(sim, 0.3, seconds=0.05)['grip_force']
    again_ref = loading_ramp(ref, 0.3, seconds=0.05)['grip_force']
    assert again == pytest.approx(again_ref, rel=0.05)


def test_torque_constant_drift_follows_the_heat_of_the_current():
    s, tau = 0.2, 2.0
    p = quiet()
    sim = InstrumentSim(p, 'needle', effects={'torque_constant_drift': s,
                                              'torque_constant_drift_time_constant': tau})
    loading_ramp(sim, p.max_current, seconds=0.05)
    cold = sim.truth()['grip_force']
    hot = hold_force(sim, p.max_current, 8 * tau)
    assert hot['torque_constant'] == pytest.approx(p.torque_constant * (1 - s), rel=2e-3)
    # the stuck pulley chain holds the jaw tension while the drum tension sinks; the lower
    # K shows on the next loading: release and grasp again
    hold_force(sim, 0.0, 0.05)
    regrasp = loading_ramp(sim, p.max_current, seconds=0.1)
    scale = regrasp['torque_constant'] / p.torque_constant
    expected = float(GripForceModel(p).forward(p.max_current * scale, 0.0, regrasp['jaw_angle']).grip_force)
    assert regrasp['grip_force'] == pytest.approx(expected, rel=0.01)
    assert regrasp['grip_force'] < 0.85 * cold
    assert sim.measure().current == pytest.approx(p.max_current, rel=1e-3)   # measured current unchanged


def test_position_spring_takes_its_torque_at_the_jaw_off_the_grip_force():
    """An opening jaw spring S (1 - phi/phi_r): in contact the object holds the drive moment
    less the spring's, so the load cell reads S (1 - phi/phi_r) G less; the cable tension and
    the drum angle (which load the drive) barely change."""
    from grip_force_ros.model import contact
    p = quiet()
    strength, rest = 0.008, 0.8                       # N*m at the closed jaw, rad
    for obj in ('needle', 'rigid'):
        sim = InstrumentSim(p, obj, effects={'position_spring': strength, 'position_spring_rest_angle': rest})
        ref = InstrumentSim(p, obj)
        loading_ramp(sim, 0.3)
        loading_ramp(ref, 0.3)
        loaded, loaded_ref = hold_force(sim, 0.3, 0.3), hold_force(ref, 0.3, 0.3)
        phi = loaded['jaw_angle']
        gain = contact.contact_gain_scalar(obj, phi, p.jaw_moment_arm_tip, p.jaw_moment_arm_inner)
        spring_force = strength * (1.0 - phi / rest) * gain     # N, 0.6 N here
        assert spring_force > 0.5
        assert loaded_ref['grip_force'] - loaded['grip_force'] == pytest.approx(spring_force, rel=0.01)
        assert loaded['jaw_tension'] == pytest.approx(loaded_ref['jaw_tension'], rel=0.01)
        # the load cell is not offset by it: the measured force is the contact's
        assert sim.measure().grip_force == pytest.approx(loaded['grip_force'], rel=1e-9)


def test_position_spring_moves_the_free_jaw_to_its_rest_angle_through_the_cable():
    p = quiet()
    strength, rest = 0.008, 0.8
    sim = InstrumentSim(p, 'free', effects={'position_spring': strength, 'position_spring_rest_angle': rest})
    ref = InstrumentSim(p, 'free')
    energy = [sim.energy()]
    for _ in range(6):
        hold_force(sim, 0.0, 0.5)
        hold_force(ref, 0.0, 0.5)
        energy.append(sim.energy())
    # no current: the spring opens the jaw (from initial_jaw_angle 0.6) to where it is 0,
    # pulling the slack cable and turning the drum the other way (closing-positive angle)
    assert p.initial_jaw_angle < rest
    assert sim.truth()['jaw_angle'] == pytest.approx(rest, abs=1e-3)
    assert ref.truth()['jaw_angle'] == pytest.approx(p.initial_jaw_angle, abs=1e-3)
    shift = (rest - p.initial_jaw_angle) * p.drive_pulley_radius / p.drum_radius
    assert ref.truth()['motor_angle'] - sim.truth()['motor_angle'] == pytest.approx(shift, rel=0.01)
    # the spring's potential is part of the energy, and the damped plant only loses it
    assert energy[0] == pytest.approx(0.5 * strength / rest * (rest - p.initial_jaw_angle) ** 2, rel=1e-9)
    assert np.all(np.diff(energy) <= 1e-12) and energy[-1] < 1e-6 * energy[0]
    # under an opening current the jaw goes to its open stop as without the spring
    hold_force(sim, -0.05, 1.0)
    assert sim.truth()['jaw_angle'] == pytest.approx(math.pi / 2, abs=1e-3)


EFFECT_RANGES = {'pivot_coulomb_friction': (0.0, 0.02), 'viscous_friction': (0.0, 0.04),
                 'cable_hysteresis': (0.0, 0.3), 'backlash': (0.0, 0.15),
                 'tension_dependent_friction': (0.0, 0.004), 'viscoelastic_creep': (0.0, 0.5),
                 'sensor_delay': (0.0, 0.05), 'torque_constant_drift': (0.0, 0.5),
                 'force_sensor_offset': (-1.0, 1.0), 'position_spring': (0.0, 0.02)}


@settings(max_examples=20, deadline=None)
@given(st.dictionaries(st.sampled_from(EFFECT_NAMES), st.floats(0.0, 1.0), max_size=4),
       st.lists(st.tuples(st.floats(-0.5, 0.5), st.floats(-1.0, 1.0),
                          st.sampled_from(['free', 'needle', 'tissue', 'rigid'])), min_size=3, max_size=12),
       st.integers(0, 2**16))
def test_any_effect_mix_stays_bounded_and_deterministic(mix, segments, seed):
    effects = {name: EFFECT_RANGES[name][0] + u * (EFFECT_RANGES[name][1] - EFFECT_RANGES[name][0])
               for name, u in mix.items()}
    runs = []
    for _ in range(2):
        sim = InstrumentSim(make_params(), 'needle', effects=effects, seed=seed)
        rows = []
        for current, wrist, obj in segments:
            sim.set_object(obj)
            sim.set_wrist_angle(wrist)
            for _ in range(40):
                sim.step(current, DT)
                m = sim.measure()
                rows.append((m.jaw_angle, m.motor_angle, m.grip_force, m.current))
                tr = sim.truth()
                assert -0.1 < tr['jaw_angle'] < math.pi / 2 + 0.1
                # instant wrist jumps of ~1 rad yank the cable (hundreds of N): bounded, not gentle
                assert abs(tr['drum_tension']) < 3000.0 and abs(tr['jaw_velocity']) < 1e4
                assert 0.0 <= tr['grip_force'] < 1000.0
        runs.append(np.array(rows))
    assert np.all(np.isfinite(runs[0]))
    np.testing.assert_array_equal(runs[0], runs[1])


def test_set_params_switches_an_effect_on_without_losing_the_state():
    p = quiet()
    sim = InstrumentSim(p, 'needle')
    loaded = loading_ramp(sim, 0.3)
    sim.set_params(p.replace(force_sensor_offset=0.5))
    sim.step(0.3, DT)
    assert sim.truth()['grip_force'] == pytest.approx(loaded['grip_force'], rel=1e-4)
    assert sim.measure().grip_force == pytest.approx(sim.truth()['grip_force'] + 0.5, rel=1e-9)
