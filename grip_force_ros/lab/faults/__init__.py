"""Fault catalogue and fault check: the controller's reliability.

* :mod:`.catalogue` (ROS-free): every fault with its defined outcome (:data:`OUTCOMES`).
* :mod:`.probe` (rclpy): a plant + fault injector node that closes the loop with a real
  controller node over DDS and records its outputs.
* :mod:`.runner` (rclpy): :func:`run_faultcheck` runs the catalogue against the real
  controller node and returns ``{"cases", "passed", "crashes", "limit_violations",
  "failures", "details"}``; ``grip-force faultcheck [--json]`` prints it.
* :mod:`.soak` (subprocesses): the long closed-loop run of ``grip-force soak``.

See docs/reliability.md.
"""
from grip_force_ros.lab.faults.catalogue import OUTCOMES, FaultCase, catalogue, select

__all__ = ['OUTCOMES', 'FaultCase', 'catalogue', 'select']
