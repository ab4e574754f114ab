"""The closed loop on one machine: master -> controller -> simulated instrument.

    ros2 launch grip_force_ros grasp.launch.py [instrument:=NAME|PATH] [namespace:=NS]
                                               [interface:=crtk]

instrument:=  an instrument file of the package (config/, e.g. long_jaw_grasper, with or
              without .yaml) or a path to a parameter YAML; every node reads all of it.
namespace:=   pushes the three nodes into NS: their topics are relative names, so
              grip/estimated_force becomes /NS/grip/estimated_force and the parameters
              /NS/controller; /diagnostics is absolute and stays /diagnostics.
interface:=   the topic profile (crtk: the package's names; dvrk comes with the dVRK work).

The master plays the needle grasp (approach, close, hold, pull test, release) once and
holds its last angle; Ctrl-C stops all three. docs/ros_interface.md has the details.
"""
from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from grip_force_ros.params.files import DEFAULT_INSTRUMENT, instrument_path
from grip_force_ros.topics import INTERFACES

PACKAGE = 'grip_force_ros'
EXECUTABLES = ('sim_instrument', 'controller', 'master')


def _nodes(context):
    config = f'{get_package_share_directory(PACKAGE)}/config'
    params = str(instrument_path(LaunchConfiguration('instrument').perform(context), config).resolve())
    namespace = LaunchConfiguration('namespace').perform(context)
    return [Node(package=PACKAGE, executable=exe, name=exe, namespace=namespace,
                 parameters=[params], output='screen')
            for exe in EXECUTABLES]


def generate_launch_description():
    return LaunchDescription([
        DeclareLaunchArgument('instrument', default_value=DEFAULT_INSTRUMENT,
                              description='instrument file in share/grip_force_ros/config '
                                          '(name, .yaml optional) or a path to a YAML'),
        DeclareLaunchArgument('namespace', default_value='',
                              description='namespace of the three nodes (topics are relative; '
                                          '/diagnostics stays global)'),
        DeclareLaunchArgument('interface', default_value=INTERFACES[0], choices=list(INTERFACES),
                              description='topic profile: crtk (the package names)'),
        OpaqueFunction(function=_nodes),
    ])
