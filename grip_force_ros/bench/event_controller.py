"""Bench variant of the controller node: commands stamped with the state they answer.

The shipped ``controller`` steps on each actuator state (its 1 kHz timer is the
watchdog fallback) and stamps each command with its own clock at the step, so
the bench's probe has to match commands to states by delivery time (biased
towards longer round trips, see BENCHMARKS.md). This variant, used only by
``grip-force bench --event-controller``, is the same node whose current command
carries the stamp of the actuator state it answers, so the round trip is exact:
the command's arrival minus its stamp. (Commands of the fallback timer keep the
controller's clock.)

Run: ``python -m grip_force_ros.bench.event_controller --ros-args --params-file X.yaml``.
"""
from __future__ import annotations

import sys

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
    """:class:`ControllerNode` whose current command carries the answered state's stamp."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._servo_pub = _StampingPublisher(self._servo_pub)

    def _on_actuator(self, msg) -> None:
        self._servo_pub.stamp = msg.header.stamp
        try:
            super()._on_actuator(msg)      # steps on the state (the shipped node's loop)
        finally:
            self._servo_pub.stamp = None


def main(args=None) -> int:
    return run_node(EventDrivenController, 'controller', args)


if __name__ == '__main__':
    sys.exit(main())
