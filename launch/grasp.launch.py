"""The closed loop on one machine: master -> controller -> simulated instrument.

    ros2 launch grip_force_ros grasp.launch.py [instrument:=NAME|PATH] [namespace:=NS]
                                               [interface:=crtk|dvrk] [arm:=PSM1] [master:=MTML]
                                               [request_enable:=true] [autostart:=true]

instrument:=      an instrument file of the package (config/, e.g. long_jaw_grasper, with or
                  without .yaml) or a path to a parameter YAML; every node reads all of it.
namespace:=       pushes the three nodes into NS: their topics are relative names, so
                  grip/estimated_force becomes /NS/grip/estimated_force and the parameters
                  /NS/controller; /diagnostics is absolute and stays /diagnostics.
interface:=       the topic profile: crtk (the package's names, current in A) or dvrk (the
                  sim plays the dVRK arm ``arm``, the master is the dVRK master ``master``:
                  /PSM1/jaw/measured_js, /PSM1/jaw/servo_jf in N*m, /MTML/gripper/measured_js,
                  /PSM1/operating_state; 100 Hz; docs/dvrk.md).
arm:=, master:=   the dVRK arm and master names of the dvrk profile (PSM1, MTML; PSM2 and MTMR
                  run beside them).
request_enable:=  dvrk: the controller asks the simulated arm to enable and home (default
                  true here: nobody else does; beside a real dVRK the console does).
autostart:=       true: the controller (a lifecycle node) configures and activates itself;
                  false: it is launched as a launch_ros LifecycleNode and waits unconfigured,
                  sending no command, for `ros2 lifecycle set /controller configure` and
                  `activate`; launch logs its transitions.

The master plays the needle grasp (approach, close, hold, pull test, release) once and
holds its last angle; Ctrl-C stops all three. docs/ros_interface.md has the details.
"""
from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from grip_force_ros.nodes.launch_actions import PACKAGE, controller_actions
from grip_force_ros.nodes.lifetime import leave_after_environment
from grip_force_ros.params.files import DEFAULT_INSTRUMENT, instrument_path
from grip_force_ros.params.interface import INTERFACES


def _nodes(context):
    def arg(name):
        return LaunchConfiguration(name).perform(context)
    config = f'{get_package_share_directory(PACKAGE)}/config'
    params = str(instrument_path(arg('instrument'), config).resolve())
    profile = {'interface': arg('interface'), 'arm': arg('arm'), 'master': arg('master')}
    controller = {**profile, 'request_enable': arg('request_enable').lower() == 'true'}

    def node(exe, leave_after=()):
        return Node(package=PACKAGE, executable=exe, name=exe, namespace=arg('namespace'),
                    parameters=[params, profile], output='screen',
                    additional_env=leave_after_environment(leave_after))

    # Ctrl-C reaches the three at once; they leave one after another, the master first, so
    # that none is torn down while another one's leaving reaches it (Fast DDS's spinning
    # set_listener, eProsima/Fast-DDS#6513: lifetime.leave_after).
    return [node('sim_instrument', leave_after=('controller', 'master')),
            *controller_actions(arg('namespace'), [params, controller],
                                arg('autostart').lower() == 'true', leave_after=('master',)),
            node('master')]


def generate_launch_description():
    return LaunchDescription([
        DeclareLaunchArgument('instrument', default_value=DEFAULT_INSTRUMENT,
                              description='instrument file in share/grip_force_ros/config '
                                          '(name, .yaml optional) or a path to a YAML'),
        DeclareLaunchArgument('namespace', default_value='',
                              description='namespace of the three nodes (topics are relative; '
                                          '/diagnostics stays global)'),
        DeclareLaunchArgument('interface', default_value=INTERFACES[0], choices=list(INTERFACES),
                              description='topic profile: crtk (the package names) or dvrk (a '
                                          'dVRK arm and master: docs/dvrk.md)'),
        DeclareLaunchArgument('arm', default_value='PSM1',
                              description='dvrk: the arm the sim plays and the controller drives'),
        DeclareLaunchArgument('master', default_value='MTML',
                              description='dvrk: the master whose gripper drives the jaw'),
        DeclareLaunchArgument('request_enable', default_value='true', choices=['true', 'false'],
                              description='dvrk: the controller asks the arm to enable and home'),
        DeclareLaunchArgument('autostart', default_value='true', choices=['true', 'false'],
                              description='false: the controller waits unconfigured for '
                                          '`ros2 lifecycle set /controller configure`'),
        OpaqueFunction(function=_nodes),
    ])
