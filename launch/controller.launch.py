"""The force controller alone, beside real hardware (or any node that serves the instrument).

    ros2 launch grip_force_ros controller.launch.py [instrument:=NAME|PATH] [namespace:=NS]
                                                    [interface:=crtk]

The instrument must publish instrument/measured_js and instrument/actuator/measured_js
(and grip/measured_force if it has a load cell) and follow instrument/actuator/servo_jf;
a master publishes master/gripper/measured_js (docs/ros_interface.md). Arguments as in
grasp.launch.py.
"""
from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from grip_force_ros.params.files import DEFAULT_INSTRUMENT, instrument_path
from grip_force_ros.topics import INTERFACES

PACKAGE = 'grip_force_ros'


def _controller(context):
    config = f'{get_package_share_directory(PACKAGE)}/config'
    params = str(instrument_path(LaunchConfiguration('instrument').perform(context), config).resolve())
    return [Node(package=PACKAGE, executable='controller', name='controller',
                 namespace=LaunchConfiguration('namespace').perform(context),
                 parameters=[params], output='screen')]


def generate_launch_description():
    return LaunchDescription([
        DeclareLaunchArgument('instrument', default_value=DEFAULT_INSTRUMENT,
                              description='instrument file in share/grip_force_ros/config '
                                          '(name, .yaml optional) or a path to a YAML'),
        DeclareLaunchArgument('namespace', default_value='',
                              description='namespace of the controller (topics are relative; '
                                          '/diagnostics stays global)'),
        DeclareLaunchArgument('interface', default_value=INTERFACES[0], choices=list(INTERFACES),
                              description='topic profile: crtk (the package names)'),
        OpaqueFunction(function=_controller),
    ])
