r"""`grip-force calibrate`: fit an instrument's parameters from a load-cell grasp log.

    grip-force calibrate --config X.yaml --log CALIB.mcap|CALIB_DIR|CALIB.csv \
        --out X_calibrated.yaml

The command is :mod:`grip_force_ros.identify.command` (``python -m`` of it is the same
fit), which the controller's ``~/calibrate`` runs too.
"""
from grip_force_ros.identify.command import HELP, add_arguments, run  # noqa: F401 (the subcommand)
