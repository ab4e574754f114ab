"""Constants of the MRDLab da Vinci tool test rig and the conventions we map it to.

The rig (O'Neill, Stephens, Kowalewski, IEEE RA-L 3(4) 2018; data set
MRDLab/mis-tool-characterization, ODbL/DbCL) drives the input disk of a da Vinci
instrument with a geared Maxon motor (the *back end*) and resists the jaw with a
second motor (the *front end*) through a Futek torque sensor.

Unit factors come from the upstream README. Sign and zero conventions are ours,
found from the data (docs/real_data.md, "Sign and zero conventions"); they map
the rig onto docs/ARCHITECTURE.md: positive current and positive motor angle
close the jaw, jaw angle 0 = closed and positive = open, jaw torque > 0 when the
jaw squeezes (closing torque held against the resisting front-end motor).
"""
from __future__ import annotations

import math

TWO_PI = 2.0 * math.pi

#: Column order of a rig TXT file (upstream README), 0-based.
RAW_COLUMNS = (
    'time',                 # s (the upstream header says ms; the values are s at 1 kHz)
    'disk_counts',          # back-end (input disk) CUI encoder, counts
    'disk_torque_counts',   # back-end Futek torque sensor, counts
    'measured_current',     # back-end motor measured current, A (Maxon controller)
    'jaw_counts',           # front-end (jaw) Maxon encoder, counts
    'jaw_torque_counts',    # front-end Futek torque sensor, counts
    'load_command',         # front-end motor command, A (constant in a run)
    'backend_command',      # back-end motor command, -1..1 (analog out)
    'motor_counts',         # back-end Maxon motor encoder, counts (before the 35:1 gearbox)
    'trajectory_target',    # trajectory target of the input disk (rad, see below)
)

#: Input-disk encoder resolution (upstream README), counts per revolution.
DISK_COUNTS_PER_REV = 8192.0
#: Motor encoder resolution at the gearbox output: 4196 counts/rev times the 35:1 gearbox.
MOTOR_COUNTS_PER_OUTPUT_REV = 4196.0 * 35.0
#: Jaw (front-end) encoder resolution, counts per revolution.
JAW_COUNTS_PER_REV = 4000.0
#: Futek torque sensors (both ends), N*m per count.
TORQUE_NM_PER_COUNT = 0.000039811

#: Sign that makes each raw column "closing positive" (found from the data):
#: the back end pushes the disk towards *negative* disk counts to close (the
#: mean current rises with the resisting load and is positive while the disk
#: counts fall against the load), the motor encoder counts *up* when the disk
#: counts down, and the jaw encoder counts *up* when closing.
DISK_SIGN = -1.0
MOTOR_SIGN = +1.0
JAW_CLOSING_SIGN = +1.0
#: The jaw torque sensor reads negative counts while it resists closing.
JAW_TORQUE_SIGN = -1.0
#: The input-disk torque sensor reads positive counts while the back end drives closing.
DISK_TORQUE_SIGN = +1.0
#: The back-end command is opposite in sign to the measured current.
BACKEND_COMMAND_SIGN = -1.0

#: Jaw encoder count taken as jaw angle 0. The jaw encoder is not re-zeroed
#: between runs (its start count rises with the load, 851..885, as the cables
#: stretch); 885 is the most closed count in the 20 runs of Tool_4_Maryland_L_2,
#: so jaw_angle >= 0 there. The mechanically closed jaw is not reached on the rig.
JAW_REFERENCE_COUNTS = 885.0

#: Current (A) for a back-end command of 1, fitted on the data (measured current
#: against the command over all 20 runs: slope -2.05 +- 0.01 A per unit). Only
#: used to express the command in A; the estimator does not need it.
BACKEND_COMMAND_FULL_SCALE = 2.05

#: Sample period of the rig (s).
SAMPLE_PERIOD = 0.001
#: Start-up of a run (s), reported apart and left out of per-run statistics: a 0.1 Hz
#: stroke starts from rest, and the friction direction is known only after ~0.75 s.
STARTUP_S = 1.0

#: Run file name XY.TXT: X = frequency step, Y = resisting torque step. The
#: headers give 0.1..0.5 Hz and 10..40 % (checked against the data: the period
#: of the disk motion and the mean jaw torque).
FREQUENCY_STEP_HZ = 0.1
FREQUENCY_FIRST_HZ = 0.1
TORQUE_STEP_PERCENT = 10.0
TORQUE_FIRST_PERCENT = 10.0

#: Where the shared data lives, relative to the repository root's parent.
DATA_ROOT = ('shared', 'data', 'mis-tool-characterization')
#: The folder of the one-folder analysis.
DEFAULT_FOLDER = 'Tool_4_Maryland_L_2'
DEFAULT_DATA_DIR = DATA_ROOT + (DEFAULT_FOLDER,)

#: Disk angle (rad) added to a right-spindle run after its columns are negated, so
#: that its stroke lies where a left-spindle stroke does: upstream's own alignment
#: for the right jaw (compileData.m: ``-counts*CountToRadCUI + (2.172+0.4131)``; our
#: disk angle is minus theirs).
RIGHT_SPINDLE_DISK_OFFSET = -(2.172 + 0.4131)

#: A trajectory column whose magnitude exceeds this holds disk-encoder counts (later
#: folders, 0..1365.33 counts for 60 degrees), not rad (Tool_4_Maryland_L_2, 0..1.05).
TRAJECTORY_COUNTS_ABOVE = 2.0 * math.pi

#: Attribution required by the ODbL/DbCL licence of the data.
ATTRIBUTION = (
    "Data: MRDLab/mis-tool-characterization (Medical Robotics and Devices Lab, University of "
    "Minnesota), folder Tool_4_Maryland_L_2, commit 03658b2ccefef9adceebc38dd4a17bd6e190cd2e. "
    "Database licence ODbL 1.0, contents DbCL 1.0. Paper: J. J. O'Neill, T. K. Stephens, "
    "T. M. Kowalewski, Evaluation of Torque Measurement Surrogates as Applied to Grip Torque and "
    "Jaw Angle Estimation of Robotic Surgical Tools, IEEE RA-L 3(4):3027-3034, 2018, "
    "doi:10.1109/LRA.2018.2849862. Converted by grip_force_ros (grip-force import-rig): units, "
    "signs and zeros changed as documented in docs/real_data.md.")

#: Published jaw torque RMSE of the paper's neural networks (N*m).
PUBLISHED_RMSE_NM = 4.42e-3
