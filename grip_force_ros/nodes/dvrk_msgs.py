"""crtk_msgs for the dvrk profile, imported lazily, and the arm's operating state.

The ``crtk`` profile never imports crtk_msgs: it works on a machine that has only the
standard messages. The ``dvrk`` profile needs ``crtk_msgs/msg/OperatingState``,
``crtk_msgs/msg/StringStamped`` and ``crtk_msgs/srv/TriggerOperatingState``; where they
cannot be imported the node refuses to start with :class:`MissingCrtkMsgs`, which says how
to get them (``./dev setup`` builds crtk_msgs; ``source .venv/ros_setup.bash`` puts its
typesupport libraries on the library path).
"""
from __future__ import annotations

from dataclasses import dataclass

#: crtk operating states (crtk_msgs/OperatingState.state) the dVRK uses.
ENABLED = 'ENABLED'
DISABLED = 'DISABLED'


class MissingCrtkMsgs(ValueError):
    """The dvrk profile was asked for and crtk_msgs cannot be imported."""


@dataclass(frozen=True)
class CrtkMsgs:
    """The crtk_msgs types of the dvrk profile."""

    OperatingState: type
    StringStamped: type
    TriggerOperatingState: type


def crtk_msgs() -> CrtkMsgs:
    """Import the crtk_msgs types, lazily: only the dvrk profile calls this.

    Raises
    ------
    MissingCrtkMsgs
        With what is missing and how to get it.
    """
    try:
        from crtk_msgs.msg import OperatingState, StringStamped
        from crtk_msgs.srv import TriggerOperatingState
    except Exception as exc:  # noqa: BLE001 - ImportError, or the typesupport library not found
        raise MissingCrtkMsgs(
            f'the dvrk interface needs crtk_msgs (OperatingState, StringStamped, '
            f'TriggerOperatingState) and it cannot be imported here ({type(exc).__name__}: '
            f'{exc}). Build it with ./dev setup, then run the node after '
            "'source .venv/ros_setup.bash' (or ./dev ros2 run ...); on a ROS machine install "
            'crtk_msgs (ros-jazzy-crtk-msgs, or colcon build it from '
            'github.com/collaborative-robotics/crtk_msgs). The crtk interface does not need it.'
        ) from None
    return CrtkMsgs(OperatingState, StringStamped, TriggerOperatingState)


def arm_interlock(arm: str, state: str | None, is_homed: bool, is_busy: bool) -> str | None:
    """Return why the arm may not be driven now (None when ENABLED, homed and not busy).

    Parameters
    ----------
    arm : str
        The arm's name, for the message.
    state : str or None
        crtk operating state; None when none has been received yet.
    is_homed, is_busy : bool
        As the arm reports them.
    """
    if state is None:
        return f'arm {arm}: no operating state yet ({arm}/operating_state)'
    if state != ENABLED:
        return f'arm {arm} is {state}, not ENABLED'
    if not is_homed:
        return f'arm {arm} is ENABLED but not homed'
    if is_busy:
        return f'arm {arm} is busy (homing)'
    return None
