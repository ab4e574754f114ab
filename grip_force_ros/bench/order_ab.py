"""A/B of the loop's publish order: round trip and full path, interleaved rounds (rclpy; prints figures).

The two narrowing choices of the loop (the sim sends the joint state and load cell only
once the command answering the actuator state came in; the controller sends its estimated
and target force only after the loop has closed) against the plain order (the sim sends
the jaw and the load cell of a sample before its actuator state, the controller its forces
right after the command). Each round measures the floor once, then every variant's product
(:func:`grip_force_ros.bench.loop.run_product`), the variants in a rotated order per round,
all in one ROS domain, so that the rounds see the same machine state::

    .venv/bin/python -m grip_force_ros.bench.order_ab --rounds 3 --seconds 20
    .venv/bin/python -m grip_force_ros.bench.order_ab --rounds 3 --seconds 20 \
        --variants plain,no_forces,lean,timer_250 [--rt-priority 50]

Prints one JSON line per run as it goes (stderr) and the whole result (stdout): per variant
the mean and the worst over the rounds of the full-path and round-trip p99 ratios and of the
missed periods above the floor's.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from dataclasses import replace

from grip_force_ros.bench.loop import BEST, compare, run_floor, run_product
from grip_force_ros.bench.procs import DomainLock
from grip_force_ros.bench.run import parse_domains
from grip_force_ros.params.files import instrument_path

#: name -> (the sim's sensor order, the controller's force outputs, further controller
#: parameters): both narrowing choices, one of them at a time, neither (the shipped
#: order: plain); then, on the plain order, what the controller's own work on the path costs
#: (BENCHMARKS.md, 2026-11-27): no force output at all, the watchdog timer at 250 Hz, both.
VARIANTS = {
    'narrowed': ('deferred', 'deferred', {}),
    'sensors_first': ('first', 'deferred', {}),
    'forces_at_once': ('deferred', 'at-once', {}),
    'plain': ('first', 'at-once', {}),
    'no_forces': ('first', 'off', {}),
    'timer_250': ('first', 'at-once', {'control_rate': 250.0}),
    'lean': ('first', 'off', {'control_rate': 250.0}),
}
#: The publish-order A/B (the default of ``--variants``).
ORDER_VARIANTS = ('narrowed', 'sensors_first', 'forces_at_once', 'plain')


def _row(name: str, loop: dict) -> dict:
    full = loop['full_path']
    return {'variant': name, 'load_average_1min': os.getloadavg()[0],
            'floor_p50_ms': loop['floor']['p50_ms'], 'floor_p99_ms': loop['floor']['p99_ms'],
            'product_p50_ms': loop['product']['p50_ms'], 'product_p99_ms': loop['product']['p99_ms'],
            'full_path_p50_ms': full['p50_ms'], 'full_path_p99_ms': full['p99_ms'],
            'full_path_max_ms': full['max_ms'], 'p99_ratio': loop['p99_ratio'],
            'full_path_p99_ratio': loop['full_path_p99_ratio'],
            'missed_fraction': loop['missed_fraction'],
            'floor_missed_fraction': loop['floor_missed_fraction'],
            'jaw_same_sample_fraction': full['inputs']['jaw']['same_sample_fraction'],
            'load_cell_same_sample_fraction': full['inputs']['load_cell']['same_sample_fraction'],
            'cpu_percent': loop['cpu_percent']['product']}


def run_ab(rounds: int, seconds: float, variants=ORDER_VARIANTS, config: str | None = None,
           domains=None, rt_priority: int = 0, say=None) -> dict:
    """Measure ``rounds`` interleaved rounds: the floor, then each variant (rotated order).

    Returns
    -------
    dict
        ``runs`` (one row per product run, with its round's floor) and ``summary``:
        per variant the mean and worst (largest) ``full_path_p99_ratio``, ``p99_ratio``
        and ``missed_over_floor`` (missed fraction minus the floor's) over the rounds.
    """
    say = say or (lambda msg: None)
    config = str(instrument_path(config))
    runs = []
    with DomainLock(domains) as domain:
        for k in range(rounds):
            floor = run_floor(seconds, domain, replace(BEST, rt_priority=rt_priority))
            order = list(variants[k % len(variants):]) + list(variants[:k % len(variants)])
            for name in order:
                sensor_order, force_outputs, controller_params = VARIANTS[name]
                product = run_product(seconds, domain, config, rt_priority=rt_priority,
                                      sensor_order=sensor_order, force_outputs=force_outputs,
                                      controller_params=controller_params)
                row = {'round': k, **_row(name, compare(floor, product))}
                say(json.dumps(row))
                runs.append(row)
    summary = {}
    for name in variants:
        rows = [r for r in runs if r['variant'] == name]
        figures = {'full_path_p99_ratio': [r['full_path_p99_ratio'] for r in rows],
                   'p99_ratio': [r['p99_ratio'] for r in rows],
                   'missed_over_floor': [r['missed_fraction'] - r['floor_missed_fraction'] for r in rows]}
        summary[name] = {key: {'mean': sum(v) / len(v), 'worst': max(v)} for key, v in figures.items() if v}
    return {'rounds': rounds, 'seconds': seconds, 'config': config, 'rt_priority': rt_priority,
            'runs': runs, 'summary': summary}


def main(argv: list[str] | None = None) -> int:
    """Run :func:`run_ab` with the command-line options and print its result as JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--rounds', type=int, default=3)
    parser.add_argument('--seconds', type=float, default=20.0, help='window of each run (s)')
    parser.add_argument('--variants', default=','.join(ORDER_VARIANTS),
                        help=f'comma-separated subset of {list(VARIANTS)}')
    parser.add_argument('--config', default=None, help='instrument YAML (path or shipped name)')
    parser.add_argument('--domain-ids', default=None, help="candidate ROS domains, e.g. '70-99'")
    parser.add_argument('--rt-priority', type=int, default=0,
                        help='SCHED_FIFO priority of the 1 kHz processes of floor and product (0: normal)')
    args = parser.parse_args(argv)
    variants = tuple(v.strip() for v in args.variants.split(',') if v.strip())
    unknown = [v for v in variants if v not in VARIANTS]
    if unknown:
        parser.error(f'unknown variant(s) {unknown}')
    result = run_ab(args.rounds, args.seconds, variants, args.config, parse_domains(args.domain_ids),
                    args.rt_priority, say=lambda msg: print(msg, file=sys.stderr, flush=True))
    print(json.dumps(result, indent=2))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
