"""Stop the shipped nodes many times, all at once or one after another, and time their teardowns.

Stop 42's loaded run caught the controller's teardown stuck inside Fast DDS
(``destroy_participant`` -> ``DomainParticipant::set_listener``) while one of its receive
threads, handling another participant's leaving, waited for the listener's mutex; both nodes
had been sent SIGINT at once by ``ProcessGroup.stop``. This tool starts ``sim_instrument``,
``controller`` and ``master`` (the default instrument, the demo's scheduling), lets them run
and match, and stops them with a :class:`~grip_force_ros.nodes.processes.ProcessGroup`,
alternating the two ways (``together``: each signal to all at once, as ``ros2 launch`` does;
``one_at_a_time``: reverse start order, each after the previous one has exited). Per way it
counts the nodes that did not exit with 0, the teardown watch's records in the logs (a
teardown past 3 s) and the teardown times (first signal to exit)::

    .venv/bin/python tools/teardown_overlap.py --cycles 200 --out /tmp/overlap

Every process runs with loopback discovery in a ROS domain this tool holds (``--domain-id``, or
the first free one: :func:`~grip_force_ros.nodes.processes.reserve_domains`).
"""
from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from grip_force_ros.nodes.processes import (DEFAULT_RT_PRIORITY, LEAVE_AFTER_ENV, ProcessGroup,
                                            master_rt_priority, node_command, reserve_domains,
                                            ros_environment, wait_until)

#: The shipped default instrument.
CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'paper_needle_driver.yaml'
NODES = ('sim_instrument', 'controller', 'master')
#: What the teardown watch writes when a teardown runs past its native-stacks time.
WATCH_RECORD = '[teardown] pid'
MODES = ('together', 'one_at_a_time', 'together_ordered')
#: ``together_ordered``: each signal to all at once, as ``ros2 launch``, but each node leaves
#: after the ones grasp.launch.py names for it (GRIP_FORCE_LEAVE_AFTER): the master first,
#: then the controller, then the sim.
LEAVE_AFTER = {'sim_instrument': ('controller', 'master'), 'controller': ('master',)}


def one_cycle(mode: str, env: dict[str, str], log_dir: Path, hold: float,
              rt_priority: int) -> dict:
    """Start the three nodes, let them run ``hold`` s once all have logged, stop them ``mode``'s way."""
    group = ProcessGroup(env, log_dir=log_dir, one_at_a_time=(mode == 'one_at_a_time'))
    with group:
        for name in NODES:
            priority = master_rt_priority(rt_priority) if name == 'master' else rt_priority
            argv = node_command(name, CONFIG)
            if mode == 'together_ordered':      # the same process (exec), its variable set
                argv = ['env', f'{LEAVE_AFTER_ENV}={",".join(LEAVE_AFTER.get(name, ()))}', *argv]
            group.start(name, argv, rt_priority=priority)
        up = wait_until(lambda: all('[INFO]' in p.log_tail(200) for p in group.processes), 60.0, 0.05)
        group.check_alive()
        time.sleep(hold)
        codes = group.stop()
    logs = {p.name: (log_dir / f'{p.name}.log').read_text(errors='replace') for p in group.processes}
    return {'mode': mode, 'up': up, 'codes': codes, 'stop_times': dict(group.stop_times),
            'watch_records': [name for name, text in logs.items() if WATCH_RECORD in text],
            # together_ordered: nodes that stopped before their peers had left (waited 3 s)
            'left_with_peers_up': [name for name, text in logs.items() if ': leaving with ' in text]}


def summary(cycles: list[dict]) -> dict:
    """Per way of stopping: counts, and the teardown times (s) over every node stopped."""
    out = {}
    for mode in MODES:
        mine = [c for c in cycles if c['mode'] == mode]
        if not mine:
            continue
        times = np.array([t for c in mine for t in c['stop_times'].values()])
        per_node = {name: np.array([c['stop_times'][name] for c in mine if name in c['stop_times']])
                    for name in NODES}
        out[mode] = {
            'cycles': len(mine),
            'not_exit_0': sum(code != 0 for c in mine for code in c['codes'].values()),
            'watch_records': sum(len(c['watch_records']) for c in mine),
            'left_with_peers_up': sum(len(c.get('left_with_peers_up', ())) for c in mine),
            'stop_time_s': ({'p50': float(np.percentile(times, 50)), 'p99': float(np.percentile(times, 99)),
                             'max': float(times.max()), 'over_1s': int((times > 1.0).sum())}
                            if times.size else {}),
            'stop_time_max_s_by_node': {name: float(v.max()) for name, v in per_node.items() if v.size},
        }
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--cycles', type=int, default=100, help='start/stop cycles (the ways alternate)')
    parser.add_argument('--modes', nargs='+', choices=MODES, default=list(MODES[:2]),
                        help='ways of stopping, taken in turn (default: together one_at_a_time)')
    parser.add_argument('--hold', type=float, default=1.0, help='running time (s) once all have logged')
    parser.add_argument('--rt-priority', type=int, default=DEFAULT_RT_PRIORITY,
                        help='SCHED_FIFO priority of the nodes where permitted (0: normal), as the demo')
    parser.add_argument('--domain-id', type=int, help='ROS domain of the nodes (default: a free one)')
    parser.add_argument('--out', help='folder for the JSON lines and the logs of failed cycles')
    parser.add_argument('--keep-logs', action='store_true', help='keep every cycle\'s logs')
    args = parser.parse_args(argv)
    out = Path(args.out or tempfile.mkdtemp(prefix='teardown_overlap_'))
    out.mkdir(parents=True, exist_ok=True)
    domain = reserve_domains(1, candidates=None if args.domain_id is None else [args.domain_id])
    env = ros_environment(domain.domain_id)
    cycles = []
    with domain, open(out / 'cycles.jsonl', 'a') as record:
        for index in range(args.cycles):
            mode = args.modes[index % len(args.modes)]
            log_dir = out / f'cycle{index:04d}'
            cycle = one_cycle(mode, env, log_dir, args.hold, args.rt_priority)
            cycle['index'] = index
            cycles.append(cycle)
            record.write(json.dumps(cycle) + '\n')
            record.flush()
            bad = cycle['watch_records'] or any(code != 0 for code in cycle['codes'].values())
            if bad:
                print(f'cycle {index} ({mode}): codes {cycle["codes"]}, watch records '
                      f'{cycle["watch_records"]}; logs in {log_dir}', flush=True)
            elif not args.keep_logs:
                shutil.rmtree(log_dir, ignore_errors=True)
    result = summary(cycles)
    (out / 'summary.json').write_text(json.dumps(result, indent=2))
    print(json.dumps(result, indent=2))
    return 0


if __name__ == '__main__':
    sys.exit(main())
