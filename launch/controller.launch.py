"""The force controller alone, beside real hardware (or any node that serves the instrument).

    ros2 launch grip_force_ros controller.launch.py [instrument:=NAME|PATH] [namespace:=NS]
                                                    [interface:=crtk|dvrk] [arm:=PSM1]
                                                    [master:=MTML] [request_enable:=false]
                                                    [autostart:=true]

crtk: the instrument must publish instrument/measured_js and instrument/actuator/measured_js
(and grip/measured_force if it has a load cell) and follow instrument/actuator/servo_jf;
a master publishes master/gripper/measured_js (docs/ros_interface.md). dvrk: beside a dVRK
console, the controller drives ``arm``'s jaw (/PSM1/jaw/servo_jf, N*m) from ``master``'s
gripper while the arm is ENABLED and homed (docs/dvrk.md); request_enable:=true lets it ask
the arm to enable and home (default false: the console's operator does). autostart:=false:
the controller waits unconfigured for `ros2 lifecycle set` (a launch_ros LifecycleNode whose
transitions launch logs). Arguments as in grasp.launch.py.
"""
from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration

from grip_force_ros.nodes.launch_actions import PACKAGE, controller_actions
from grip_force_ros.params.files import DEFAULT_INSTRUMENT, instrument_path
from grip_force_ros.params.interface import INTERFACES


def _controller(context):
    def arg(name):
        return LaunchConfiguration(name).perform(context)
    config = f'{get_package_share_directory(PACKAGE)}/config'
    params = str(instrument_path(arg('instrument'), config).resolve())
    own = {'interface': arg('interface'), 'arm': arg('arm'), 'master': arg('master'),
           'request_enable': arg('request_enable').lower() == 'true'}
    return controller_actions(arg('namespace'), [params, own], arg('autostart').lower() == 'true')


def generate_launch_description():
    return LaunchDescription([
        DeclareLaunchArgument('instrument', default_value=DEFAULT_INSTRUMENT,
                              description='instrument file in share/grip_force_ros/config '
                                          '(name, .yaml optional) or a path to a YAML'),
        DeclareLaunchArgument('namespace', default_value='',
                              description='namespace of the controller (topics are relative; '
                                          '/diagnostics stays global)'),
        DeclareLaunchArgument('interface', default_value=INTERFACES[0], choices=list(INTERFACES),
                              description='topic profile: crtk (the package names) or dvrk (a '
                                          'dVRK arm and master: docs/dvrk.md)'),
        DeclareLaunchArgument('arm', default_value='PSM1',
                              description='dvrk: the arm whose jaw the controller drives'),
        DeclareLaunchArgument('master', default_value='MTML',
                              description='dvrk: the master whose gripper drives the jaw'),
        DeclareLaunchArgument('request_enable', default_value='false', choices=['true', 'false'],
                              description='dvrk: ask the arm to enable and home'),
        DeclareLaunchArgument('autostart', default_value='true', choices=['true', 'false'],
                              description='false: the controller waits unconfigured for '
                                          '`ros2 lifecycle set /controller configure`'),
        OpaqueFunction(function=_controller),
    ])
