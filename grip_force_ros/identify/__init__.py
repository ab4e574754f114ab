"""Identification: instrument parameters fitted to measured data (numpy/scipy, no rclpy).

:mod:`.calibration`: one fitter of schema parameters (:func:`fit_parameters`, bounded,
robust, standard errors from the covariance or a moving-block bootstrap); with it the
cable-pulley friction (or another schema parameter of the model) from a load-cell grasp
and the calibrated instrument YAML (``grip-force calibrate``, the demo's instrument
comparison), and the diagnosis' re-identification of an instrument's parameters on whole
logs. :mod:`.procedures`: what a controller runs on the instrument for it: the grasp's
current staircase and its recording, and the tare of the load cell and current sensor
(the demo's instrument comparison, the controller node's ``~/calibrate`` and ``~/tare``).
:mod:`.command`: the calibration fit as a command (``python -m``; ``grip-force calibrate``,
and the child process of the controller's ``~/calibrate``), which reads the log with
:mod:`grip_force_ros.logs`. The rest depends on the model and the parameter schema only.
"""
from grip_force_ros.identify.calibration import (FITTABLE, CalibrationError, CalibrationResult,
                                                 ParameterFit, Plateaus, block_bootstrap_std,
                                                 calibrated_yaml, fit_instrument, fit_parameters,
                                                 steady_plateaus)
from grip_force_ros.identify.procedures import (CALIBRATION_FIRST_RAMP, CALIBRATION_HOLD,
                                                CALIBRATION_RAMP, CALIBRATION_SHARES,
                                                CurrentStaircase, GraspRecording, SensorZero,
                                                calibration_current)

__all__ = ['FITTABLE', 'CalibrationError', 'CalibrationResult', 'ParameterFit', 'Plateaus',
           'block_bootstrap_std', 'calibrated_yaml', 'fit_instrument', 'fit_parameters',
           'steady_plateaus', 'CALIBRATION_SHARES', 'CALIBRATION_HOLD', 'CALIBRATION_FIRST_RAMP',
           'CALIBRATION_RAMP', 'CurrentStaircase', 'GraspRecording', 'SensorZero',
           'calibration_current']
