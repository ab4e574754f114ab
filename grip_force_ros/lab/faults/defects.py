"""Negative control of the fault check: deliberately broken controller builds.

A fault check that passes says little unless it can fail. Each defect here breaks one
safety function of the controller core, and the fault catalogue must catch every one of
them: ``run_faultcheck`` (``grip-force faultcheck``) runs each defect's matching cases on
a controller with that defect and reports ``negative_control: {cases, caught}``.

The test-only switch: a defect exists only as a class swapped onto the controller object
of the fault check's own in-process ``ControllerNode`` (:func:`break_controller`). No
parameter, environment variable or command-line argument of the ``controller`` executable
reaches this module (only ``lab/faults/runner.py`` imports it; ``nodes/`` may not import
``faults/``, ``test_layers``), so a robot's controller cannot be started with a defect by
accident. :func:`break_controller` also refuses to run outside a fault check
(:data:`NEGATIVE_CONTROL_FLAG`, set only while :func:`negative_control_session` runs).
"""
from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass

from grip_force_ros.control import ControlInputs, GripController
from grip_force_ros.control.limits import CurrentLimiter

#: Set (to a truthy value) only inside :func:`negative_control_session`.
NEGATIVE_CONTROL_FLAG = {'active': False}
#: (module, attribute, original) patched by a defect, restored at the end of the session.
_PATCHED: list = []
_INF = math.inf


@dataclass(frozen=True)
class Defect:
    """One deliberately broken safety function.

    Attributes
    ----------
    name : str
        Identifier (``current_limit_off``, ...).
    description : str
        What is broken.
    cases : tuple of str
        Catalogue cases that must fail on a controller with this defect (the matching cases).
    """

    name: str
    description: str
    cases: tuple


DEFECTS = {d.name: d for d in (
    Defect('current_limit_off', 'the current limit is gone (slew limit kept)',
           ('force_sensor_stuck_at_zero',)),
    Defect('slew_limit_off', 'the slew limit is gone: the command may jump (current limit kept)',
           ('silence_instrument', 'jaw_angle_above_range', 'force_sensor_stuck_then_silent')),
    Defect('watchdog_off', 'no input is ever stale: the watchdogs never trip',
           ('silence_master', 'silence_instrument', 'silence_actuator', 'frozen_stamp_actuator')),
    Defect('nan_passed_through', 'non-finite input values are stored as good samples',
           ('nan_instrument_wrist_angle', 'nan_actuator_measured_current',
            'nan_master_gripper_angle')),
)}


class _NanThroughInputs(ControlInputs):
    """ControlInputs that store non-finite values instead of rejecting them (a defect)."""

    __slots__ = ()

    def set_master(self, receive_time, master_angle, stamp=math.nan):
        if not math.isfinite(master_angle):
            self.master_angle, self.master_time, self.master_fault = master_angle, receive_time, None
            return None
        return super().set_master(receive_time, master_angle, stamp)

    def set_instrument(self, receive_time, wrist_angle, jaw_angle, jaw_velocity=0.0, stamp=math.nan):
        if not all(math.isfinite(v) for v in (wrist_angle, jaw_angle, jaw_velocity)):
            self.wrist_angle, self.jaw_angle, self.jaw_velocity = wrist_angle, jaw_angle, jaw_velocity
            self.instrument_time, self.instrument_fault = receive_time, None
            return None
        return super().set_instrument(receive_time, wrist_angle, jaw_angle, jaw_velocity, stamp)

    def set_actuator(self, receive_time, measured_current, motor_angle=0.0, motor_velocity=0.0,
                     stamp=math.nan):
        if not all(math.isfinite(v) for v in (measured_current, motor_angle, motor_velocity)):
            self.measured_current, self.motor_angle = measured_current, motor_angle
            self.motor_velocity, self.actuator_time, self.actuator_fault = motor_velocity, receive_time, None
            return None
        return super().set_actuator(receive_time, measured_current, motor_angle, motor_velocity, stamp)


def _broken_controller_class(defect: str) -> type:
    """Make a GripController subclass whose configuration re-applies ``defect`` (retunes too)."""

    class Broken(GripController):
        def _configure(self, params):
            super()._configure(params)
            if defect == 'current_limit_off':
                self.limiter = CurrentLimiter(_INF, params.max_current_slew, self.period)
            elif defect == 'slew_limit_off':
                self.limiter = CurrentLimiter(params.max_current, _INF, self.period)
            elif defect == 'watchdog_off':
                self.timeouts = dict.fromkeys(self.timeouts, _INF)
                self._required = tuple(r[:4] + (_INF,) for r in self._required)

    Broken.__name__ = f'GripController_{defect}'
    return Broken


def _lenient_read_joints(msg, joints, fields, others=False):
    """``read_joints`` without its finite check (the node-side half of ``nan_passed_through``)."""
    from grip_force_ros.nodes.common import InputRejected
    names = list(msg.name)
    try:
        return {n: tuple(float(getattr(msg, f)[names.index(n)]) for f in fields) for n in joints}
    except (ValueError, IndexError) as exc:
        raise InputRejected(f'malformed: {exc}') from None


def break_controller(node, defect: str) -> None:
    """Give the in-process ``ControllerNode`` ``node`` the defect ``defect``.

    Raises
    ------
    RuntimeError
        Outside :func:`negative_control_session` (the test-only switch).
    ValueError
        An unknown defect.
    """
    if not NEGATIVE_CONTROL_FLAG['active']:
        raise RuntimeError('a controller defect can only be injected by the fault check\'s '
                           'negative control (faults.defects.negative_control_session)')
    if defect not in DEFECTS:
        raise ValueError(f'unknown defect {defect!r}; one of {sorted(DEFECTS)}')
    if defect == 'nan_passed_through':
        from grip_force_ros.nodes import controller_io as node_module   # the profiles read joints there
        node.inputs.__class__ = _NanThroughInputs
        _PATCHED.append((node_module, 'read_joints', node_module.read_joints))
        node_module.read_joints = _lenient_read_joints
        return
    ctrl = node.controller
    ctrl.__class__ = _broken_controller_class(defect)
    ctrl._configure(ctrl.params)


@contextlib.contextmanager
def negative_control_session():
    """Allow :func:`break_controller` inside this block (the fault check's negative control).

    Everything patched in it is restored at its end.
    """
    NEGATIVE_CONTROL_FLAG['active'] = True
    try:
        yield
    finally:
        NEGATIVE_CONTROL_FLAG['active'] = False
        while _PATCHED:
            module, name, original = _PATCHED.pop()
            setattr(module, name, original)
