"""Shared pytest fixtures.

Every test process gets DDS discovery on loopback only and its own ROS domain, so
parallel test runs (and other developers' runs on the same machine) never see
each other's nodes.
"""
import os

from grip_force_ros.lab.processes import ProcessError, reserve_domains

# Set before anything imports rclpy.
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
# The suite's own domain, held for the whole session (a lock file per domain, and no
# domain whose DDS ports another process has bound): two suites, a demo and a bench on one
# machine never share one. A ROS_DOMAIN_ID given by the caller is kept (held too when free).
_preset = os.environ.get('ROS_DOMAIN_ID')
if _preset:
    try:
        DOMAIN = reserve_domains(1, candidates=[int(_preset)])
    except ProcessError:    # the caller's explicit choice stands, held or not
        DOMAIN = None
else:
    DOMAIN = reserve_domains(1)
    os.environ['ROS_DOMAIN_ID'] = str(DOMAIN.domain_id)

# Property tests: CI runs the same examples every time (a failure there is reproducible
# from its log); a developer's run explores new ones (and hypothesis keeps the failures
# it finds in .hypothesis/ to replay them).
import pytest  # noqa: E402
from hypothesis import settings  # noqa: E402

# No per-example deadline: hypothesis's 200 ms default measures the machine, not the code
# (test_motor_angle_inverts_jaw_angle exceeded it on a 2-core machine running the loaded ROS
# tests beside it); speed is what the benchmarks measure.
settings.register_profile('dev', deadline=None)
settings.register_profile('ci', deadline=None, derandomize=True, print_blob=True)
settings.load_profile('ci' if os.environ.get('CI') else 'dev')


# A load for the whole session (`./dev test --with-load ...`): one busy process per
# core (or --load-workers), stopped at the end of the session whatever happens
# (grip_force_ros/lab/bench/load.py); `--load-kind disk` the disk pressure instead (fsync
# writers, page-cache eviction of the package's files; grip_force_ros/lab/bench/pressure.py),
# `both` the two. `grip-force loadcheck` runs the ROS tests K times so.
def pytest_addoption(parser):
    group = parser.getgroup('grip_force_ros')
    group.addoption('--with-load', action='store_true',
                    help='run the session under a bounded load (default: one busy process per core)')
    group.addoption('--load-workers', type=int, default=None,
                    help='busy processes of --with-load (default: one per core)')
    group.addoption('--load-kind', choices=('cpu', 'disk', 'both'), default='cpu',
                    help='the load of --with-load: cpu (default), disk (fsync writers, page-cache '
                         'eviction) or both')


@pytest.fixture(scope='session', autouse=True)
def cpu_load(request):
    """Run the session under the --with-load generator (yields it; None without the option)."""
    if not request.config.getoption('--with-load'):
        yield None
        return
    from grip_force_ros.lab.bench.load import MAX_SECONDS
    from grip_force_ros.lab.bench.pressure import make_pressure
    with make_pressure(request.config.getoption('--load-kind'), seconds=MAX_SECONDS,
                       workers=request.config.getoption('--load-workers')) as load:
        yield load


def pytest_collection_modifyitems(config, items):
    """Mark the tests of the ros2 command-line tools (test/_ros_tools.py) ``ros`` too.

    They start real nodes over DDS (``ros2 launch``, ``ros2 topic``, crtk_msgs between
    processes), so ``-m ros`` (``grip-force loadcheck``) must select them with the others.
    """
    ros = pytest.mark.ros
    for item in items:
        module = getattr(item, 'module', None)
        if module is not None and hasattr(module, 'require_ros_tools'):
            item.add_marker(ros)
