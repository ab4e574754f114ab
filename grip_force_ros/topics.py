"""Names of the ROS interface (topics, joint names, frames). No rclpy here.

CRTK-style names, as used by the dVRK. All remappable with ``--ros-args -r``.

| topic | type | from -> to | content |
|---|---|---|---|
| master/gripper/measured_js | sensor_msgs/JointState | master -> controller | position[0]: gripper opening (rad) |
| instrument/measured_js | sensor_msgs/JointState | sim/hw -> controller | wrist_pitch, jaw: position (rad), velocity (rad/s) |
| instrument/actuator/measured_js | sensor_msgs/JointState | sim/hw -> controller | jaw_drum: position (rad), velocity (rad/s), effort = measured current (A) |
| instrument/actuator/servo_jf | sensor_msgs/JointState | controller -> sim/hw | jaw_drum: effort = current command (A) |
| grip/estimated_force | geometry_msgs/WrenchStamped | controller -> any | force.z = grip force (N), force.x = needle pull-out force (N) |
| grip/estimate_band | geometry_msgs/WrenchStamped | controller -> any | force.x, force.y = the estimate band's low and high edge (N), force.z = the estimated grip force (N) |
| grip/target_force | geometry_msgs/WrenchStamped | controller -> any | force.z = target grip force (N) |
| grip/measured_force | geometry_msgs/WrenchStamped | sim load cell -> any | force.z = measured grip force (N) |
| /diagnostics | diagnostic_msgs/DiagnosticArray | controller, sim | state, limits hit, watchdog, rejected inputs |


The ``dvrk`` profile (the da Vinci Research Kit's names under an arm and a master):
:func:`topic_set` and the ``DVRK_*`` names below.
"""  # noqa: E501 - Markdown table rows are kept whole
from __future__ import annotations

from dataclasses import dataclass

MASTER_JS = 'master/gripper/measured_js'
INSTRUMENT_JS = 'instrument/measured_js'
ACTUATOR_JS = 'instrument/actuator/measured_js'
SERVO_CURRENT = 'instrument/actuator/servo_jf'
ESTIMATED_FORCE = 'grip/estimated_force'
ESTIMATE_BAND = 'grip/estimate_band'
TARGET_FORCE = 'grip/target_force'
MEASURED_FORCE = 'grip/measured_force'
DIAGNOSTICS = '/diagnostics'

#: The controller's services (private names: /controller/set_object, ...; nodes/controller_services.py).
SET_OBJECT_SRV = '~/set_object'     # rcl_interfaces/srv/SetParameters: object_kind
TARE_SRV = '~/tare'                 # std_srvs/srv/Trigger
CALIBRATE_SRV = '~/calibrate'       # std_srvs/srv/Trigger
#: The controller's grasp actions (control_msgs; dvrk: under the arm, as its grip topics):
GRIP_COMMAND_ACTION = 'grip_command'                     # control_msgs/action/GripperCommand
PARALLEL_GRIP_COMMAND_ACTION = 'parallel_grip_command'   # .../ParallelGripperCommand

MASTER_JOINT = 'gripper'
WRIST_JOINT = 'wrist_pitch'
JAW_JOINT = 'jaw'
DRUM_JOINT = 'jaw_drum'
JAW_FRAME = 'jaw'


# --- the dVRK profile (interface 'dvrk'; docs/dvrk.md) ---------------------------------------
# The da Vinci Research Kit's topics of an arm (PSM1, PSM2, ...) and a master (MTML, MTMR),
# relative names under the device's own (``PSM1/jaw/measured_js``), as the dVRK publishes them.
DVRK_ARM_JS = 'measured_js'             # the arm's joints by name, wrist_pitch among them
DVRK_JAW_JS = 'jaw/measured_js'         # jaw: position (rad), velocity (rad/s), effort (N*m)
DVRK_JAW_SERVO = 'jaw/servo_jf'         # jaw: effort = jaw effort command (N*m, positive opens)
DVRK_JAW_SERVO_JP = 'jaw/servo_jp'      # jaw: position = jaw setpoint (rad), the PSM's position loop
DVRK_SERVO_CP = 'servo_cp'              # geometry_msgs/PoseStamped: the arm's Cartesian setpoint
DVRK_SERVO_JP = 'servo_jp'              # sensor_msgs/JointState: the arm's joint setpoints
DVRK_GRIPPER_JS = 'gripper/measured_js'  # the master gripper: position (rad)
DVRK_OPERATING_STATE = 'operating_state'  # crtk_msgs/OperatingState, topic and service
DVRK_STATE_COMMAND = 'state_command'    # crtk_msgs/StringStamped: enable, disable, home, ...
#: The PSM's joints in ``measured_js`` (dVRK 2.2+: the arm's three, then the tool file's;
#: share/kinematic/psm.json and share/tool/*.json of sawIntuitiveResearchKit).
DVRK_PSM_JOINTS = ('outer_yaw', 'outer_pitch', 'outer_insertion', 'roll', 'wrist_pitch', 'wrist_yaw')
#: Names of the wrist pitch joint, in the order they are looked for: dVRK 2.2+ (tool files),
#: then dVRK 2.1 and before.
DVRK_WRIST_JOINTS = ('wrist_pitch', 'outer_wrist_pitch')


@dataclass(frozen=True)
class TopicSet:
    """The topics of one interface profile (relative names; None: not in the profile).

    The ``crtk`` profile carries the jaw and the wrist in ``instrument_js`` and the motor
    current in ``actuator_js``; the ``dvrk`` one the wrist in ``instrument_js`` (the arm's
    ``measured_js``) and the jaw, with the jaw effort, in ``actuator_js`` (``jaw/measured_js``).
    """

    interface: str
    master_js: str
    instrument_js: str
    actuator_js: str
    command: str
    estimated_force: str
    estimate_band: str
    target_force: str
    measured_force: str
    operating_state: str | None = None
    state_command: str | None = None
    jaw_servo_jp: str | None = None
    servo_cp: str | None = None
    servo_jp: str | None = None

    def recorded(self) -> tuple[str, ...]:
        """Every topic a demo of this profile records (its rosbag2), /diagnostics last."""
        extra = tuple(t for t in (self.jaw_servo_jp, self.operating_state) if t)
        return (self.master_js, self.instrument_js, self.actuator_js, self.command,
                self.estimated_force, self.estimate_band, self.target_force,
                self.measured_force) + extra + (DIAGNOSTICS,)


def dvrk_topic(device: str, name: str) -> str:
    """Return the dVRK topic ``name`` of ``device`` (an arm or a master): 'PSM1/jaw/measured_js'."""
    return f'{device}/{name}'


def action_names(interface: str = 'crtk', arm: str = 'PSM1') -> tuple[str, str]:
    """Return the controller's grasp actions (GripperCommand, ParallelGripperCommand) of a profile."""
    names = (GRIP_COMMAND_ACTION, PARALLEL_GRIP_COMMAND_ACTION)
    return names if interface == 'crtk' else tuple(dvrk_topic(arm, n) for n in names)


#: Prefix of every /diagnostics status name of this package's nodes.
DIAGNOSTIC_PREFIX = 'grip_force_ros: '


def diagnostic_name(namespace: str, node: str) -> str:
    """Return the /diagnostics status name of ``node`` in ``namespace``.

    ``'grip_force_ros: controller'`` in the root namespace (``'/'`` or ``''``),
    ``'grip_force_ros: /PSM1/controller'`` in ``/PSM1``: /diagnostics is one topic for
    every node, so the arms of one console tell their statuses apart by name, as an
    aggregator groups them.
    """
    ns = namespace.rstrip('/')
    return f'{DIAGNOSTIC_PREFIX}{ns}/{node}' if ns else f'{DIAGNOSTIC_PREFIX}{node}'


def is_status_of(name: str, node: str) -> bool:
    """Tell whether a /diagnostics status ``name`` is one of ``node`` (any namespace)."""
    return name == DIAGNOSTIC_PREFIX + node or (name.startswith(DIAGNOSTIC_PREFIX)
                                                and name.endswith('/' + node))


def topic_set(interface: str = 'crtk', arm: str = 'PSM1', master: str = 'MTML') -> TopicSet:
    """Return the topics of ``interface`` ('crtk' or 'dvrk', with the dVRK arm and master names).

    In ``dvrk`` the grip force topics go under the arm too (``PSM1/grip/estimated_force``), so
    that two arms with a controller each run side by side.
    """
    if interface == 'crtk':
        return TopicSet('crtk', MASTER_JS, INSTRUMENT_JS, ACTUATOR_JS, SERVO_CURRENT,
                        ESTIMATED_FORCE, ESTIMATE_BAND, TARGET_FORCE, MEASURED_FORCE)
    if interface == 'dvrk':
        return TopicSet('dvrk', dvrk_topic(master, DVRK_GRIPPER_JS), dvrk_topic(arm, DVRK_ARM_JS),
                        dvrk_topic(arm, DVRK_JAW_JS), dvrk_topic(arm, DVRK_JAW_SERVO),
                        dvrk_topic(arm, ESTIMATED_FORCE), dvrk_topic(arm, ESTIMATE_BAND),
                        dvrk_topic(arm, TARGET_FORCE),
                        dvrk_topic(arm, MEASURED_FORCE), dvrk_topic(arm, DVRK_OPERATING_STATE),
                        dvrk_topic(arm, DVRK_STATE_COMMAND), dvrk_topic(arm, DVRK_JAW_SERVO_JP),
                        dvrk_topic(arm, DVRK_SERVO_CP), dvrk_topic(arm, DVRK_SERVO_JP))
    raise ValueError(f"unknown interface {interface!r}: 'crtk' or 'dvrk'")


#: Every topic a demo of the crtk profile records (the rosbag2 of a run).
RECORDED = topic_set('crtk').recorded()
