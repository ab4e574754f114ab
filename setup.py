"""ament_python build of grip_force_ros (colcon build, or pip install -e .)."""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = 'grip_force_ros'

setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(include=[PACKAGE, PACKAGE + '.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE]),
        ('share/' + PACKAGE, ['package.xml']),
        ('share/' + PACKAGE + '/config', sorted(glob('config/*.yaml'))),
        ('share/' + PACKAGE + '/launch', sorted(glob('launch/*.launch.py'))),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='grip_force_ros maintainers',
    maintainer_email='maintainers@grip-force-ros.invalid',
    description='Grip-force model and force control of cable-driven surgical instruments.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'controller = grip_force_ros.nodes.controller:main',
            'sim_instrument = grip_force_ros.nodes.sim_instrument:main',
            'master = grip_force_ros.nodes.master:main',
            'grip-force = grip_force_ros.lab.cli:main',
        ],
    },
)
