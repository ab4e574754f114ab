"""Identification: instrument parameters fitted to measured data (numpy/scipy, no rclpy).

:mod:`.calibration`: the cable-pulley friction (or another schema parameter of the
model) from a load-cell grasp, with standard errors, and the calibrated instrument
YAML. Used by ``grip-force calibrate`` and the demo's instrument comparison; it
depends on the model and the parameter schema only (nothing below imports it).
"""
from grip_force_ros.identify.calibration import (FITTABLE, CalibrationError, CalibrationResult,
                                                 Plateaus, calibrated_yaml, fit_instrument,
                                                 steady_plateaus)

__all__ = ['FITTABLE', 'CalibrationError', 'CalibrationResult', 'Plateaus', 'calibrated_yaml',
           'fit_instrument', 'steady_plateaus']
