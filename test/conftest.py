"""Shared pytest fixtures.

Every test process gets DDS discovery on loopback only and its own ROS domain, so
parallel test runs (and other developers' runs on the same machine) never see
each other's nodes.
"""
import os

# Set before anything imports rclpy.
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', str(100 + os.getpid() % 100))

# Property tests: CI runs the same examples every time (a failure there is reproducible
# from its log); a developer's run explores new ones (and hypothesis keeps the failures
# it finds in .hypothesis/ to replay them).
from hypothesis import settings  # noqa: E402

settings.register_profile('ci', derandomize=True, print_blob=True)
if os.environ.get('CI'):
    settings.load_profile('ci')
