r"""The product's controller for the full-path figures: the shipped node, noting the inputs of each step.

``grip-force bench`` measures the round trip at the sim (actuator-state stamp ->
command arrival, :mod:`.product_sim`); the full path needs, per command, the sample
stamps of *every* input the step used. This module runs the shipped
:class:`~grip_force_ros.nodes.controller.ControllerNode` (the same loop, topics and
timing) and only extends its ``_update`` (one control step) to note, for each command that answers an
actuator state, the stamps of the actuator state, the jaw angle (``instrument/measured_js``)
and the load cell (``grip/measured_force``) in its ``ControlInputs`` and the controller's
clock at the step; a ring of the newest ``--capacity`` steps is written as ``.npz`` to
``--record`` when the node shuts down. Cost on the loop's path: a few array writes per step.

Run by :func:`grip_force_ros.lab.bench.loop.run_product`::

    python -m grip_force_ros.lab.bench.product_controller --record steps.npz \
        --ros-args --params-file config/paper_needle_driver.yaml
"""
from __future__ import annotations

import argparse
import functools
import sys

import numpy as np
from rclpy.utilities import remove_ros_args

from grip_force_ros.lab import node_process
from grip_force_ros.nodes.controller import ControllerNode
from grip_force_ros.nodes.lifetime import run_node

#: Columns of the record (ns): the answered actuator-state stamp, the controller's clock at the
#: step, and the sample stamps of the inputs the step used (0: none yet, or no stamp).
COLUMNS = ('answered_ns', 'step_ns', 'actuator_ns', 'jaw_ns', 'load_cell_ns')


def _ns(stamp_s: float) -> int:
    """Stamp (s, NaN when none) -> int ns, 0 for none."""
    return int(round(stamp_s * 1e9)) if stamp_s == stamp_s else 0


class BenchController(ControllerNode):
    """The shipped controller node; notes the input stamps of every step that answers a state."""

    def __init__(self, opts, **kwargs):
        super().__init__(**kwargs)
        self._record_path = opts.record
        self._rows = np.zeros((opts.capacity, len(COLUMNS)), np.int64)
        self._n = 0

    def _update(self, now_ns, answered_ns, started):
        """Run the shipped step, then note the input stamps of a step that answers a state."""
        super()._update(now_ns, answered_ns, started)
        if answered_ns is not None:
            inputs = self.inputs
            self._rows[self._n % len(self._rows)] = (
                answered_ns, now_ns,
                _ns(inputs.actuator_stamp), _ns(inputs.instrument_stamp), _ns(inputs.force_stamp))
            self._n += 1

    def records(self) -> dict[str, np.ndarray]:
        """Return the noted steps, oldest first: one int64 array (ns) per column of :data:`COLUMNS`."""
        size = len(self._rows)
        rows = self._rows[:self._n] if self._n <= size else np.roll(self._rows, -(self._n % size), axis=0)
        return {name: rows[:, i].copy() for i, name in enumerate(COLUMNS)}

    def destroy_node(self):
        """Write the record, then destroy the node."""
        if getattr(self, '_record_path', None):       # not set when the node refused to start
            np.savez(self._record_path, **self.records())
            self._record_path = None
        return super().destroy_node()


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog='python -m grip_force_ros.lab.bench.product_controller')
    p.add_argument('--record', required=True, help='.npz written at shutdown')
    p.add_argument('--capacity', type=int, default=200_000, help='newest steps kept')
    return p


def main(argv=None) -> int:
    argv = list(sys.argv if argv is None else argv)
    opts = build_parser().parse_args(remove_ros_args(argv)[1:])
    node_process.install()      # its teardown watched, as the harness's nodes
    return run_node(functools.partial(BenchController, opts), 'controller', argv)


if __name__ == '__main__':
    sys.exit(main())
