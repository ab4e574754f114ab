"""Simulated instrument: statics against the model, dynamics sanity, noise, determinism, API."""
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from grip_force_ros.model import GripForceModel
from grip_force_ros.params import make_params
from grip_force_ros.sim import (EFFECT_NAMES, InstrumentSim, SimError, simulate, step_response_metrics)
from grip_force_ros.sim.step_response import metrics_of_signal

NOISE = ('current_noise_std', 'motor_angle_noise_std', 'motor_velocity_noise_std',
         'wrist_angle_noise_std', 'jaw_angle_noise_std', 'jaw_velocity_noise_std',
         'grip_force_noise_std')
QUIET = {name: 0.0 for name in NOISE}


def quiet_params(**changes):
    return make_params({**QUIET, **changes})


def ramp_and_hold(sim, current, ramp=1.0, hold=0.3, dt=1e-3):
    """Raised-cosine ramp 0 -> current (A) (no overshoot), then hold."""
    n_ramp = int(round(ramp / dt))
    for k in range(n_ramp):
        sim.step(current * 0.5 * (1.0 - math.cos(math.pi * (k + 1) / n_ramp)), dt)
    for _ in range(int(round(hold / dt))):
        sim.step(current, dt)
    return sim.truth()


@pytest.mark.parametrize('obj', ['needle', 'rigid', 'tissue'])
@pytest.mark.parametrize('current', [0.05, 0.2, 0.45])
def test_static_grip_force_equals_model_forward(obj, current):
    p = quiet_params()
    truth = ramp_and_hold(InstrumentSim(p, obj), current)
    expected = GripForceModel(p).forward(current, 0.0, truth['jaw_angle'], obj).grip_force
    assert truth['grip_force'] == pytest.approx(float(expected), rel=2e-3)
    assert abs(truth['jaw_velocity']) < 1e-6 and abs(truth['motor_velocity']) < 1e-6


def test_static_agreement_holds_at_a_wrist_angle_with_wrap_gain():
    p = quiet_params(wrist_wrap_gain=0.5)
    sim = InstrumentSim(p, 'needle')
    sim.set_wrist_angle(0.8)
    truth = ramp_and_hold(sim, 0.3)
    model = GripForceModel(p)
    expected = float(model.forward(0.3, 0.8, truth['jaw_angle'], 'needle').grip_force)
    assert truth['grip_force'] == pytest.approx(expected, rel=2e-3)
    # the wrist wrap lowers the efficiency, so the force is below the straight-wrist one
    assert expected < float(model.forward(0.3, 0.0, truth['jaw_angle'], 'needle').grip_force)


def test_friction_and_stiffness_scales_make_the_plant_differ_from_the_yaml():
    p = quiet_params(friction_scale=1.2, stiffness_scale=0.8)
    truth = ramp_and_hold(InstrumentSim(p, 'needle'), 0.3)
    yaml_model = GripForceModel(p)
    plant_model = GripForceModel(p.replace(pulley_friction_coefficient=0.15 * 1.2))
    assert truth['grip_force'] == pytest.approx(
        float(plant_model.forward(0.3, 0.0, truth['jaw_angle']).grip_force), rel=2e-3)
    assert truth['grip_force'] < 0.9 * float(yaml_model.forward(0.3, 0.0, truth['jaw_angle']).grip_force)
    # softer cable: more stretch, so the drum turns further for the same jaw angle
    stiff = ramp_and_hold(InstrumentSim(quiet_params(friction_scale=1.2), 'needle'), 0.3)
    assert truth['motor_angle'] > stiff['motor_angle'] + 0.01


def test_cable_stretch_is_the_angle_gap_between_drum_and_jaw():
    p = quiet_params()
    sim = InstrumentSim(p, 'needle')
    truth = ramp_and_hold(sim, 0.3)
    k = p.cable_modulus * math.pi * p.cable_radius ** 2 / p.cable_length
    share = p.cable_jaw_side_fraction
    stretch = truth['drum_tension'] * (1 - share) / k + truth['jaw_tension'] * share / k
    kinematic = -p.drum_radius / p.drive_pulley_radius * truth['motor_angle']
    assert truth['jaw_angle'] == pytest.approx(kinematic + stretch / p.drive_pulley_radius, abs=1e-9)


def test_unloading_follows_the_back_driven_capstan_ratio():
    """Friction opposes slip: loading passes lambda*T0, unloading needs T0 = lambda*Tn."""
    p = quiet_params()
    sim = InstrumentSim(p, 'needle')
    loaded = ramp_and_hold(sim, 0.4)
    lam = loaded['efficiency']
    assert loaded['jaw_tension'] / loaded['drum_tension'] == pytest.approx(lam, rel=1e-3)
    for k in range(1000):                               # slow ramp down to 0.15 A
        sim.step(0.4 - 0.25 * 0.5 * (1 - math.cos(math.pi * (k + 1) / 1000)), 1e-3)
    for _ in range(300):
        sim.step(0.15, 1e-3)
    unloaded = sim.truth()
    assert unloaded['jaw_tension'] / unloaded['drum_tension'] == pytest.approx(1 / lam, rel=1e-3)
    # so the grip force on the way down is above the model's (loading) prediction
    model = float(GripForceModel(p).forward(0.15, 0.0, unloaded['jaw_angle']).grip_force)
    assert unloaded['grip_force'] == pytest.approx(model / lam ** 2, rel=3e-3)


@settings(max_examples=15, deadline=None)
@given(st.lists(st.floats(-0.5, 0.5), min_size=5, max_size=30), st.sampled_from(['needle', 'tissue', 'free']))
def test_pulley_tension_ratio_stays_in_the_capstan_band(levels, obj):
    p = quiet_params()
    sim = InstrumentSim(p, obj)
    lam = sim.truth()['efficiency']
    for level in levels:
        for _ in range(20):
            sim.step(level, 1e-3)
            tr = sim.truth()
            t0, tn = tr['drum_tension'], tr['jaw_tension']
            assert math.isfinite(tr['jaw_angle']) and abs(tr['jaw_angle']) < 2.0
            assert abs(t0 - tn) <= (1 - lam) * max(abs(t0), abs(tn)) * (1 + 1e-9) + 1e-9
            assert t0 * tn >= -1e-9                     # one cable: same sign on both sides


def test_free_jaw_settles_and_loses_energy_without_current():
    p = quiet_params()
    sim = InstrumentSim(p, 'free')
    for _ in range(50):
        sim.step(-0.2, 1e-3)                            # kick it open
    energies = []
    for _ in range(400):
        sim.step(0.0, 1e-3)
        energies.append(sim.energy())
    energies = np.array(energies)
    assert np.all(np.diff(energies) <= 1e-12 + 1e-9 * energies[:-1])
    truth = sim.truth()
    assert abs(truth['jaw_velocity']) < 1e-3 and abs(truth['motor_velocity']) < 1e-3
    assert 0.0 <= truth['jaw_angle'] <= math.pi / 2 + 0.01


def test_jaw_opens_with_negative_current_and_stops_at_the_hard_stops():
    p = quiet_params()
    sim = InstrumentSim(p, 'free')
    for _ in range(500):
        sim.step(-0.1, 1e-3)
    assert sim.truth()['jaw_angle'] == pytest.approx(math.pi / 2, abs=0.02)
    for _ in range(500):
        sim.step(0.1, 1e-3)
    assert sim.truth()['jaw_angle'] == pytest.approx(0.0, abs=0.02)
    assert sim.measure().grip_force == 0.0               # nothing between the jaws


def test_the_open_stop_is_the_instruments_and_inside_its_plausible_range():
    """Maryland forceps: the dVRK's jaw range ends at 80 deg (1.396 rad); the sim stopped at
    pi/2 for every instrument, where the controller would reject the jaw angle. The
    opening current of the stop test (-0.3 A, the forceps' max_current, for 1 s) now ends
    0.1 rad inside the plausible range (jaw_open_stop 0: from jaw_angle_max)."""
    from grip_force_ros.params import ParameterError, load_params_file
    from grip_force_ros.params.files import instrument_path
    p = load_params_file(instrument_path('maryland_forceps'))
    sim = InstrumentSim(p.replace(**QUIET), 'free')
    for _ in range(1000):
        sim.step(-p.max_current, 1e-3)
    assert sim.truth()['jaw_angle'] == pytest.approx(1.39626 - 0.1, abs=0.02)
    assert sim.truth()['jaw_angle'] < p.jaw_angle_max
    with pytest.raises(ParameterError, match='jaw_open_stop'):       # the old stop: refused
        p.replace(jaw_open_stop=math.pi / 2)
    sim = InstrumentSim(p.replace(jaw_open_stop=1.0, **QUIET), 'free')    # one given
    for _ in range(1000):
        sim.step(-p.max_current, 1e-3)
    assert sim.truth()['jaw_angle'] == pytest.approx(1.0, abs=0.02)
    with pytest.raises(ParameterError, match='initial_jaw_angle'):
        make_params({'jaw_open_stop': 0.5, 'initial_jaw_angle': 0.6})


def test_wrist_coupling_moves_the_jaw_for_a_held_drum():
    p = quiet_params()
    sim = InstrumentSim(p, 'free')
    ramp_and_hold(sim, 0.0, ramp=0.01, hold=0.01)
    sim.set_wrist_angle(0.5)
    for _ in range(300):
        sim.step(0.0, 1e-3)
    tr = sim.truth()
    kinematic = -p.drum_radius / p.drive_pulley_radius * tr['motor_angle'] + 0.6 * 0.5
    assert tr['jaw_angle'] == pytest.approx(kinematic, abs=1e-6)


def test_same_seed_same_log_other_seed_other_noise():
    p = make_params()
    currents = np.linspace(0.0, 0.3, 300)
    a = simulate(p, currents, 1e-3, seed=3)
    b = simulate(p, currents, 1e-3, seed=3)
    c = simulate(p, currents, 1e-3, seed=4)
    for name in ('current', 'motor_angle', 'jaw_angle', 'grip_force'):
        np.testing.assert_array_equal(a[name], b[name])
        assert not np.array_equal(a[name], c[name])


def test_noise_statistics_match_the_parameters():
    p = make_params({'current_noise_std': 0.004, 'grip_force_noise_std': 0.05,
                     'jaw_angle_noise_std': 0.002, 'motor_angle_noise_std': 5e-4})
    sim = InstrumentSim(p, 'needle', seed=11)
    ramp_and_hold(sim, 0.3, ramp=0.3, hold=0.3)
    truth = sim.truth()
    rows = []
    for _ in range(4000):
        sim.step(0.3, 1e-4)             # tiny steps: the state stays put, the noise is fresh
        m = sim.measure()
        rows.append((m.current, m.grip_force, m.jaw_angle, m.motor_angle))
    rows = np.array(rows)
    centre = np.array([truth['current'], truth['grip_force'], truth['jaw_angle'], truth['motor_angle']])
    std = np.array([0.004, 0.05, 0.002, 5e-4])
    np.testing.assert_allclose(rows.std(axis=0), std, rtol=0.06)
    assert np.all(np.abs(rows.mean(axis=0) - centre) < 4 * std / math.sqrt(len(rows)) + 1e-6 * abs(centre))
    # white: neighbouring samples uncorrelated
    resid = rows[:, 1] - rows[:, 1].mean()
    assert abs(np.corrcoef(resid[1:], resid[:-1])[0, 1]) < 0.06


def test_measure_is_stable_between_steps_and_has_every_field():
    sim = InstrumentSim(make_params(), 'needle', seed=1)
    sim.step(0.1, 1e-3)
    assert sim.measure() is sim.measure()
    assert set(sim.measure().__slots__) == {'t', 'motor_angle', 'motor_velocity', 'current', 'wrist_angle',
                                            'jaw_angle', 'jaw_velocity', 'grip_force'}
    assert sim.measure().t == pytest.approx(1e-3)


def test_reset_restores_the_initial_state_and_noise():
    sim = InstrumentSim(make_params(), 'needle', seed=2)
    first = [sim.step(0.2, 1e-3) or sim.measure() for _ in range(50)]
    sim.reset()
    second = [sim.step(0.2, 1e-3) or sim.measure() for _ in range(50)]
    assert first == second


def test_current_loop_lags_the_command():
    p = quiet_params(current_loop_time_constant=2e-3)
    sim = InstrumentSim(p, 'free')
    sim.step(0.4, 2e-3)
    assert sim.measure().current == pytest.approx(0.4 * (1 - math.exp(-1)), rel=2e-3)


@pytest.mark.parametrize('bad', [
    lambda: InstrumentSim(make_params(), 'sponge'),
    lambda: InstrumentSim(make_params(), 'needle', effects={'gremlins': 1.0}),
    lambda: InstrumentSim(make_params(), 'needle', effects={'backlash': -1.0}),
    lambda: InstrumentSim(make_params()).step(float('nan'), 1e-3),
    lambda: InstrumentSim(make_params()).step(0.1, 0.0),
    lambda: InstrumentSim(make_params()).set_wrist_angle(float('inf')),
    lambda: simulate(make_params(), [[0.1]], 1e-3),
])
def test_bad_input_raises_a_value_error(bad):
    with pytest.raises(SimError) as err:
        bad()
    assert isinstance(err.value, ValueError) and str(err.value)


def test_simulate_returns_the_log_contract():
    p = make_params()
    n = 200
    log = simulate(p, np.full(n, 0.2), 1e-3, obj='tissue', wrist_profile=np.linspace(0, 0.3, n))
    assert list(log) == ['t', 'current', 'motor_angle', 'wrist_angle', 'jaw_angle', 'grip_force', 'object']
    assert all(len(v) == n for v in log.values())
    assert np.all(np.diff(log['t']) > 0) and log['t'][-1] == pytest.approx(0.2)
    assert set(log['object']) == {'tissue'}
    assert log['wrist_angle'][-1] == pytest.approx(0.3, abs=0.01)


def test_effect_names_are_the_design_vocabulary():
    assert EFFECT_NAMES == ('pivot_coulomb_friction', 'viscous_friction', 'cable_hysteresis', 'backlash',
                            'tension_dependent_friction', 'viscoelastic_creep', 'sensor_delay',
                            'torque_constant_drift', 'force_sensor_offset', 'position_spring')


def test_metrics_of_a_first_order_step():
    tau = 0.01
    t = np.arange(0, 0.3, 1e-5)
    y = np.where(t < 0.05, 0.0, 2.0 * (1 - np.exp(-(t - 0.05) / tau)))
    m = metrics_of_signal(t, y, t_step=0.05)
    assert m.final_value == pytest.approx(2.0, rel=1e-6)
    assert m.rise_time == pytest.approx(tau * math.log(9), rel=1e-2)
    assert m.settling_time == pytest.approx(tau * math.log(50), rel=1e-2)
    assert m.overshoot < 1e-9


def test_needle_step_response_damps_within_the_papers_0_1_s():
    m = step_response_metrics(make_params(), current=0.35, obj='needle', duration=0.2)
    assert m.settling_time < 0.1
    assert m.final_value > 0.0


@pytest.mark.parametrize('obj', ['needle', 'tissue'])
def test_slow_loading_and_unloading_follow_the_quasi_static_play_reference(obj):
    from grip_force_ros.sim.quasistatic import quasi_static_grip_force
    p = quiet_params()
    t = np.arange(8000) * 1e-3
    profile = np.interp(t, [0, 2, 4, 5.5, 8], [0.0, 0.4, 0.1, 0.35, 0.05])
    log = simulate(p, profile, 1e-3, obj=obj, extra=True)
    reference = quasi_static_grip_force(p, log['current'], 0.0, log['jaw_angle'], obj)
    touching = log['true_grip_force'] > 0.2
    assert touching.mean() > 0.8
    touching &= t > t[np.argmax(touching)] + 0.1          # after the impact of the first touch
    np.testing.assert_allclose(log['true_grip_force'][touching], reference[touching], rtol=0.01, atol=0.01)
    # while the model's single-valued map misses the unloading branches by far
    model = GripForceModel(p).forward(log['current'], 0.0, log['jaw_angle'], obj).grip_force
    assert np.max(np.abs(model[touching] - log['true_grip_force'][touching])) > 1.0


def test_capstan_play_stays_in_the_band_and_is_the_loading_branch_when_rising():
    from grip_force_ros.sim.quasistatic import capstan_play
    rng = np.random.default_rng(0)
    drum = np.cumsum(rng.normal(size=500)) * 5
    out = capstan_play(drum, 0.6)
    lo = np.minimum(0.6 * drum, drum / 0.6)
    hi = np.maximum(0.6 * drum, drum / 0.6)
    assert np.all((out >= lo - 1e-12) & (out <= hi + 1e-12))
    rising = np.linspace(0, 100, 50)
    np.testing.assert_allclose(capstan_play(rising, 0.6), 0.6 * rising)
