"""The estimate's band over real publish/subscribe: ``grip/estimate_band`` and /diagnostics.

The controller runs in this process on the Maryland forceps' file (jaw friction terms on,
sensorless); the simulated instrument (the same file: the rig's friction in the plant) and
the master run as processes, as in the demo. A probe node subscribes to the companion topic
and /diagnostics: while the jaw holds the needle the estimate is held inside a band of
positive width, the topic carries it at ``force_output_rate`` and /diagnostics says so.
"""
from __future__ import annotations

import time
from pathlib import Path

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped

from grip_force_ros import topics
from grip_force_ros.lab.harness import RosRunner
from grip_force_ros.lab.processes import NodeProcess
from grip_force_ros.nodes.common import STATE_SUB_QOS
from grip_force_ros.nodes.controller import ControllerNode
from grip_force_ros.params import SPECS, read_params_yaml

pytestmark = pytest.mark.ros

CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'maryland_forceps.yaml'
GRASP = 4.5           # s of the master's needle grasp: close (from ~0.7 s) and hold
#: Longest wait for a node process's first message (s): importing numpy and scipy alone took
#: more than 15 s at a load average of 16 on 2 cores.
START = 60.0


def _controller_values(path: Path) -> dict:
    return {k: v for k, v in read_params_yaml(path).items()
            if k in SPECS and SPECS[k].group in ('instrument', 'limits', 'controller')}


def test_the_band_is_published_and_diagnosed_while_the_jaw_sticks(tmp_path):
    bands: list[tuple[float, float, float, float]] = []     # (receive s, low, high, estimate) N
    estimates: list[float] = []                             # receive times (s)
    held: list[str] = []                                    # 'estimate' values of /diagnostics
    with RosRunner() as ros:
        ctl = ros.add(ControllerNode, **_controller_values(CONFIG))
        assert ctl.controller.friction_state is not None and not ctl.params.force_sensor_enabled
        probe = ros.plain_node('band_probe')

        def on_band(msg):
            f = msg.wrench.force
            bands.append((time.monotonic(), f.x, f.y, f.z))

        def on_diagnostics(msg):
            for status in msg.status:
                if topics.is_status_of(status.name, 'controller'):
                    held.extend(kv.value for kv in status.values if kv.key == 'estimate')

        probe.create_subscription(WrenchStamped, topics.ESTIMATE_BAND, on_band, STATE_SUB_QOS)
        probe.create_subscription(WrenchStamped, topics.ESTIMATED_FORCE,
                                  lambda msg: estimates.append(time.monotonic()), STATE_SUB_QOS)
        probe.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, on_diagnostics, 50)
        ros.start()
        sim = NodeProcess('sim_instrument', params_file=str(CONFIG),
                          log_path=str(tmp_path / 'sim.log'))
        try:
            assert ros.wait_for(lambda: ctl.inputs.instrument_time == ctl.inputs.instrument_time,
                                START), 'no instrument state from the sim process'
            master = NodeProcess('master', params_file=str(CONFIG),
                                 log_path=str(tmp_path / 'master.log'))
            try:
                assert ros.wait_for(lambda: ctl.inputs.master_time == ctl.inputs.master_time,
                                    START), 'no master input from the master process'
                assert ros.wait_for(lambda: any(v.startswith('held in stick') for v in held),
                                    GRASP + 10.0), ('never held in stick', held[-5:], bands[-3:])
                time.sleep(1.0)                                  # some of the hold
            finally:
                master.stop()
        finally:
            sim.stop()
        assert ros.spin_error is None, ros.spin_error
    assert bands, 'no message on grip/estimate_band'
    # inside the band while the jaw sticks: positive width, the estimate strictly inside
    inside = [b for b in bands if b[1] < b[3] < b[2]]
    assert len(inside) > 20, bands[-5:]
    assert all(b[2] - b[1] > 0.5 for b in inside)
    assert all(b[1] <= b[3] <= b[2] for b in bands)
    # /diagnostics: "estimate: held in stick, band X N", X the width in N
    said = [v for v in held if v.startswith('held in stick, band ')]
    width = float(said[-1].removeprefix('held in stick, band ').removesuffix(' N'))
    assert said[-1].endswith(' N') and width > 0.5
    # at the estimate's own (reduced) rate: one band per estimated force, not one per step
    assert abs(len(bands) - len(estimates)) <= 0.05 * len(estimates) + 3
    span = bands[-1][0] - bands[0][0]
    assert len(bands) / span < 1.5 * ctl.params.force_output_rate, (len(bands), span)
