"""Shared pytest fixtures.

Every test process gets DDS discovery on loopback only and its own ROS domain, so
parallel test runs (and other developers' runs on the same machine) never see
each other's nodes.
"""
import os

# Set before anything imports rclpy.
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', str(100 + os.getpid() % 100))
