"""Real-time settings of the 1 kHz nodes (group 'realtime'); applied by ``nodes/realtime.py``.

The controller, the sim and the master declare them. They act on the node's process once,
right before it starts spinning (docs/ros_interface.md, "Real-time settings"), so they are
read-only at runtime.
"""
from grip_force_ros.params.schema import ParamSpec

_G = 'realtime'

#: Highest CPU id ``cpu_affinity`` may name (Linux's default ``CONFIG_NR_CPUS`` range).
CPU_ID_MAX = 4095

REALTIME = [
    ParamSpec('lock_memory', 'bool', True, '',
              "Lock the process's memory at start (mlockall of current and future pages), "
              'so that no page of the loop is paged out and read back from disk; where not '
              'permitted (no CAP_IPC_LOCK and RLIMIT_MEMLOCK too small: ulimit -l) the node '
              'says why once in its log and runs unlocked.',
              read_only=True, group=_G),
    ParamSpec('cpu_affinity', 'integer_array', (), '',
              'CPU ids every thread of the node process is pinned to at start '
              '(sched_setaffinity); empty: no pinning. An id this machine does not let the '
              'process run on is refused at start.',
              min=0, max=CPU_ID_MAX, read_only=True, group=_G),
]
