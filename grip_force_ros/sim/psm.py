"""The simulated dVRK PSM's control modes (ROS-free): what a command does to the arm and the jaw.

The dVRK keeps one control space and mode for the whole arm
(``mtsIntuitiveResearchKitArm::SetControlSpaceAndMode``; ../shared/vendor/README.md, "The
dVRK PSM's control modes"), and :class:`PsmControl` keeps it the same way:

- ``jaw/servo_jf`` -> Cartesian space, **effort** mode for the whole arm: the arm's wrench
  goal is zeroed, so its joints are commanded zero effort and are no longer held. Here they
  drift toward a sag pose (:data:`SAG`, a spring-and-gravity stand-in) with
  :data:`DRIFT_TIME_CONSTANT`; only the jaw gets the effort (the held current).
- ``servo_cp`` -> Cartesian position mode, ``servo_jp`` -> joint position mode, and
  ``jaw/servo_jp`` -> position mode in the space the arm is in (Cartesian stays Cartesian,
  anything else becomes joint space): the arm's joints are held (back to their goal with
  :data:`HOLD_TIME_CONSTANT`), and leaving effort mode sets the jaw effort to 0.
- In position mode the jaw follows its setpoint through the disc PIDs
  (:class:`grip_force_ros.model.dvrk_jaw.JawPositionLoop`: the vendored gains through the
  tool coupling, the drive's current limit), recomputed at :data:`PID_RATE` (the dVRK's
  1.5 kHz) and held between, into the same plant (:class:`~grip_force_ros.sim.plant.InstrumentSim`).
  Its proportional part acts on the jaw angle the sim reports on ``jaw/measured_js`` (a
  dVRK computes that angle from the disc encoders; the sim's is the jaw's own, so the
  controller's setpoint and the loop agree on it), its derivative on the drum's rate
  (collocated with the motor), with the vendored ``d`` capped at :data:`DERIVATIVE_CAP`
  ``J / T`` of the plant's drum: the instrument files' drum is lighter than a PSM disc's
  reflected rotor, and the vendored gain sampled at 1.5 kHz would make it ring.

The sim has no kinematics: ``servo_cp`` holds the arm at its reference joints (the pose
it was built with: a stand-in that streams one pose sees the arm hold it), ``servo_jp`` at
the joints it carries, ``jaw/servo_jp`` out of effort mode where the arm is. Entering
position mode holds the jaw where it is (its setpoint the measured angle: the jaw effort
is 0, so a jaw that was squeezing lets go until a new setpoint comes). The wrist pitch and
the jaw are the plant's; the other joints are this module's. Every change of space or mode
is counted (:attr:`PsmControl.mode_changes`) and, the first time the arm goes limp, said
(:meth:`PsmControl.take_notice`).
"""
from __future__ import annotations

import math

from grip_force_ros.model.dvrk_jaw import JawPositionLoop

#: The dVRK's control spaces and modes (mtsIntuitiveResearchKitControlTypes).
UNDEFINED_SPACE, JOINT_SPACE, CARTESIAN_SPACE = 'UNDEFINED_SPACE', 'JOINT_SPACE', 'CARTESIAN_SPACE'
UNDEFINED_MODE, POSITION_MODE, EFFORT_MODE = 'UNDEFINED_MODE', 'POSITION_MODE', 'EFFORT_MODE'
#: The rate of the dVRK's arm loop and its PIDs (Hz).
PID_RATE = 1500.0
#: The arm joints this module moves (the PSM's first four; wrist pitch and jaw: the plant).
ARM_JOINTS = ('outer_yaw', 'outer_pitch', 'outer_insertion', 'roll')
#: Where the unheld arm sags to, relative to its goal (rad, rad, m, rad): gravity pulls the
#: outer pitch down and the instrument out of the cannula, a stand-in for the real arm's fall.
SAG = (0.0, -0.3, -0.05, 0.0)
#: Time constant of the unheld arm's drift toward the sag pose (s).
DRIFT_TIME_CONSTANT = 1.0
#: Time constant of the held arm's return to its goal (s): the arm PIDs' settling.
HOLD_TIME_CONSTANT = 0.02
#: Largest ``d T / J`` of the jaw loop's derivative on the plant's drum (-), T the PID period,
#: J the drum's inertia, d the derivative gain at the drum: a sampled derivative rings beyond
#: 2 and is unstable; the plant's drum (the instrument file's motor) is lighter than a PSM
#: disc's reflected rotor, so the vendored d gain is capped there (:meth:`PsmControl.damping_on`).
DERIVATIVE_CAP = 0.5


class PsmControl:
    """The arm's control space and mode, its four arm joints, the jaw's setpoint and PID.

    Parameters
    ----------
    loop : JawPositionLoop
        The jaw position loop (disc PIDs through the coupling, drive current limit).
    jaw_min, jaw_max : float
        The jaw setpoint's bounds (rad; the tool's ``jaw.qmin``, ``jaw.qmax``): the dVRK clips
        a ``jaw/servo_jp`` there.
    goal : sequence of float, optional
        The arm joints' goal (:data:`ARM_JOINTS`; rad, rad, m, rad); zeros by default.
    """

    def __init__(self, loop: JawPositionLoop, jaw_min: float, jaw_max: float, goal=None):
        self.loop = loop
        self.jaw_min, self.jaw_max = float(jaw_min), float(jaw_max)
        self.space, self.mode = UNDEFINED_SPACE, UNDEFINED_MODE
        self.reference = tuple(float(q) for q in (goal if goal is not None
                                                  else (0.0,) * len(ARM_JOINTS)))
        self.goal = list(self.reference)       # where the arm is held in position mode
        self.joints = list(self.goal)          # the arm joints now (rad, rad, m, rad)
        # the jaw's setpoint (rad); nan: the loop is off (0 A); None: hold the jaw where it
        # is at the next step (position mode entered without a jaw setpoint)
        self.jaw_setpoint: float | None = math.nan
        self.mode_changes = 0                  # changes of space or mode since start
        self.effort_entries = 0                # of them, into effort mode
        self.largest_drift = 0.0               # largest |joint - reference| seen (rad or m)
        self._notice: str | None = None        # said once: the arm went limp
        self._said_limp = False
        self._pid_due = 0.0                    # s until the PID's next update
        self._damping = None                   # N*m*s/rad at the jaw, as applied (capped)
        self._pid_current = 0.0                # A, the PID's output held between updates

    # ------------------------------------------------------------------ modes
    @property
    def effort_mode(self) -> bool:
        """Tell whether the arm is in effort mode (its joints not held; the jaw takes efforts)."""
        return self.mode == EFFORT_MODE

    def _set(self, space: str, mode: str) -> bool:
        """Switch to ``space`` and ``mode``; return whether anything changed."""
        if (space, mode) == (self.space, self.mode):
            return False
        self.space, self.mode = space, mode
        self.mode_changes += 1
        if mode == EFFORT_MODE:
            self.effort_entries += 1
            if not self._said_limp:
                self._said_limp = True
                self._notice = ('jaw/servo_jf puts the whole arm in Cartesian effort mode: its '
                                'joints are commanded zero effort and no longer held (the sim '
                                'lets them drift); a position command holds them again and '
                                'sets the jaw effort to 0')
        return True

    def homed(self) -> None:
        """Take the end of homing: joint position mode, holding its goal, the jaw where it is."""
        self._set(JOINT_SPACE, POSITION_MODE)
        self.jaw_setpoint = None
        self.joints = list(self.goal)          # homing brings the arm to its pose
        self.largest_drift = 0.0

    def jaw_effort(self) -> None:
        """Take a ``jaw/servo_jf``: the whole arm goes to Cartesian effort mode."""
        self._set(CARTESIAN_SPACE, EFFORT_MODE)
        self.jaw_setpoint = math.nan

    def jaw_position(self, setpoint: float) -> None:
        """Take a ``jaw/servo_jp`` to ``setpoint`` (rad): position mode in the arm's space, clipped."""
        space = CARTESIAN_SPACE if self.space == CARTESIAN_SPACE else JOINT_SPACE
        if self._set(space, POSITION_MODE):
            self.goal = list(self.joints)      # the other joints: held where they are
        q = float(setpoint)
        self.jaw_setpoint = self.jaw_min if q < self.jaw_min else (
            self.jaw_max if q > self.jaw_max else q)

    def arm_cartesian_position(self) -> None:
        """Take a ``servo_cp``: Cartesian position mode; the arm held at its reference pose."""
        self._leave_effort()
        self._set(CARTESIAN_SPACE, POSITION_MODE)
        self.goal = list(self.reference)

    def arm_joint_position(self, joints) -> None:
        """Take a ``servo_jp`` to ``joints`` (:data:`ARM_JOINTS` first; a 7th value is the jaw's)."""
        self._leave_effort()
        self._set(JOINT_SPACE, POSITION_MODE)
        values = [float(q) for q in joints]
        for i in range(min(len(values), len(ARM_JOINTS))):
            self.goal[i] = values[i]
        if len(values) >= 7:
            self.jaw_position(values[6])

    def _leave_effort(self) -> None:
        if self.mode != POSITION_MODE:
            self.jaw_setpoint = None           # the jaw effort is 0: the jaw held where it is

    def cut(self) -> None:
        """Take the drive's command timeout: the jaw's loop stops (0 A) until the next jaw command."""
        self.jaw_setpoint = math.nan
        self._pid_current = 0.0

    def take_notice(self) -> str | None:
        """Return what the sim should say once (the arm went limp), then None."""
        notice, self._notice = self._notice, None
        return notice

    # ------------------------------------------------------------------ time
    def advance(self, plant, current: float, dt: float, powered: bool = True) -> None:
        """Advance the plant and the arm joints by ``dt`` (s).

        Parameters
        ----------
        plant : InstrumentSim
            The instrument (jaw, cable, drum) the jaw's motor drives.
        current : float
            The held jaw current (A, + closes): used in effort mode; in position mode the PID's.
        dt : float
            Step (s), > 0.
        powered : bool
            The arm is ENABLED: false cuts every current, and nothing is held.
        """
        held = powered and self.mode == POSITION_MODE
        self._move_arm(dt, held)
        if held and self.jaw_setpoint is None:
            self.jaw_setpoint = plant.jaw_angle_now()
        if not held or self.jaw_setpoint != self.jaw_setpoint:
            plant.step(current if powered and self.mode == EFFORT_MODE else 0.0, dt)
            self._pid_due = 0.0
            return
        period = 1.0 / PID_RATE
        loop, setpoint = self.loop, self.jaw_setpoint
        stiffness = loop.stiffness
        damping = self._damping if self._damping is not None else self.damping_on(plant)
        amps, limit = loop.conversion.amps_per_newton_metre, loop.max_current
        remaining = dt
        while remaining > 1e-12:
            if self._pid_due <= 1e-12:
                velocity = plant.jaw_state()[1]          # the drum's rate: collocated damping
                angle = plant.jaw_angle_now()             # the jaw angle jaw/measured_js reports
                current = -amps * (stiffness * (setpoint - angle) - damping * velocity)
                self._pid_current = (limit if current > limit
                                     else (-limit if current < -limit else current))
                self._pid_due = period
            h = self._pid_due if self._pid_due < remaining else remaining
            plant.step(self._pid_current, h)
            remaining -= h
            self._pid_due -= h

    def damping_on(self, plant) -> float:
        """Return the jaw damping (N*m*s/rad) the sim's loop applies on ``plant``.

        The vendored one, capped so that ``d T / J`` at the drum stays within
        :data:`DERIVATIVE_CAP`.

        The PID's jaw effort ``E`` drives the drum with ``gear_k c NmToAmps E`` N*m, and a jaw
        rate ``w`` is a drum rate ``w r_n / r0``: the derivative at the drum is
        ``D c NmToAmps gear_k (r0/r_n)^2``.
        """
        inertia, gear_k, ratio = plant.drum_constants()
        per_damping = self.loop.conversion.amps_per_newton_metre * gear_k * ratio * ratio
        cap = DERIVATIVE_CAP * inertia * PID_RATE / per_damping
        self._damping = min(self.loop.damping, cap)
        return self._damping

    @property
    def pid_current(self) -> float:
        """The jaw PID's last output (A, + closes; 0 when the loop is off)."""
        q = self.jaw_setpoint
        return self._pid_current if q is not None and q == q else 0.0

    def _move_arm(self, dt: float, held: bool) -> None:
        tau = HOLD_TIME_CONSTANT if held else DRIFT_TIME_CONSTANT
        share = 1.0 - math.exp(-dt / tau)
        worst = self.largest_drift
        for i, goal in enumerate(self.goal):
            target = goal if held else goal + SAG[i]
            q = self.joints[i] + share * (target - self.joints[i])
            self.joints[i] = q
            off = abs(q - self.reference[i])
            if off > worst:
                worst = off
        self.largest_drift = worst

    def drift(self) -> float:
        """Return the arm joints' largest distance from their reference now (rad or m)."""
        return max(abs(q - g) for q, g in zip(self.joints, self.reference))

    def status(self) -> dict[str, str]:
        """Key/value strings for /diagnostics."""
        return {'arm_control_space': self.space, 'arm_control_mode': self.mode,
                'arm_mode_changes': str(self.mode_changes),
                'arm_effort_mode_entries': str(self.effort_entries),
                'arm_held': str(self.mode == POSITION_MODE).lower(),
                'arm_drift_max': f'{self.largest_drift:.6f}',
                'jaw_setpoint_rad': (f'{self.jaw_setpoint:.5f}' if self.jaw_setpoint is not None
                                     and self.jaw_setpoint == self.jaw_setpoint else 'none')}
