"""Grip-force model of a cable-driven surgical instrument (numpy only, no rclpy).

>>> from grip_force_ros.params import make_params
>>> from grip_force_ros.model import GripForceModel
>>> m = GripForceModel(make_params())
>>> round(m.grip_force_scalar(0.35, 0.0, 0.0, 'needle'), 3)   # doctest: +SKIP

Modules: ``friction`` (pulley ratio eta, efficiency lambda_n), ``transmission``
(current -> drum tension -> drive torque), ``angle`` (coupling + creep), ``contact``
(rigid, tissue, needle, pull-out), ``instrument`` (:class:`GripForceModel`, the loading
branch), ``hysteresis`` (:class:`HystereticGripForce`: the pulleys' stick band, direction-aware).
"""
from grip_force_ros.model.contact import OBJECTS, ModelError
from grip_force_ros.model.instrument import ForwardResult, GripForceModel, check_instrument
from grip_force_ros.model.hysteresis import HystereticGripForce, hysteretic_grip_force, play_operator

__all__ = ['GripForceModel', 'ForwardResult', 'ModelError', 'OBJECTS', 'check_instrument',
           'HystereticGripForce', 'hysteretic_grip_force', 'play_operator']
