"""Grip-force controller core: ROS-free, plain values in, plain values out (SI units).

Public API (stable; the rclpy node in ``nodes/controller.py`` wires it)::

    from grip_force_ros.control import GripController, ControlInputs, ControlOutput, Mode

    ctrl = GripController(params)            # params: ParamSet (instrument + limits + controller)
    inputs = ctrl.new_inputs()               # ControlInputs, validated in one place
    # in the subscription callbacks (receive_time = node clock now [s], stamp = header stamp [s],
    # same clock; stamp=nan skips the stamp checks). Each returns (fresh, reason): fresh is
    # True when the sample was accepted as a new one (False: a duplicate or rejected), reason
    # None or why the sample was rejected (str; publish it on /diagnostics):
    inputs.set_master(receive_time, master_angle)                      # [rad]
    inputs.set_instrument(receive_time, wrist_angle, jaw_angle, jaw_velocity=0.0, stamp=nan)
    inputs.set_actuator(receive_time, measured_current, motor_angle=0.0, motor_velocity=0.0,
                        stamp=nan)                                     # [A], [rad], [rad/s]
    inputs.set_force(receive_time, grip_force, stamp=nan)              # [N], load cell (optional)
    inputs.reject(source, receive_time, reason)   # a malformed message (missing joint, bad length)
    # once per control period (the node: on each fresh actuator state, its control_rate
    # timer only as the fallback when no state came):
    out = ctrl.step(now, inputs)             # -> ControlOutput (a NamedTuple)
    out.current_command    # [A]  motor current command, |.| <= max_current, slew-limited
    out.target_force       # [N]  0 in free motion and in the safe state
    out.estimated_force    # [N]  grip force used as feedback (sensor, or the direction-aware
                           #      model estimate: model/hysteresis.py, the pulleys' stick band)
    out.pull_out_force     # [N]  needle pull-out force from the estimate (0 unless needle)
    out.mode               # Mode.FREE | Mode.GRIP | Mode.SAFE (a str enum: 'free', 'grip', 'safe')
    out.limits_hit         # tuple of 'current_limit', 'slew_limit'
    out.reasons            # tuple of str: why safe, what was clamped; () when all is well
    out.target_jaw_angle   # [rad] jaw target in free motion (measured jaw angle otherwise)
    out.feedforward_current  # [A]
    out.band_low, out.band_high  # [N] the sensorless estimate's band: the jaw friction holds the
                                 #     force between them while the jaw sticks (jaw friction
                                 #     terms on); else both the estimate (no band)
    out.band_width         # [N]  band_high - band_low (0: no band; load cell, paper instruments)
    out.estimate_held      # bool: the estimate is held strictly inside the band (stick: a
                           #       change of load does not show in the current)
    ctrl.status(inputs)      # dict[str, str] for /diagnostics: mode, reasons, counters, rejections,
                             # the band ('estimate': 'held in stick, band 0.412 N', ...)
    ctrl.update_params(new_params)  # runtime change (validated ParamSet), bumpless; the node
                                    # refuses read-only parameters first (ParamSpec.read_only)
    # a grasp goal (control/grasp.py; the node's GripperCommand actions) commands instead of
    # the master until it ends; the master resumes bumplessly:
    ctrl.start_goal(GraspGoal(position, force, params, force_rate=..., contact_confirm_time=...))
    ctrl.commander           # 'master' or 'action (<goal state>)'
    ctrl.end_goal()

Sources are ``'master'``, ``'instrument'``, ``'actuator'`` and ``'force'`` (the last one
only required when ``force_sensor_enabled``).

Safe state (documented choice): the current command ramps to 0 A at the slew limit
(``max_current_slew``); ``mode is Mode.SAFE`` from the first ``step`` after a required input
became stale (older than ``watchdog_timeout`` by its receive time), missing, or invalid
(NaN/inf, out-of-range angle or current, stamp backwards or ahead of the receive time by
more than ``stamp_future_tolerance``), with the reason in ``out.reasons``. A rejected sample
is not stored (the last good value is kept) and its source stays faulted until a valid
sample arrives. When all inputs are good again, control resumes bumplessly: the PID
integrator is preset so the command continues from its last value (no current jump), and
the force target ramps from the estimate to the map's target over ``resume_ramp_time``
(constructor argument, default ``RESUME_RAMP_TIME`` = 0.1 s for the full ``grip_force_max``).
A runtime parameter change (``update_params``) presets the PID on the next step, in whatever
mode it is (the mode stays a real one: /diagnostics never shows another).
A duplicate sample (same stamp as the last one) is ignored and does not refresh the
watchdog. Master angles slightly outside [master_angle_min, master_angle_max] are clamped
and flagged; beyond ``master_angle_tolerance`` they are invalid.

Pieces (small classes, each usable alone): :class:`ForceMap` (master angle -> free jaw target
or grip force target), :class:`PID` (back-calculation anti-windup, filtered derivative on the
measurement, bumpless preset), :class:`CurrentLimiter` (current and slew limits, reports
which hit). The gains are designed offline by `grip-force tune` (the laboratory).
"""
from grip_force_ros.control.controller import ControlOutput, GripController, Mode
from grip_force_ros.control.force_map import ForceMap
from grip_force_ros.control.inputs import SOURCES, ControlInputs
from grip_force_ros.control.limits import CurrentLimiter
from grip_force_ros.control.pid import PID

__all__ = ['GripController', 'ControlInputs', 'ControlOutput', 'Mode', 'ForceMap', 'PID',
           'CurrentLimiter', 'SOURCES']
