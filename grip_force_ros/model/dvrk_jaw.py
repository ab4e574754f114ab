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
    limit ``dvrk_jaw_effort_max`` (the dVRK refuses a larger ``jaw/servo_jf``), so the
    limiter, and with it the anti-windup, knows the limit that really acts.
    """
    limit = params.max_current
    if params.interface == 'dvrk':
        limit = min(limit, JawEffortConversion.from_params(params).current_limit(
            params.dvrk_jaw_effort_max))
    return limit
