"""The drive side of the simulated instrument (ROS-free): command timeout, dVRK arm state.

:class:`CommandTimeout`: a real drive cuts the motor current when its master stops sending
commands (the dVRK's IO watchdog: 30 ms). With no command for ``timeout`` seconds the
current command becomes 0 A; the timeout is reported once per expiry and re-armed by the
next command.

:class:`ArmState`: the operating state of a dVRK arm as the sim plays it in the ``dvrk``
profile (crtk: DISABLED, ENABLED, PAUSED, FAULT; is_homed, is_busy). It starts DISABLED and
not homed, as a real arm at power-up; ``enable`` powers it, ``home`` keeps it busy for
``homing_time`` and then reports it homed; ``disable`` cuts the power (the homing is kept,
as the encoders are); only an ENABLED, homed, idle arm takes effort commands.
"""
from __future__ import annotations

import math

#: crtk operating states.
DISABLED, ENABLED, PAUSED, FAULT = 'DISABLED', 'ENABLED', 'PAUSED', 'FAULT'
#: The state commands of crtk (crtk_msgs/StringStamped on ``state_command``).
STATE_COMMANDS = ('enable', 'disable', 'pause', 'resume', 'home', 'unhome')


class CommandTimeout:
    """Drive-side command timeout.

    Parameters
    ----------
    timeout : float
        Longest time without a command (s) before the current is cut, > 0.
    """

    def __init__(self, timeout: float):
        if not timeout > 0.0:
            raise ValueError(f'timeout must be > 0 s, got {timeout!r}')
        self.timeout = float(timeout)
        self.last_command = math.nan   # s, time of the last command (nan: none since the last cut)
        self.expiries = 0              # how often the current was cut
        self.last_expiry = math.nan    # s, when it was last cut
        self.last_silence = math.nan   # s, the time without a command at the last cut

    def command(self, now: float) -> None:
        """Note a command received at ``now`` (s): (re-)arms the timeout."""
        self.last_command = now

    def expired(self, now: float) -> bool:
        """Tell whether the timeout expired at ``now`` (s): True once per expiry, then disarmed."""
        if self.last_command != self.last_command or now - self.last_command <= self.timeout:
            return False
        self.last_silence = now - self.last_command
        self.last_command = math.nan
        self.expiries += 1
        self.last_expiry = now
        return True

    @property
    def armed(self) -> bool:
        """Tell whether a command is being held (the timeout is running)."""
        return self.last_command == self.last_command


class ArmState:
    """Operating state of the simulated dVRK arm.

    Parameters
    ----------
    homing_time : float
        How long ``home`` keeps the arm busy (s).
    """

    def __init__(self, homing_time: float):
        self.homing_time = float(homing_time)
        self.state = DISABLED
        self.is_homed = False
        self.is_busy = False
        self._homed_at = math.nan      # s, when the homing in progress completes

    @property
    def ready(self) -> bool:
        """Tell whether the arm takes effort commands: ENABLED, homed and not busy."""
        return self.state == ENABLED and self.is_homed and not self.is_busy

    def key(self) -> tuple:
        """Return (state, is_homed, is_busy): what an operating_state message carries."""
        return (self.state, self.is_homed, self.is_busy)

    def command(self, name: str, now: float) -> str | None:
        """Apply a state command at ``now`` (s); return why it was refused, or None.

        Unknown commands and commands that do not apply in the present state are refused
        (the state is unchanged); a command that is already in effect is accepted.
        """
        if name not in STATE_COMMANDS:
            return f'unknown state command {name!r} (one of {", ".join(STATE_COMMANDS)})'
        if name == 'enable':
            self.state = ENABLED
        elif name == 'disable':
            self.state = DISABLED
            self._stop_homing()
        elif name == 'pause':
            if self.state != ENABLED:
                return f'pause refused: the arm is {self.state}'
            self.state = PAUSED
            self._stop_homing()
        elif name == 'resume':
            if self.state != PAUSED:
                return f'resume refused: the arm is {self.state}, not PAUSED'
            self.state = ENABLED
        elif name == 'home':
            if self.state != ENABLED:
                return f'home refused: the arm is {self.state}, not ENABLED'
            if not self.is_homed and not self.is_busy:
                self.is_busy = True
                self._homed_at = now + self.homing_time
        elif name == 'unhome':
            self.is_homed = False
            self._stop_homing()
        return None

    def update(self, now: float) -> None:
        """Advance to ``now`` (s): a homing in progress completes after ``homing_time``."""
        if self.is_busy and now >= self._homed_at:
            self.is_busy = False
            self.is_homed = True
            self._homed_at = math.nan

    def _stop_homing(self) -> None:
        if self.is_busy:
            self.is_busy = False
            self._homed_at = math.nan
