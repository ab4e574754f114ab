"""The MRDLab da Vinci tool rig: import, conventions, and a motor-side jaw torque estimator.

Real instrument data (O'Neill et al., IEEE RA-L 2018; MRDLab/mis-tool-characterization,
ODbL/DbCL): a Maryland forceps jaw driven through its cables from the input disk
while a second motor resists it at the jaw. No rclpy here.

>>> from grip_force_ros.lab.rig import read_runs, default_data_dir    # doctest: +SKIP
>>> runs = read_runs(default_data_dir())                          # doctest: +SKIP

Estimator: :mod:`grip_force_ros.lab.rig.estimator` (batch, fit/predict),
:mod:`grip_force_ros.lab.rig.transfer` (other folders: signs, current tare, calibration run),
:mod:`grip_force_ros.lab.rig.streaming` (the same observer one sample at a time),
analysis and report: :mod:`grip_force_ros.lab.rig.analysis`, :mod:`grip_force_ros.lab.rig.report`.
"""
from grip_force_ros.lab.rig.reader import (EXTRA_COLUMNS, RigDataError, RigRun, data_root,
                                           default_data_dir, read_run, read_runs, run_files, spindle_of,
                                           to_contract_log)

__all__ = ['EXTRA_COLUMNS', 'RigDataError', 'RigRun', 'data_root', 'default_data_dir', 'read_run',
           'read_runs', 'run_files', 'spindle_of', 'to_contract_log']
