"""Identification: instrument parameters fitted to measured data (numpy/scipy, no rclpy).

:mod:`.calibration`: the cable-pulley friction (or another schema parameter of the
model) from a load-cell grasp, with standard errors, and the calibrated instrument
YAML. :mod:`.procedures`: what a controller runs on the instrument for it: the grasp's
current staircase and its recording, and the tare of the load cell and current sensor.
Used by ``grip-force calibrate``, the demo's instrument comparison and the controller
node's ``~/calibrate`` and ``~/tare``; it depends on the model and the parameter schema
only (nothing below imports it).
"""
from grip_force_ros.identify.calibration import (FITTABLE, CalibrationError, CalibrationResult,
                                                 Plateaus, calibrated_yaml,
                                                 fit_instrument, steady_plateaus)
from grip_force_ros.identify.procedures import (CALIBRATION_FIRST_RAMP, CALIBRATION_HOLD,
                                                CALIBRATION_RAMP, CALIBRATION_SHARES,
                                                CurrentStaircase, GraspRecording, SensorZero,
                                                calibration_current)

__all__ = ['FITTABLE', 'CalibrationError', 'CalibrationResult', 'Plateaus', 'calibrated_yaml',
           'fit_instrument', 'steady_plateaus', 'CALIBRATION_SHARES',
           'CALIBRATION_HOLD', 'CALIBRATION_FIRST_RAMP', 'CALIBRATION_RAMP', 'CurrentStaircase',
           'GraspRecording', 'SensorZero', 'calibration_current']
