"""Simulated cable-driven instrument (ROS-free): the plant that stands in for hardware.

>>> from grip_force_ros.params import make_params
>>> from grip_force_ros.sim import InstrumentSim
>>> sim = InstrumentSim(make_params(), obj='needle', effects={'backlash': 0.02}, seed=1)
>>> for _ in range(100):
...     sim.step(0.3, 0.001)          # current command (A), dt (s)
>>> m = sim.measure()                 # SimMeasurement: t, motor_angle, ..., grip_force

See docs/sim.md for the dynamics, the effects and the measured step response.
"""
from grip_force_ros.sim.effects import EFFECT_NAMES, SimError
from grip_force_ros.sim.plant import OBJECTS, InstrumentSim, SimMeasurement
from grip_force_ros.sim.offline import simulate
from grip_force_ros.sim.quasistatic import capstan_play, quasi_static_grip_force
from grip_force_ros.sim.step_response import StepMetrics, step_response_metrics

__all__ = ['EFFECT_NAMES', 'OBJECTS', 'InstrumentSim', 'SimMeasurement', 'SimError', 'simulate',
           'StepMetrics', 'step_response_metrics', 'capstan_play', 'quasi_static_grip_force']
