"""Figure of the ROS graph (README.md, docs/ros_interface.md): nodes, topics, services.

    .venv/bin/python -m grip_force_ros.lab.figures.ros_graph [OUT.png]

Drawn from the topic table, not from a live graph: every name comes from
:mod:`grip_force_ros.topics` (the ``crtk`` profile, the names ``ros2 topic list`` shows
with ``ros2 launch grip_force_ros grasp.launch.py``; test/test_launch.py checks them on
the live graph), so the figure cannot drift from the code. Prints the edges it draws;
writes the PNG (default docs/figures/ros_graph.png).
"""
from __future__ import annotations

import sys

from grip_force_ros import topics
from grip_force_ros.lab.plotting import pyplot, save

#: Node boxes: name -> (x, y) centre, in axes units (0..1).
NODES = {'master': (0.08, 0.62), 'controller': (0.45, 0.62), 'sim_instrument': (0.86, 0.62)}
#: Topic edges: (topic, publisher, subscriber, y of the arrow, message type).
EDGES = (
    (topics.MASTER_JS, 'master', 'controller', 0.70, 'sensor_msgs/JointState (rad)'),
    (topics.SERVO_CURRENT, 'controller', 'sim_instrument', 0.70, 'JointState effort: current (A)'),
    (topics.INSTRUMENT_JS, 'sim_instrument', 'controller', 0.62, 'JointState: wrist, jaw (rad)'),
    (topics.ACTUATOR_JS, 'sim_instrument', 'controller', 0.54,
     'JointState: drum (rad), current (A)'),
)
#: Topics read by anyone (monitor, ros2 topic echo, the demo's bag): (topic, publisher, type).
OUTPUTS = (
    (topics.ESTIMATED_FORCE, 'controller', 'WrenchStamped: grip, pull-out (N)'),
    (topics.ESTIMATE_BAND, 'controller', 'WrenchStamped: band low, high, grip (N)'),
    (topics.TARGET_FORCE, 'controller', 'WrenchStamped: target grip (N)'),
    (topics.DIAGNOSTICS, 'controller', 'DiagnosticArray (also sim_instrument)'),
    (topics.MEASURED_FORCE, 'sim_instrument', 'WrenchStamped: load cell (N)'),
)
#: The controller's services (its private names) and lifecycle.
SERVICES = (
    (topics.SET_OBJECT_SRV, 'rcl_interfaces/SetParameters (object_kind)'),
    (topics.TARE_SRV, 'std_srvs/Trigger'),
    (topics.CALIBRATE_SRV, 'std_srvs/Trigger'),
    ('~/change_state, ~/get_state, ...', 'lifecycle_msgs (ros2 lifecycle)'),
)
BOX_W, BOX_H = 0.15, 0.22


def _private(name: str, node: str) -> str:
    return name.replace('~', f'/{node}') if name.startswith('~') else name


def draw(out: str):
    """Draw the graph to ``out`` (PNG); return the lines printed (one per edge)."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(13, 6.5))
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.axis('off')
    lines = []
    for name, (x, y) in NODES.items():
        label = f'/{name}'
        if name == 'controller':
            label += '\n(lifecycle node,\nautostart)'
        ax.add_patch(plt.Rectangle((x - BOX_W / 2, y - BOX_H / 2), BOX_W, BOX_H, fc='#dbe8f6',
                                   ec='#2f5d8a', lw=1.5))
        ax.text(x, y, label, ha='center', va='center', fontsize=10, weight='bold')
    for topic, src, dst, y, kind in EDGES:
        x0 = NODES[src][0] + (BOX_W / 2 if NODES[dst][0] > NODES[src][0] else -BOX_W / 2)
        x1 = NODES[dst][0] + (-BOX_W / 2 if NODES[dst][0] > NODES[src][0] else BOX_W / 2)
        ax.annotate('', xy=(x1, y), xytext=(x0, y),
                    arrowprops={'arrowstyle': '->', 'lw': 1.4, 'color': '#333333'})
        ax.text((x0 + x1) / 2, y + 0.012, f'/{topic}', ha='center', va='bottom', fontsize=8.5,
                family='monospace')
        ax.text((x0 + x1) / 2, y - 0.012, kind, ha='center', va='top', fontsize=7, color='#555555')
        lines.append(f'/{topic}: {src} -> {dst} ({kind})')
    for k, (topic, src, kind) in enumerate(OUTPUTS):
        x, y = NODES[src][0], NODES[src][1] - BOX_H / 2
        name = topic if topic.startswith('/') else f'/{topic}'
        if src == 'controller':         # a column under the controller, left-aligned
            yt = 0.36 - 0.07 * k
            ax.text(x + 0.005, yt, f'{name}  ({kind})', ha='left', va='top', fontsize=8,
                    family='monospace')
        else:                           # under the sim, centred on two lines
            yt = 0.40
            ax.text(x, yt, f'{name}\n({kind})', ha='center', va='top', fontsize=8,
                    family='monospace')
        ax.annotate('', xy=(x, yt + 0.02), xytext=(x, y),
                    arrowprops={'arrowstyle': '->', 'lw': 1.0, 'color': '#777777'})
        lines.append(f'{name}: {src} -> any ({kind})')
    sx, sy = NODES['controller'][0], NODES['controller'][1] + BOX_H / 2
    ax.text(sx, 0.98, 'services of /controller', ha='center', va='top', fontsize=9, weight='bold')
    for k, (service, kind) in enumerate(SERVICES):
        name = _private(service, 'controller')
        ax.text(sx, 0.93 - 0.04 * k, f'{name}  [{kind}]', ha='center', va='top', fontsize=8,
                family='monospace')
        lines.append(f'service {name} ({kind})')
    ax.annotate('', xy=(sx, sy), xytext=(sx, 0.93 - 0.04 * len(SERVICES) + 0.005),
                arrowprops={'arrowstyle': '->', 'lw': 1.0, 'color': '#777777'})
    ax.text(0.5, 0.02, 'crtk profile, default namespace; drawn from grip_force_ros/topics.py '
                       '(python -m grip_force_ros.lab.figures.ros_graph)',
            ha='center', fontsize=7.5, color='#555555')
    save(fig, out)
    return lines


def main(argv: list[str] | None = None) -> int:
    """Draw the graph and print its edges (argument: output PNG)."""
    argv = sys.argv[1:] if argv is None else argv
    out = argv[0] if argv else 'docs/figures/ros_graph.png'
    for line in draw(out):
        print(line)
    print(f'wrote {out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
