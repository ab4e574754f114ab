"""The dVRK's jaw effort <-> motor current conversion, friction-free, as the dVRK does it.

The dVRK (sawIntuitiveResearchKit) turns a jaw effort (``jaw/servo_jf``, N*m at the jaw,
positive opens) into motor currents in two steps, and its ``jaw/measured_js`` effort back
from the measured currents the same way:

1. **Tool coupling** (the tool file, ``coupling.ActuatorToJointPosition`` ``C``; rows roll,
   pitch, yaw, jaw; columns the PSM's actuators 4..7): actuator torques
   ``tau_a = C^T tau_j``. A jaw effort alone drives the two jaw disks (actuators 6 and 7),
   ``tau_6 = -c tau_jaw`` and ``tau_7 = +c tau_jaw``, with ``c`` the jaw row's last entry
   (``dvrk_jaw_coupling``; 0.915964 for the Maryland bipolar forceps 400172, 1.2177 for the
   large needle driver 400006). Each jaw blade gets ``tau_jaw``: the jaw angle is the
   difference of the two blades' angles.
2. **Motor constants** (the PSM's IO configuration, sawRobotIO1394 ``NmToAmps``): motor
   current ``I = NmToAmps * tau_a`` per actuator, ``NmToAmps = 1 / (K_t * gear)`` =
   1 / (0.0438 N*m/A * 11.71) = 1.949705 A/(N*m) for the Classic PSM's actuators 4..7
   (``dvrk_actuator_nm_to_amps``; jhu-dvrk/sawIntuitiveResearchKit @ 95a7e92,
   ``share/jhu-dVRK/sawRobotIO1394-PSM1-28007.xml``, actuators 3..6: ``NmToAmps
   Scale="1.949705"``, ``MaxCurrent 0.670 A``).

So one jaw motor carries ``|I| = c * NmToAmps * |tau_jaw|`` (1.7859 A per N*m for the
Maryland forceps), and this package's current (one drum motor, positive closes the jaw,
docs/ARCHITECTURE.md) is that motor's current with the closing sign:

    current = -c * NmToAmps * tau_jaw        tau_jaw = -current / (c * NmToAmps)

What the conversion leaves out, on a real dVRK: friction in the instrument's cables and the
PSM's sterile adapter (the dVRK's conversion is friction-free, so its ``jaw/measured_js``
effort is the motor side's torque, not the torque at the blades), and the drive's own
current loop (a commanded effort becomes a current setpoint; the measured current lags and
has an offset). The model's feedforward accounts for the cable friction: it computes the
*current* the grip force needs through the lossy pulley chain (the paper's inverse), and
only then converts that current to the friction-free effort the dVRK turns back into the
same current. The current loop and the adapter friction are not modelled (docs/dvrk.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class JawEffortConversion:
    """The dVRK's friction-free conversion between jaw effort and jaw motor current.

    Parameters
    ----------
    jaw_coupling : float
        ``c``: the jaw row's actuator-7 entry of the tool's ``ActuatorToJointPosition``
        (rad of jaw per rad of the jaw disk), > 0.
    nm_to_amps : float
        The PSM's ``NmToAmps`` of the jaw actuators (A/(N*m)), > 0.
    """

    jaw_coupling: float
    nm_to_amps: float

    def __post_init__(self):
        if not (self.jaw_coupling > 0.0 and self.nm_to_amps > 0.0):
            raise ValueError(f'jaw_coupling {self.jaw_coupling!r} and nm_to_amps '
                             f'{self.nm_to_amps!r} must be > 0')

    @classmethod
    def from_params(cls, params) -> 'JawEffortConversion':
        """Build it from a ParamSet (``dvrk_jaw_coupling``, ``dvrk_actuator_nm_to_amps``)."""
        return cls(params.dvrk_jaw_coupling, params.dvrk_actuator_nm_to_amps)

    @property
    def amps_per_newton_metre(self) -> float:
        """Jaw motor current per jaw effort, ``c * NmToAmps`` (A/(N*m))."""
        return self.jaw_coupling * self.nm_to_amps

    def actuator_torques(self, jaw_effort: float) -> tuple[float, float]:
        """Return the torques (N*m) of the jaw actuators 6 and 7 for ``jaw_effort`` (N*m): ``C^T``."""
        return (-self.jaw_coupling * jaw_effort, self.jaw_coupling * jaw_effort)

    def current(self, jaw_effort: float) -> float:
        """Return this package's motor current, A (+ closes), for a dVRK jaw effort, N*m (+ opens)."""
        return -self.amps_per_newton_metre * jaw_effort

    def effort(self, current: float) -> float:
        """Return the dVRK jaw effort, N*m (+ opens), whose conversion yields ``current`` in A."""
        return -current / self.amps_per_newton_metre

    def current_limit(self, effort_limit: float) -> float:
        """Return the largest current (A) whose effort stays within ``effort_limit`` (N*m, ftmax)."""
        return self.amps_per_newton_metre * effort_limit


def command_current_limit(params) -> float:
    """Return the controller's current limit (A) for a ParamSet.

    ``max_current``; in the ``dvrk`` interface at most the current of the tool's jaw effort
    limit ``dvrk_jaw_effort_max`` (the sim refuses a larger ``jaw/servo_jf``) and the drive's
    current limit ``dvrk_actuator_max_current``, so the limiter, and with it the
    anti-windup, knows the limit that really acts (in both ``dvrk_command`` paths).
    """
    limit = params.max_current
    if params.interface == 'dvrk':
        limit = min(limit, params.dvrk_actuator_max_current,
                    JawEffortConversion.from_params(params).current_limit(
                        params.dvrk_jaw_effort_max))
    return limit


@dataclass(frozen=True)
class JawPositionLoop:
    """The dVRK's jaw position loop seen at the jaw: the tool-disc PIDs through the coupling.

    The dVRK's PID (sawControllersPID, ``share/pid/sawControllersPID-PSM.json``) runs on the
    actuator (disc) positions at 1.5 kHz: a ``jaw/servo_jp`` setpoint ``q_sp`` becomes disc
    setpoints through ``C^-1`` (``JointToActuatorPosition``), and each disc gets the torque
    ``p e_a - d w_a`` (p 6.0 N*m/rad, d 0.09 N*m*s/rad, no output limit). With the tool's jaw
    row ``(0, 0, -c, c)`` and a yaw row whose two jaw-disc entries are equal (every tool that
    imports), a jaw error ``e`` alone moves the two jaw discs by ``-e/(2c)`` and ``+e/(2c)``
    (the yaw unchanged); their torques ``-+p e/(2c)`` are the jaw effort ``E`` with
    ``C^T (0, 0, 0, E)`` = ``(0, 0, -c E, c E)``, so ``E = p e / (2 c^2)``: the jaw
    stiffness is ``K = p / (2 c^2)`` and the damping ``D = d / (2 c^2)`` (docs/dvrk.md;
    the full ``C^-T diag(p) C^-1`` of the Maryland forceps has 3.5757 N*m/rad at the jaw and
    no jaw cross term). The drive limits each disc motor's current to ``max_current``.

    Parameters
    ----------
    conversion : JawEffortConversion
        The tool coupling ``c`` and the actuators' ``NmToAmps``.
    disc_p_gain : float
        Proportional gain of the jaw discs' PID (N*m/rad of disc), >= 0.
    disc_d_gain : float
        Derivative gain of the jaw discs' PID (N*m*s/rad of disc), >= 0.
    max_current : float
        The drive's current limit of one disc motor (A), > 0.
    """

    conversion: JawEffortConversion
    disc_p_gain: float
    disc_d_gain: float
    max_current: float

    def __post_init__(self):
        if not (self.disc_p_gain > 0.0 and self.disc_d_gain >= 0.0 and self.max_current > 0.0):
            raise ValueError(f'disc_p_gain {self.disc_p_gain!r} must be > 0, disc_d_gain '
                             f'{self.disc_d_gain!r} >= 0, max_current {self.max_current!r} > 0')

    @classmethod
    def from_params(cls, params) -> 'JawPositionLoop':
        """Build it from a ParamSet (``dvrk_disc_p_gain``, ``dvrk_disc_d_gain``, ...)."""
        return cls(JawEffortConversion.from_params(params), params.dvrk_disc_p_gain,
                   params.dvrk_disc_d_gain, params.dvrk_actuator_max_current)

    @property
    def stiffness(self) -> float:
        """Jaw effort per rad of jaw position error, ``p / (2 c^2)`` (N*m/rad)."""
        c = self.conversion.jaw_coupling
        return self.disc_p_gain / (2.0 * c * c)

    @property
    def damping(self) -> float:
        """Jaw effort per rad/s of jaw velocity, ``d / (2 c^2)`` (N*m*s/rad)."""
        c = self.conversion.jaw_coupling
        return self.disc_d_gain / (2.0 * c * c)

    @property
    def effort_limit(self) -> float:
        """The jaw effort at the drive's current limit (N*m): ``max_current / (c NmToAmps)``."""
        return self.max_current / self.conversion.amps_per_newton_metre

    def effort(self, setpoint: float, angle: float, velocity: float) -> float:
        """Return the PID's jaw torque command, in N*m (+ opens), for a setpoint and the jaw's state.

        ``K (setpoint - angle) - D velocity``; the setpoint's own velocity is 0 (a
        ``jaw/servo_jp`` carries a position only). Angles in rad, velocity in rad/s.
        """
        return self.stiffness * (setpoint - angle) - self.damping * velocity

    def current(self, setpoint: float, angle: float, velocity: float) -> float:
        """Return the motor current the loop drives, in A (+ closes), drive-limited."""
        current = self.conversion.current(self.effort(setpoint, angle, velocity))
        limit = self.max_current
        return limit if current > limit else (-limit if current < -limit else current)

    def setpoint(self, effort: float, angle: float, lowest: float, highest: float) -> float:
        """Return the ``jaw/servo_jp`` setpoint, in rad, whose PID effort at rest is ``effort``.

        ``angle + effort / K``, bounded to ``[lowest, highest]`` (the tool's ``jaw.qmin`` and
        ``jaw.qmax``; the dVRK clips there too). At ``effort`` 0 the setpoint is the
        measured ``angle``: the loop holds the jaw where it is, no jump.

        Parameters
        ----------
        effort : float
            The jaw effort wanted (N*m, + opens); the caller keeps it within its limits.
        angle : float
            The measured jaw angle (rad).
        lowest, highest : float
            The setpoint's bounds (rad).
        """
        q = angle + effort / self.stiffness
        return lowest if q < lowest else (highest if q > highest else q)

    def command_setpoint(self, mode: str, effort: float, angle: float, target_angle: float,
                         lowest: float, highest: float) -> float:
        """Return the controller's ``jaw/servo_jp`` setpoint (rad) for one step.

        In free motion (``mode`` 'free') the jaw's target angle itself: the PSM's loop tracks
        it, as teleoperation's own ``jaw/servo_jp`` does (a current turned into a setpoint
        would be undone by the loop within the state period while the jaw moves). In grip and
        in the safe state the setpoint whose effort at rest is ``effort``
        (:meth:`setpoint`): the grip force loop's effort, and a safe ramp to 0 N*m ends at the
        measured angle. Bounded to ``[lowest, highest]``.

        Parameters
        ----------
        mode : str
            The controller's mode: 'free', 'grip' or 'safe'.
        effort : float
            The step's jaw effort (N*m, + opens), within the caller's limits.
        angle, target_angle : float
            The measured and the target jaw angle (rad).
        lowest, highest : float
            The setpoint's bounds (rad).
        """
        if mode == 'free' and target_angle == target_angle:
            q = target_angle
            return lowest if q < lowest else (highest if q > highest else q)
        return self.setpoint(effort, angle, lowest, highest)


#: Time constant of the low-pass on the measured jaw angle that the controller's grip setpoint
#: starts from (s): the setpoint ``angle + E / K`` passes the jaw sensor's noise into the jaw
#: effort times ``K``; over the grip's static jaw 20 ms takes most of it out.
ORIGIN_TIME_CONSTANT = 0.02


class SetpointOrigin:
    """The measured jaw angle, low-passed: where the controller's grip setpoint starts from.

    Parameters
    ----------
    time_constant : float
        First-order time constant (s), > 0.
    """

    def __init__(self, time_constant: float = ORIGIN_TIME_CONSTANT):
        if not time_constant > 0.0:
            raise ValueError(f'time_constant must be > 0 s, got {time_constant!r}')
        self.time_constant = float(time_constant)
        self.angle = math.nan         # rad, the filtered angle (nan: no sample yet)
        self._time = math.nan         # s, the time of the last sample

    def update(self, angle: float, now: float) -> float:
        """Take the jaw angle ``angle`` (rad) measured at ``now`` (s); return the filtered angle."""
        if self.angle != self.angle or not now > self._time:
            self.angle = float(angle) if self.angle != self.angle else self.angle
        else:
            share = 1.0 - math.exp(-(now - self._time) / self.time_constant)
            self.angle += share * (angle - self.angle)
        self._time = now
        return self.angle
