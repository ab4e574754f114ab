"""Controller core: force map, PID, limits, input validation, watchdog, bumpless switching."""
import math

import numpy as np
import pytest

from grip_force_ros.lab.closed_loop import NO_FORCE_SENSOR, closed_loop_step
from grip_force_ros.control import PID, ControlInputs, CurrentLimiter, ForceMap, GripController, Mode
from grip_force_ros.model import GripForceModel
from grip_force_ros.params import make_params

PERIOD = 1e-3


@pytest.fixture
def params():
    return make_params({})


def feed(inputs, t, master, jaw, current, wrist=0.0, jaw_velocity=0.0):
    inputs.set_master(t, master)
    inputs.set_instrument(t, wrist, jaw, jaw_velocity)
    inputs.set_actuator(t, current)


def run_grip(ctrl, inputs, n=300, master=0.05, jaw=0.04, t0=0.0):
    """Hold the master closed on a needle; the measured current follows the command."""
    out = None
    for k in range(n):
        t = t0 + k * PERIOD
        feed(inputs, t, master, jaw, ctrl.command)
        out = ctrl.step(t, inputs)
    return out, t0 + n * PERIOD


# --------------------------------------------------------------------------- force map
def test_force_map_free_then_grip_rising_and_capped():
    fm = ForceMap(master_angle_min=0.0, master_contact_angle=0.2, master_to_jaw_gain=1.5,
                  jaw_angle_max=1.5, force_max=4.0)
    gripping, jaw_target = fm.update(0.6, 0.9)
    assert not gripping and jaw_target == pytest.approx(0.9)
    forces = []
    for m in np.linspace(0.19, 0.0, 20):
        gripping, f = fm.update(m, 0.04)
        assert gripping
        forces.append(f)
    assert np.all(np.diff(forces) > 0)                         # rises with further closing
    assert forces[-1] == pytest.approx(4.0)                    # reaches the maximum at closed
    assert max(forces) <= 4.0


def test_force_map_detects_blocked_jaw_and_releases_with_hysteresis():
    fm = ForceMap(master_angle_min=0.0, master_contact_angle=0.2, master_to_jaw_gain=1.0,
                  jaw_angle_max=1.5, force_max=4.0, contact_jaw_margin=0.05,
                  contact_jaw_speed=0.5, release_hysteresis=0.02)
    # jaw held at 0.5 rad by tissue while the master asks for 0.4: contact at master 0.4
    assert fm.update(0.4, 0.5, 0.0) == (True, 0.0)
    assert fm.contact_angle == pytest.approx(0.4)
    gripping, f = fm.update(0.2, 0.5)
    assert gripping and f == pytest.approx(4.0 * 0.2 / 0.4)
    assert fm.update(0.41, 0.5)[0]                              # inside the hysteresis
    assert not fm.update(0.43, 0.5)[0]                          # released
    # a jaw lagging while moving fast is not a contact
    assert not fm.update(0.4, 0.5, jaw_velocity=-3.0)[0]


def test_force_map_exponent_and_cap_from_params(params):
    p = params.replace(grip_force_max=50.0, max_grip_force=6.0, force_map_exponent=2.0)
    fm = ForceMap.from_params(p)
    assert fm.force_max == 6.0                                  # never above the hardware limit
    fm.update(0.1, 0.04)
    half = fm.force_target(0.1)                                 # half way from 0.2 to 0
    assert half == pytest.approx(6.0 * 0.25)


# --------------------------------------------------------------------------- PID
def test_pid_integrates_and_back_calculation_limits_windup():
    pid = PID(kp=0.0, ki=10.0, kd=0.0, derivative_filter_time=1e-3, period=PERIOD,
              tracking_time=0.01, integral_limit=100.0)
    lim = CurrentLimiter(0.5, 1e6, PERIOD)
    cmd = 0.0
    for _ in range(5000):                                       # 5 s of a large error
        u = pid.update(1.0, 0.0)
        cmd, _ = lim.apply(u, cmd)
        pid.track(u, cmd)
    assert cmd == 0.5
    # back-calculation keeps the integral near the limit, not at ki*e*t = 50
    assert pid.integral < 0.7
    # the error reverses: the output leaves saturation within a few ms
    steps = 0
    while cmd >= 0.5 and steps < 1000:
        u = pid.update(-1.0, 0.0)
        cmd, _ = lim.apply(u, cmd)
        pid.track(u, cmd)
        steps += 1
    assert steps < 30


def test_pid_derivative_on_measurement_no_setpoint_kick_and_filtered():
    pid = PID(kp=0.0, ki=0.0, kd=1.0, derivative_filter_time=0.01, period=PERIOD)
    pid.update(0.0, 0.0)
    assert pid.update(5.0, 0.0) == 0.0                          # setpoint step: no kick
    out = pid.update(5.0, 0.001)                                # measurement ramps 1 rad/s
    assert out == pytest.approx(-1.0 * (PERIOD / (0.01 + PERIOD)))  # first-order filtered
    for _ in range(200):
        m = pid.last_measurement + 0.001
        out = pid.update(5.0, m)
    assert out == pytest.approx(-1.0, rel=1e-3)                 # -kd * d(measurement)/dt


def test_pid_preset_is_bumpless():
    pid = PID(kp=2.0, ki=5.0, kd=0.1, derivative_filter_time=1e-3, period=PERIOD, sign=-1.0)
    pid.preset(0.123, setpoint=0.3, measurement=0.5)
    assert pid.update(0.3, 0.5) == pytest.approx(0.123)


# --------------------------------------------------------------------------- limiter
def test_limiter_reports_which_limit():
    lim = CurrentLimiter(0.5, 100.0, PERIOD)                    # 0.1 A per step
    assert lim.apply(0.05, 0.0) == (0.05, ())
    assert lim.apply(0.3, 0.0) == (pytest.approx(0.1), ('slew_limit',))
    assert lim.apply(0.9, 0.45) == (0.5, ('current_limit',))
    assert lim.apply(0.9, 0.2) == (pytest.approx(0.3), ('current_limit', 'slew_limit'))
    assert lim.apply(math.nan, 0.05) == (0.0, ())


# --------------------------------------------------------------------------- inputs
def test_inputs_reject_bad_samples_and_keep_last_good(params):
    inp = ControlInputs.from_params(params)
    assert inp.set_instrument(0.0, 0.1, 0.3) == (True, None)
    for bad in [(math.nan, 0.3), (0.1, math.inf), (3.0, 0.3), (0.1, 2.0), (0.1, -0.5)]:
        fresh, reason = inp.set_instrument(0.001, *bad)
        assert not fresh and reason and reason.startswith('instrument:')
        assert inp.instrument_fault == reason
        assert (inp.wrist_angle, inp.jaw_angle) == (0.1, 0.3)    # last good kept
    assert inp.set_instrument(0.002, 0.1, 0.31) == (True, None)
    assert inp.instrument_fault is None
    assert inp.set_actuator(0.0, 'garbage')[1].startswith('actuator: a value is not a number')
    assert sum(inp.rejected.values()) == 6


def test_inputs_stamps_backwards_future_and_duplicates(params):
    inp = ControlInputs.from_params(params)
    assert inp.set_master(1.0, 0.5, stamp=0.999) == (True, None)
    assert inp.set_master(1.001, 0.6, stamp=0.999) == (False, None)   # duplicate: ignored
    assert inp.master_angle == 0.5 and inp.master_time == 1.0  # no watchdog refresh
    assert 'backwards' in inp.set_master(1.002, 0.6, stamp=0.5)[1]
    assert inp.set_master(1.003, 0.6, stamp=0.51) == (True, None)   # stream continues from the jump
    assert 'ahead' in inp.set_master(1.004, 0.6, stamp=5.0)[1]


def test_master_clamped_or_rejected(params):
    inp = ControlInputs.from_params(params)                     # range [0, 1.2], tolerance 0.5
    assert inp.set_master(0.0, -0.2) == (True, None) and inp.master_clamped and inp.master_angle == 0.0
    assert inp.set_master(0.0, 1.3) == (True, None) and inp.master_clamped and inp.master_angle == 1.2
    assert inp.set_master(0.0, 0.4) == (True, None) and not inp.master_clamped
    assert inp.set_master(0.0, 5.0)[0] is False
    assert 'outside' in inp.set_master(0.0, 5.0)[1]


# --------------------------------------------------------------------------- controller
def test_starts_safe_until_inputs_arrive(params):
    ctrl = GripController(params)
    inp = ctrl.new_inputs()
    out = ctrl.step(0.0, inp)
    assert out.mode == 'safe' and out.current_command == 0.0
    assert any('no master input' in r for r in out.reasons)


def test_grip_on_needle_reaches_target_with_model_estimate(params):
    ctrl = GripController(params)
    inp = ctrl.new_inputs()
    out, _ = run_grip(ctrl, inp, n=400, master=0.1)
    assert out.mode == 'grip'
    assert out.target_force == pytest.approx(params.grip_force_max * 0.5)
    assert out.estimated_force == pytest.approx(out.target_force, rel=0.02)
    assert out.pull_out_force == pytest.approx(
        (math.sqrt(2) + 1) * params.needle_friction_coefficient * out.estimated_force)
    assert 0.0 < out.current_command <= params.max_current


def test_watchdog_safe_within_two_periods_and_ramps_down(params):
    ctrl = GripController(params)
    inp = ctrl.new_inputs()
    out, t = run_grip(ctrl, inp, n=300, master=0.0)
    i_before = out.current_command
    assert i_before > 0.2
    # instrument joint states stop; master and actuator keep coming
    last_instrument = inp.instrument_time
    modes, currents = [], []
    for k in range(60):
        now = t + k * PERIOD
        inp.set_master(now, 0.0)
        inp.set_actuator(now, ctrl.command)
        out = ctrl.step(now, inp)
        modes.append(out.mode)
        currents.append(out.current_command)
        if out.mode == 'safe':
            assert any('stale instrument' in r for r in out.reasons)
    first_safe = t + modes.index('safe') * PERIOD
    assert first_safe - (last_instrument + params.watchdog_timeout) <= 2 * PERIOD
    steps = np.abs(np.diff([i_before] + currents))
    assert np.all(steps <= params.max_current_slew * PERIOD + 1e-12)
    assert currents[-1] == 0.0                                   # ramped to zero


def test_resume_after_stale_without_current_jump(params):
    ctrl = GripController(params)
    inp = ctrl.new_inputs()
    _, t = run_grip(ctrl, inp, n=300, master=0.0)
    for k in range(35):                                          # 35 ms silence: safe
        out = ctrl.step(t + k * PERIOD, inp)
    assert out.mode == 'safe'
    held = out.current_command
    t += 35 * PERIOD
    feed(inp, t, 0.0, 0.04, ctrl.command)
    out = ctrl.step(t, inp)
    assert out.mode == 'grip'
    assert out.current_command == pytest.approx(held, abs=1e-12)   # bumpless: continues
    # and the loop then converges back to the target force
    out, _ = run_grip(ctrl, inp, n=400, master=0.0, t0=t + PERIOD)
    assert out.estimated_force == pytest.approx(out.target_force, rel=0.02)


@pytest.mark.parametrize('ramp', [0.1, 0.02, 0.0])
def test_resume_ramp_time_sets_how_the_force_target_returns(params, ramp):
    ctrl = GripController(params, resume_ramp_time=ramp)
    inp = ctrl.new_inputs()
    out, t = run_grip(ctrl, inp, n=300, master=0.0)
    target = out.target_force                                     # N, the map's target
    for k in range(35):                                          # 35 ms silence: safe
        ctrl.step(t + k * PERIOD, inp)
    t += 35 * PERIOD
    feed(inp, t, 0.0, 0.04, ctrl.command)
    out = ctrl.step(t, inp)
    assert out.mode == 'grip' and out.estimated_force < 0.5 * target
    if ramp == 0.0:                                              # no ramp: the map's target at once
        assert out.target_force == target
    else:                                                        # one period's climb from the estimate
        step = params.grip_force_max * PERIOD / ramp
        assert out.target_force == pytest.approx(out.estimated_force + step, rel=1e-12)


@pytest.mark.parametrize('ramp', [-0.1, math.inf, math.nan])
def test_resume_ramp_time_must_be_finite_and_not_negative(params, ramp):
    with pytest.raises(ValueError, match='resume_ramp_time'):
        GripController(params, resume_ramp_time=ramp)


def test_free_to_grip_switch_is_bumpless(params):
    ctrl = GripController(params)
    inp = ctrl.new_inputs()
    cmds = []
    masters = np.concatenate([np.full(100, 0.5), np.linspace(0.5, 0.1, 200)])
    jaw = 0.5
    for k, m in enumerate(masters):
        t = k * PERIOD
        jaw = max(0.04, m)                                       # jaw follows until the needle
        feed(inp, t, m, jaw, ctrl.command)
        out = ctrl.step(t, inp)
        cmds.append((out.mode, out.current_command, out.feedforward_current))
    modes = [c[0] for c in cmds]
    k = modes.index('grip')
    assert modes[k - 1] == 'free'
    # the feedforward appears at the switch but the command does not jump
    assert abs(cmds[k][1] - cmds[k - 1][1]) < 0.01


@pytest.mark.parametrize('bad', [
    dict(master=math.nan), dict(jaw=math.inf), dict(jaw=3.0), dict(wrist=-2.0),
    dict(current=math.nan), dict(current=50.0), dict(master=9.0)])
def test_invalid_input_goes_safe_at_once_and_says_why(params, bad):
    ctrl = GripController(params)
    inp = ctrl.new_inputs()
    _, t = run_grip(ctrl, inp, n=200, master=0.0)
    values = dict(master=0.0, jaw=0.04, current=ctrl.command, wrist=0.0)
    values.update(bad)
    inp.set_master(t, values['master'])
    inp.set_instrument(t, values['wrist'], values['jaw'], 0.0)
    inp.set_actuator(t, values['current'])
    out = ctrl.step(t, inp)
    assert out.mode == 'safe'
    assert any(r.startswith('invalid input') for r in out.reasons)
    assert all(math.isfinite(v) for v in (out.current_command, out.target_force,
                                          out.estimated_force, out.pull_out_force))


def test_force_sensor_feedback_used_when_enabled(params):
    ctrl = GripController(params.replace(force_sensor_enabled=True))
    inp = ctrl.new_inputs()
    for k in range(50):
        t = k * PERIOD
        feed(inp, t, 0.0, 0.04, ctrl.command)
        out = ctrl.step(t, inp)
    assert out.mode == 'safe' and any('no force input' in r for r in out.reasons)
    for k in range(50, 600):
        t = k * PERIOD
        feed(inp, t, 0.0, 0.04, ctrl.command)
        inp.set_force(t, 0.8 * ctrl.model.grip_force_scalar(ctrl.command, 0.0, 0.04, 'needle'))
        out = ctrl.step(t, inp)
    # the plant gives 20% less force than the model: the integrator makes up for it
    assert out.mode == 'grip'
    assert out.estimated_force == pytest.approx(out.target_force, rel=0.05)
    assert out.current_command > out.feedforward_current * 1.1


def test_nonfinite_clock_is_safe(params):
    ctrl = GripController(params)
    inp = ctrl.new_inputs()
    _, t = run_grip(ctrl, inp, n=50)
    out = ctrl.step(math.nan, inp)
    assert out.mode == 'safe' and 'clock' in out.reasons[0]


def test_runtime_gain_change_is_bumpless_and_takes_effect(params):
    ctrl = GripController(params)
    inp = ctrl.new_inputs()
    out, t = run_grip(ctrl, inp, n=300, master=0.05)
    before = out.current_command
    ctrl.update_params(params.replace(force_ki=2 * params.force_ki, grip_force_max=2.0))
    feed(inp, t, 0.05, 0.04, ctrl.command)
    out = ctrl.step(t, inp)
    assert out.mode == 'grip'
    assert abs(out.current_command - before) <= params.max_current_slew * PERIOD + 1e-12
    out, _ = run_grip(ctrl, inp, n=400, master=0.05, t0=t + PERIOD)
    assert ctrl.force_pid.ki == 2 * params.force_ki
    assert out.target_force == pytest.approx(2.0 * 0.15 / 0.2)      # the new map is used
    assert out.estimated_force == pytest.approx(out.target_force, rel=0.02)


def test_runtime_change_keeps_a_real_mode_for_diagnostics(params):
    ctrl = GripController(params)
    inp = ctrl.new_inputs()
    out, t = run_grip(ctrl, inp, n=300, master=0.05)
    assert out.mode is Mode.GRIP
    ctrl.update_params(params.replace(force_ki=2 * params.force_ki))
    status = ctrl.status(inp)
    assert status['mode'] == 'grip' and type(status['mode']) is str    # not a pseudo-mode
    assert ctrl.retuned
    feed(inp, t, 0.05, 0.04, ctrl.command)
    out = ctrl.step(t, inp)
    assert out.mode is Mode.GRIP and not ctrl.retuned                    # preset done, flag cleared
    assert {m.value for m in Mode} == {'free', 'grip', 'safe'}


class _ScalarPathsOnly:
    def __init__(self, model, **attributes):
        self.grip_force_scalar = model.grip_force_scalar
        self.current_for_force_scalar = model.current_for_force_scalar
        self.__dict__.update(attributes)


def test_stick_band_follows_the_models_declared_capability(params):
    model = GripForceModel(params)
    assert model.supports_stick_band is True
    assert GripController(params, model).stick_band is not None
    assert GripController(params, _ScalarPathsOnly(model)).stick_band is None
    # a model object that carries the private helpers but says no is taken at its word
    said_no = _ScalarPathsOnly(model, supports_stick_band=False, tension_per_amp=model.tension_per_amp,
                               _efficiency_scalar=model._efficiency_scalar)
    assert GripController(params, said_no).stick_band is None


def test_status_for_diagnostics(params):
    ctrl = GripController(params)
    inp = ctrl.new_inputs()
    run_grip(ctrl, inp, n=20)
    inp.set_instrument(1.0, math.nan, 0.1)
    ctrl.step(0.02, inp)
    status = ctrl.status(inp)
    assert status['mode'] == 'safe'
    assert 'non-finite' in status['reasons']
    assert status['rejected_inputs'] == '1'
    assert status['periods'] == '21'
    assert all(isinstance(v, str) for v in status.values())


def test_controller_cross_parameter_checks():
    from grip_force_ros.params import ParameterError
    with pytest.raises(ParameterError, match='master_angle_min'):
        make_params({'master_angle_min': 1.0, 'master_angle_max': 0.5})
    with pytest.raises(ParameterError, match='two control periods'):
        make_params({'watchdog_timeout': 0.002, 'control_rate': 500.0})


def test_unset_zero_stamps_are_not_duplicates(params):
    inp = ControlInputs.from_params(params)
    for k in range(3):
        assert inp.set_master(0.001 * k, 0.5, stamp=0.0) == (True, None)
        assert inp.master_time == 0.001 * k                    # every sample refreshes


def test_rejection_counters_stay_bounded(params):
    inp = ControlInputs.from_params(params)
    for k in range(5000):                    # every reason text differs by its numbers
        inp.set_instrument(k * 1e-3, 0.1, 2.0 + k * 1e-3)
        inp.set_master(k * 1e-3, 0.5, stamp=-k * 1.0)
    assert sum(inp.rejected.values()) == 5000 + 4999
    assert len(inp.rejected) <= 3
    assert inp.rejected['instrument: jaw angle # rad outside [#, #]'] == 5000


# --------------------------------------------------------------------------- late vs lost
def test_each_input_has_its_own_watchdog_and_feedback_never_outlives_the_set_point():
    from grip_force_ros.control.inputs import TIMEOUT_PARAMS
    from grip_force_ros.params import SPECS, ParameterError
    assert set(TIMEOUT_PARAMS) == {'master', 'instrument', 'actuator', 'force'}
    assert all(n in SPECS and SPECS[n].unit == 's' for n in TIMEOUT_PARAMS.values())
    p = make_params({})
    assert p.watchdog_timeout == p.actuator_watchdog_timeout == 0.03      # the dVRK's drive link
    assert p.master_watchdog_timeout > p.watchdog_timeout
    for name in ('watchdog_timeout', 'actuator_watchdog_timeout', 'force_watchdog_timeout'):
        with pytest.raises(ParameterError, match=f"'{name}' 0.2 s is longer than 'master_watchdog"):
            make_params({name: 0.2})
        with pytest.raises(ParameterError, match='two control periods'):
            make_params({name: 0.003, 'control_rate': 500.0})
    make_params({'watchdog_timeout': 0.2, 'master_watchdog_timeout': 0.2})   # equal is fine


def test_interval_estimate_follows_the_stream_and_ignores_stalls_and_bursts():
    from grip_force_ros.control.inputs import next_interval
    interval = math.nan
    for _ in range(50):
        interval = next_interval(interval, 4e-3)            # a 250 Hz master
    assert interval == pytest.approx(4e-3)
    assert next_interval(interval, 0.5) < 1.31 * interval    # one stall: clipped to 4x, gain 0.1
    assert next_interval(interval, math.nan) == interval and next_interval(interval, 0.0) == interval
    for _ in range(150):
        interval = next_interval(interval, 4e-4)            # a 10x burst
    from grip_force_ros.control.inputs import LATE_FACTOR
    late = 0
    for _ in range(12):                                     # back to 250 Hz
        late += 4e-3 > LATE_FACTOR * interval
        interval = next_interval(interval, 4e-3)
    assert late <= 5 and 4e-3 < LATE_FACTOR * interval      # normal gaps late for 5 samples only


def test_a_late_master_is_counted_and_the_hold_goes_on_with_its_last_value(params):
    """A 250 Hz master that stalls 60 ms (late: > 3 of its 4 ms intervals, < its 100 ms
    watchdog): grip goes on, no safe period, one late episode once it is back."""
    ctrl = GripController(params)
    inp = ctrl.new_inputs()
    t = 0.0
    for k in range(400):                       # 0.4 s of grip, master every 4th period
        t = k * PERIOD
        if k % 4 == 0:
            inp.set_master(t, 0.0)
        inp.set_instrument(t, 0.0, 0.04)
        inp.set_actuator(t, ctrl.command)
        out = ctrl.step(t, inp)
    assert out.mode == 'grip'
    target = out.target_force
    for k in range(1, 61):                     # 60 ms without the master
        now = t + k * PERIOD
        inp.set_instrument(now, 0.0, 0.04)
        inp.set_actuator(now, ctrl.command)
        out = ctrl.step(now, inp)
        assert out.mode == 'grip' and out.target_force == target
    assert ctrl.late_counts['master'] == 0     # counted when the episode ends
    now += PERIOD
    inp.set_master(now, 0.0)
    inp.set_instrument(now, 0.0, 0.04)
    inp.set_actuator(now, ctrl.command)
    out = ctrl.step(now, inp)
    assert out.mode == 'grip'
    assert ctrl.late_counts == {'master': 1, 'instrument': 0, 'actuator': 0, 'force': 0}
    oldest = now - PERIOD - 0.396              # the last step before it, on the 0.396 s sample
    assert ctrl.late_max_age['master'] == pytest.approx(oldest, abs=1e-9)
    status = ctrl.status(inp)
    assert status['late_inputs'] == '1' and status['late_master'] == '1'
    assert float(status['late_master_max_ms']) == pytest.approx(oldest * 1e3, abs=0.05)


def test_a_lost_master_trips_its_own_watchdog_and_is_not_counted_late(params):
    ctrl = GripController(params)
    inp = ctrl.new_inputs()
    _, t = run_grip(ctrl, inp, n=300, master=0.0)
    last = inp.master_time
    modes = []
    for k in range(130):
        now = t + k * PERIOD
        inp.set_instrument(now, 0.0, 0.04)
        inp.set_actuator(now, ctrl.command)
        out = ctrl.step(now, inp)
        modes.append(out.mode)
    first_safe = t + modes.index('safe') * PERIOD
    assert -1e-9 <= first_safe - (last + params.master_watchdog_timeout) <= 2 * PERIOD
    assert all(m == 'grip' for m in modes[:modes.index('safe')])    # held until then
    feed(inp, t + 130 * PERIOD, 0.0, 0.04, ctrl.command)
    ctrl.step(t + 130 * PERIOD, inp)
    assert ctrl.late_counts['master'] == 0     # lost, not late: the safe state reported it
    assert ctrl.late_max_age['master'] == 0.0  # nor its age


def test_a_stale_actuator_trips_at_its_own_timeout(params):
    params = params.replace(actuator_watchdog_timeout=0.01)
    ctrl = GripController(params)
    inp = ctrl.new_inputs()
    _, t = run_grip(ctrl, inp, n=300, master=0.0)
    last = inp.actuator_time
    for k in range(20):
        now = t + k * PERIOD
        inp.set_master(now, 0.0)
        inp.set_instrument(now, 0.0, 0.04)
        out = ctrl.step(now, inp)
        if out.mode == 'safe':
            break
    assert any('stale actuator input' in r and '> 10.0 ms' in r for r in out.reasons)
    assert now - (last + 0.01) <= 2 * PERIOD


def test_a_jaw_resting_open_past_its_target_is_not_an_object():
    """Started (or resumed after a safe state at 0 A) with the jaw resting open wider than the
    master asks, here at its open stop, the controller stays in free motion and closes the
    jaw to the master's angle: the rest is not a blocked jaw (it moves once pulled). Before
    CONTACT_CONFIRM_TIME it read the resting jaw as an object and held a 0 N grip."""
    from grip_force_ros.params.files import instrument_path
    from grip_force_ros.params import load_params_file
    from grip_force_ros.sim import InstrumentSim
    params = load_params_file(instrument_path('paper_needle_driver'))
    sim = InstrumentSim(params, obj='needle', seed=0)
    for _ in range(300):                       # 0.3 s at -0.03 A: the jaw opens to its stop
        sim.step(-0.03, 1e-3)
    assert sim.measure().jaw_angle > 1.5
    ctrl = GripController(params)
    inputs = ctrl.new_inputs()
    modes = set()
    for k in range(2000):
        t = k * 1e-3
        _, out = closed_loop_step(sim, ctrl, inputs, t, 0.8, 1e-3, sources=NO_FORCE_SENSOR)
        modes.add(out.mode)
    assert Mode.GRIP not in modes
    assert sim.measure().jaw_angle == pytest.approx(0.8, abs=0.01)


def test_a_blocked_jaw_is_contact_after_the_confirm_time():
    """An object keeps the jaw blocked: contact once it has been blocked for the confirm time
    (master still, jaw 0.1 rad above its target, not moving); a jaw that moves again resets
    the count."""
    from grip_force_ros.control.force_map import CONTACT_CONFIRM_TIME
    fmap = ForceMap(master_angle_min=0.0, master_contact_angle=0.2, master_to_jaw_gain=1.0,
                    jaw_angle_max=1.5, force_max=4.0)
    dt = 1e-3
    steps = round(CONTACT_CONFIRM_TIME / dt)
    for _ in range(steps - 1):
        assert fmap.update(0.5, 0.6, 0.0, dt) == (False, 0.5)
    assert fmap.update(0.5, 0.6, 1.0, dt) == (False, 0.5)      # moving: not blocked
    for _ in range(steps - 1):
        assert fmap.update(0.5, 0.6, 0.0, dt)[0] is False
    gripping, target = fmap.update(0.5, 0.6, 0.0, dt)
    assert gripping and target == 0.0 and fmap.contact_angle == 0.5
