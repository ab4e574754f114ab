"""Names of the ROS interface (topics, joint names, frames). No rclpy here.

CRTK-style names, as used by the dVRK. All remappable with ``--ros-args -r``.

| topic | type | from -> to | content |
|---|---|---|---|
| master/gripper/measured_js | sensor_msgs/JointState | master -> controller | position[0]: gripper opening (rad) |
| instrument/measured_js | sensor_msgs/JointState | sim/hw -> controller | wrist_pitch, jaw: position (rad), velocity (rad/s) |
| instrument/actuator/measured_js | sensor_msgs/JointState | sim/hw -> controller | jaw_drum: position (rad), velocity (rad/s), effort = measured current (A) |
| instrument/actuator/servo_jf | sensor_msgs/JointState | controller -> sim/hw | jaw_drum: effort = current command (A) |
| grip/estimated_force | geometry_msgs/WrenchStamped | controller -> any | force.z = grip force (N), force.x = needle pull-out force (N) |
| grip/target_force | geometry_msgs/WrenchStamped | controller -> any | force.z = target grip force (N) |
| grip/measured_force | geometry_msgs/WrenchStamped | sim load cell -> any | force.z = measured grip force (N) |
| /diagnostics | diagnostic_msgs/DiagnosticArray | controller, sim | state, limits hit, watchdog, rejected inputs |
"""  # noqa: E501 - Markdown table rows are kept whole

MASTER_JS = 'master/gripper/measured_js'
INSTRUMENT_JS = 'instrument/measured_js'
ACTUATOR_JS = 'instrument/actuator/measured_js'
SERVO_CURRENT = 'instrument/actuator/servo_jf'
ESTIMATED_FORCE = 'grip/estimated_force'
TARGET_FORCE = 'grip/target_force'
MEASURED_FORCE = 'grip/measured_force'
DIAGNOSTICS = '/diagnostics'

MASTER_JOINT = 'gripper'
WRIST_JOINT = 'wrist_pitch'
JAW_JOINT = 'jaw'
DRUM_JOINT = 'jaw_drum'
JAW_FRAME = 'jaw'

#: Every topic a demo records (the rosbag2 of a run).
RECORDED = (MASTER_JS, INSTRUMENT_JS, ACTUATOR_JS, SERVO_CURRENT, ESTIMATED_FORCE,
            TARGET_FORCE, MEASURED_FORCE, DIAGNOSTICS)

#: Topic-name profiles (the launch files' ``interface:=``). ``crtk``: the names above. The
#: dVRK PSM's names (``dvrk``) come with the dVRK work; the launch argument exists already.
INTERFACES = ('crtk',)
