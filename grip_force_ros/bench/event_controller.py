"""Bench variant of the controller node: one control step per actuator state (event-driven).

The shipped ``controller`` steps on its own 1 kHz timer, unsynchronised with
the sim's 1 kHz timer, so each command answers a state that waited 0..1 period
for the next tick. This variant, used only by ``grip-force bench
--product-controller events`` to measure the proposal, steps in the actuator
state's callback instead (the state arrives once per sim period), and keeps a
1 kHz timer as a fallback that steps only when no state arrived for 1.5
periods (so the watchdog still trips on a silent sim).

Run: ``python -m grip_force_ros.bench.event_controller --ros-args --params-file X.yaml``.
"""
from __future__ import annotations

import sys
import time

from grip_force_ros.nodes.common import run_node
from grip_force_ros.nodes.controller import ControllerNode


class _StampingPublisher:
    """Publishes the command with the stamp of the state it answers (for the bench's probe)."""

    def __init__(self, publisher):
        self.publisher = publisher
        self.stamp = None            # builtin_interfaces/Time of the state being answered

    def publish(self, msg) -> None:
        if self.stamp is not None:
            msg.header.stamp = self.stamp
        self.publisher.publish(msg)


class EventDrivenController(ControllerNode):
    """:class:`ControllerNode` stepping on each actuator state; timer only as a fallback.

    The current command carries the stamp of the actuator state it answers (the
    shipped node stamps it with its clock at the tick), so the bench measures this
    variant's round trip exactly: arrival minus the command's stamp.
    """

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._last_step = time.perf_counter()
        self._servo_pub = _StampingPublisher(self._servo_pub)

    def _on_actuator(self, msg) -> None:
        super()._on_actuator(msg)
        self._last_step = time.perf_counter()
        self._servo_pub.stamp = msg.header.stamp
        super()._tick()
        self._servo_pub.stamp = None

    def _tick(self) -> None:
        # fallback: the sim went quiet for 1.5 periods; step so the watchdog can act
        if time.perf_counter() - self._last_step > 1.5 * self._period:
            self._last_step = time.perf_counter()
            super()._tick()


def main(args=None) -> int:
    return run_node(EventDrivenController, 'controller', args)


if __name__ == '__main__':
    sys.exit(main())
