"""Controller parameters (group 'controller'). Owned by control/; see docs/control.md.

Gains are per instrument: ``grip-force tune --config X.yaml`` designs them on a
linear plant model at ``gain_design_rate``, with the knees of their schedule on the state
rate (control/schedule.py), and the instrument YAMLs carry the result. The defaults here
are the design for the paper's needle driver (``config/paper_needle_driver.yaml``).
"""
from grip_force_ros.objects import OBJECTS
from grip_force_ros.params.schema import ParamSpec

_P = ParamSpec
_G = 'controller'

#: State rates (Hz) over which the gains are shown stable (docs/control.md, "Rate
#: independence": hold error, overshoot and settling measured at 100..1500 Hz); the
#: controller refuses to start outside them.
STATE_RATE_MIN = 100.0
STATE_RATE_MAX = 1500.0
#: The watchdog timeout must cover this many state periods (a state may come late by one).
WATCHDOG_STATE_PERIODS = 2.0
#: The watchdog timeouts of the inputs the loop closes on (instrument joints, actuator, load
#: cell) and of the set point (master); control/inputs.py maps each input source to its own.
FEEDBACK_TIMEOUTS = ('watchdog_timeout', 'actuator_watchdog_timeout', 'force_watchdog_timeout')
MASTER_TIMEOUT = 'master_watchdog_timeout'

CONTROLLER = [
    # --- loop timing and watchdog -------------------------------------------------------
    _P('control_rate', 'double', 1000.0, 'Hz',
       'Rate of the watchdog timer: it checks the inputs this often and steps the controller '
       'when no state came (a lost state, or silence). The control steps themselves run on the '
       'instrument states, on the measured time between them (expected_state_rate).',
       min=100.0, max=10000.0, read_only=True, group=_G),
    _P('expected_state_rate', 'double', 1000.0, 'Hz',
       'Rate of the instrument state the controller steps on (the combined '
       'instrument/measured_js, or instrument/actuator/measured_js of a split driver; '
       'dvrk: <arm>/jaw/measured_js, 100 Hz by default). The PID, filters and slew limit step '
       'on the measured time between states; the gains are scheduled on this rate '
       '(gain_design_rate) and shown stable from '
       f'{STATE_RATE_MIN:g} to {STATE_RATE_MAX:g} Hz (docs/control.md), and the node refuses '
       'to start outside that range. A step interval longer than watchdog_timeout is a fault.',
       min=STATE_RATE_MIN, max=STATE_RATE_MAX, read_only=True, group=_G),
    # One watchdog per input (docs/control.md, "Late and lost inputs"): an input older than its
    # timeout (by receive time) is lost and puts the output in the safe state (the current
    # ramps to 0 at the slew limit); younger, control goes on with its last value, and an
    # input older than three of its own sample intervals is counted late (/diagnostics).
    # The feedback watchdogs must cover two state periods (expected_state_rate).
    _P('watchdog_timeout', 'double', 0.03, 's',
       'Watchdog of the instrument joint states (instrument/measured_js): older than this by '
       'its receive time, the input is lost and the output goes to the safe state. 30 ms, the '
       "dVRK's watchdog on its drive link. Must cover two state periods (expected_state_rate).",
       min=0.002, max=1.0, group=_G),
    _P('actuator_watchdog_timeout', 'double', 0.03, 's',
       'Watchdog of the actuator state (measured current, drum angle: the jaw_drum of the '
       'combined instrument/measured_js, or instrument/actuator/measured_js of a split '
       "driver), the loop's feedback on the drive link. 30 ms, as the dVRK's drive link.",
       min=0.002, max=1.0, group=_G),
    _P('force_watchdog_timeout', 'double', 0.03, 's',
       'Watchdog of the load cell (grip/measured_force) when force_sensor_enabled: the force '
       'loop closes on it, so a stale force is a stale feedback, as the drive link: 30 ms.',
       min=0.002, max=1.0, group=_G),
    _P('master_watchdog_timeout', 'double', 0.1, 's',
       "Watchdog of the master console stream (master/gripper/measured_js), the set point. Up to "
       'this age the hold goes on with the last master angle (a console at 100 Hz-1 kHz with '
       "jitter, or a stalled process, is late, not lost); 0.1 s is below a surgeon's visual "
       'reaction time (~0.2 s), and the grip force stays closed-loop on fresh instrument data '
       'meanwhile. Never below the feedback watchdogs.',
       min=0.002, max=1.0, group=_G),
    _P('force_output_rate', 'double', 100.0, 'Hz',
       'Rate of the estimated force, its band and the target force outputs (grip/estimated_force, '
       'grip/estimate_band, grip/target_force): nobody reads them at the loop\'s rate, and two '
       'publishes a period would cost the loop (BENCHMARKS.md, "The nodes\' own cost"). The '
       'command keeps the '
       'state rate; at or above expected_state_rate the forces go out every step.',
       min=1.0, max=STATE_RATE_MAX, group=_G),
    _P('stamp_future_tolerance', 'double', 0.1, 's',
       'A message stamped more than this ahead of the controller clock is rejected as invalid.',
       min=0.0, max=10.0, group=_G),
    # --- what is held and how it is measured ------------------------------------------
    _P('object_kind', 'string', 'needle', '',
       'Object the jaw grips, for the contact model of the feedforward and the force estimate.',
       choices=OBJECTS, group=_G),
    _P('force_sensor_enabled', 'bool', False, '',
       'Use the grip force sensor topic as force feedback; otherwise the model estimate from '
       'the measured current.', group=_G),
    _P('feedforward_enabled', 'bool', True, '',
       'Add the inverse-model current for the target force at the measured wrist and jaw angles.',
       group=_G),
    _P('stick_branch_band', 'double', 0.02, '-',
       'Sensorless: band (fraction of max_grip_force) around the estimated force inside which the '
       "feedforward keeps its stick-band branch (loading / unloading) instead of switching. The "
       'switch is a relay inside the force loop: too narrow a band on an instrument whose '
       'friction grows with tension runs a limit cycle (four_pulley_needle_driver: 20 Hz at 0.02, '
       'docs/control.md); a wide one leaves an unloading hold up to the band above its target.',
       min=0.005, max=0.25, group=_G),
    # --- force map: master gripper angle -> jaw angle target or grip force target ------
    _P('master_angle_min', 'double', 0.0, 'rad',
       'Master gripper angle when fully closed; below it the angle is clamped and flagged.',
       min=-1.0, max=3.0, group=_G),
    _P('master_angle_max', 'double', 1.2, 'rad',
       'Master gripper angle when fully open; above it the angle is clamped and flagged.',
       min=-1.0, max=3.0, group=_G),
    _P('master_angle_tolerance', 'double', 0.5, 'rad',
       'A master angle further than this outside [master_angle_min, master_angle_max] is '
       'rejected as invalid (safe state) rather than clamped.', min=0.0, max=3.0, group=_G),
    _P('master_to_jaw_gain', 'double', 1.0, 'rad/rad',
       'Jaw angle target per rad of master gripper angle in free motion.',
       min=0.05, max=10.0, group=_G),
    _P('master_contact_angle', 'double', 0.2, 'rad',
       'Below this master angle the controller grips (force control) even if no contact was '
       'detected; the grip force target rises from 0 here to grip_force_max at master_angle_min.',
       min=-1.0, max=3.0, group=_G),
    _P('grip_force_max', 'double', 4.0, 'N',
       'Grip force target at the fully closed master (never above the read-only max_grip_force).',
       min=0.0, max=200.0, group=_G),
    _P('force_map_exponent', 'double', 1.0, '',
       'Shape of the force map: target = grip_force_max * s**exponent, s in [0, 1] the share of '
       'master travel closed past contact (1 = linear).', min=0.2, max=5.0, group=_G),
    _P('contact_jaw_margin', 'double', 0.05, 'rad',
       'Contact is detected when the measured jaw angle stays this far above its target '
       '(the jaw is blocked by an object); the force then rises with further master closing.',
       min=0.001, max=1.0, group=_G),
    _P('contact_jaw_speed', 'double', 0.5, 'rad/s',
       'Contact is only detected while the jaw moves slower than this (blocked, not lagging).',
       min=0.0, max=100.0, group=_G),
    _P('grip_release_hysteresis', 'double', 0.02, 'rad',
       'The master must open this far past the contact angle to leave grip for free motion.',
       min=0.0, max=0.5, group=_G),
    # --- gain schedule on the state rate (control/schedule.py) ------------------------------
    _P('gain_design_rate', 'double', 1000.0, 'Hz',
       'State rate the force_* and jaw_* gains are designed at (grip-force tune). At an '
       'expected_state_rate below it the controller shrinks each loop\'s crossover by the gain '
       'schedule (force_schedule_knee, jaw_schedule_knee; docs/control.md); at and above it the '
       'gains run as designed.', min=STATE_RATE_MIN, max=STATE_RATE_MAX, group=_G),
    _P('force_schedule_knee', 'double', 680.0, 'Hz',
       'Knee of the force loop\'s gain schedule: the state rate at which the sampling (one '
       'period of delay and the hold) costs as much phase at the crossover as the plant\'s own '
       'lag. Below gain_design_rate the crossover scales by (1/knee + 1/gain_design_rate) / '
       '(1/knee + 1/expected_state_rate); from grip-force tune.', min=10.0, max=1.0e5, group=_G),
    _P('jaw_schedule_knee', 'double', 820.0, 'Hz',
       'Knee of the jaw loop\'s gain schedule (as force_schedule_knee); from grip-force tune.',
       min=10.0, max=1.0e5, group=_G),
    # --- force loop (grip) -----------------------------------------------------------------
    _P('force_kp', 'double', 0.00883, 'A/N',
       'Proportional gain of the force loop, at gain_design_rate (scheduled below it).',
       min=0.0, max=10.0, group=_G),
    _P('force_ki', 'double', 5.52, 'A/(N*s)',
       'Integral gain of the force loop, at gain_design_rate (scheduled below it).',
       min=0.0, max=1000.0, group=_G),
    _P('force_kd', 'double', 0.0, 'A*s/N',
       'Derivative gain of the force loop (on the filtered measurement), at gain_design_rate '
       '(scheduled below it).',
       min=0.0, max=1.0, group=_G),
    _P('force_derivative_filter_time', 'double', 0.0005, 's',
       'Time constant of the first-order filter of the force derivative, at gain_design_rate (below '
       'it the filter keeps its number of state periods).',
       min=1e-4, max=1.0, group=_G),
    # --- jaw angle loop (free motion) ------------------------------------------------------
    _P('jaw_kp', 'double', 0.369, 'A/rad',
       'Proportional gain of the jaw angle loop in free motion, at gain_design_rate (scheduled '
       'below it).', min=0.0, max=100.0, group=_G),
    _P('jaw_ki', 'double', 0.0354, 'A/(rad*s)',
       'Integral gain of the jaw angle loop, at gain_design_rate (scheduled below it).',
       min=0.0, max=10000.0, group=_G),
    _P('jaw_kd', 'double', 0.00059, 'A*s/rad',
       'Derivative gain of the jaw angle loop (on the filtered measurement), at gain_design_rate '
       '(scheduled below it).',
       min=0.0, max=10.0, group=_G),
    _P('jaw_derivative_filter_time', 'double', 0.002, 's',
       'Time constant of the first-order filter of the jaw angle derivative, at gain_design_rate '
       '(below it the filter keeps its number of state periods).',
       min=1e-4, max=1.0, group=_G),
    _P('anti_windup_tracking_time', 'double', 0.01, 's',
       'Back-calculation anti-windup: the integrator tracks the limited command with this '
       'time constant (never below one control period).', min=1e-4, max=10.0, group=_G),
    _P('bumpless_transfer_time', 'double', 0.02, 's',
       'On a switch (free <-> grip, or back from the safe state) the command continues from its '
       'last value; the difference to the new loop output decays with this time constant.',
       min=1e-3, max=1.0, group=_G),
    # --- lifecycle and services of the node (docs/ros_interface.md) ----------------------
    _P('autostart', 'bool', True, '',
       'The controller node is a lifecycle node: with true it configures and activates itself '
       'at start (ros2 run, the launch files, the demo); with false it waits unconfigured, '
       'sending no command, for `ros2 lifecycle set /controller configure` and `activate`.',
       read_only=True, group=_G),
    _P('load_cell_offset', 'double', 0.0, 'N',
       'Subtracted from the load-cell grip force (grip/measured_force) before use. ~/tare sets '
       'it: the mean reading with the jaw open and no grip force.', min=-50.0, max=50.0, group=_G),
    _P('current_sensor_offset', 'double', 0.0, 'A',
       'Subtracted from the measured motor current before use. ~/tare sets it: the mean of '
       'measured minus commanded current with the jaw open and no grip force.',
       min=-5.0, max=5.0, group=_G),
    _P('tare_duration', 'double', 0.2, 's',
       'Averaging window of ~/tare (one sample per control step).', min=0.01, max=5.0, group=_G),
    _P('tare_jaw_open_angle', 'double', 0.3, 'rad',
       '~/tare refuses (and stops) while the measured jaw angle is below this: the jaw must be '
       'open, touching nothing (above the sim\'s tissue contact, 0.25 rad).',
       min=0.0, max=3.0, group=_G),
    # --- the grasp actions (grip_command, parallel_grip_command; docs/ros_interface.md) ----
    _P('action_force_tolerance', 'double', 0.02, '',
       'A grasp goal is settled (its result goes out) when the grip force has stayed within '
       'this fraction of the goal force (max_effort) for action_settle_time; the goal then holds '
       'on. At least 0.01 N.', min=0.001, max=0.5, group=_G),
    _P('action_settle_time', 'double', 0.1, 's',
       'How long the force (in contact) or the jaw (no contact) must stay within its tolerance '
       'before a grasp goal is settled.', min=0.0, max=10.0, group=_G),
    _P('action_position_tolerance', 'double', 0.02, 'rad',
       'A grasp goal with no contact is reached when the jaw is within this of the goal '
       'position; a cancel is done when the jaw is within this of action_release_angle.',
       min=0.001, max=1.0, group=_G),
    _P('action_release_angle', 'double', 0.4, 'rad',
       'A cancelled grasp goal opens the jaw to this angle (at most jaw_angle_max) with no '
       'grip force, the safe open state.', min=0.0, max=3.0, group=_G),
    _P('action_takeover_angle', 'double', 0.05, 'rad',
       'After a grasp goal is done (settled or cancelled) it holds on until the master gripper '
       'moves more than this from where it was then: the master then commands again, '
       'bumplessly (the current continues, the force target ramps from the present force).',
       min=0.001, max=3.0, group=_G),
    _P('action_feedback_rate', 'double', 10.0, 'Hz',
       'Rate of the grasp actions\' feedback (jaw position, estimated grip force, stalled, '
       'reached_goal).', min=1.0, max=100.0, group=_G),
    _P('calibration_file', 'string', '', '',
       'Where ~/calibrate writes the calibrated parameter YAML; empty: '
       '$ROS_HOME/grip_force_ros/<instrument_name>_calibrated.yaml ($ROS_HOME: ~/.ros).',
       group=_G),
]


def check_controller(values) -> None:
    """Cross-parameter checks of the 'controller' group (called by ``check_consistency``).

    Raises
    ------
    ParameterError
        Naming the keys and values.
    """
    from grip_force_ros.params.schema import ParameterError
    lo, hi = values['master_angle_min'], values['master_angle_max']
    if lo >= hi:
        raise ParameterError(f"'master_angle_min' {lo} rad must be below 'master_angle_max' {hi} rad")
    for name in (MASTER_TIMEOUT,) + FEEDBACK_TIMEOUTS:
        periods = values[name] * values['control_rate']
        if periods < 2.0:
            raise ParameterError(
                f"'{name}' {values[name]} s is less than two control periods at 'control_rate' "
                f"{values['control_rate']} Hz: every input would be stale")
    rate = values['expected_state_rate']
    for name in FEEDBACK_TIMEOUTS:
        if values[name] * rate < WATCHDOG_STATE_PERIODS:
            raise ParameterError(
                f"'{name}' {values[name]} s is less than {WATCHDOG_STATE_PERIODS:g} state periods "
                f"at 'expected_state_rate' {rate:g} Hz ({WATCHDOG_STATE_PERIODS / rate * 1e3:g} ms): "
                'every state would arrive stale')
    # A lost feedback leaves the force loop acting on an old measurement (the integrator winds
    # on an old error); a lost set point only holds the grasp. The first must never be
    # tolerated longer than the second.
    for name in FEEDBACK_TIMEOUTS:
        if values[name] > values[MASTER_TIMEOUT]:
            raise ParameterError(
                f"'{name}' {values[name]} s is longer than '{MASTER_TIMEOUT}' "
                f'{values[MASTER_TIMEOUT]} s: a stale feedback would be tolerated longer than a '
                'stale set point')
