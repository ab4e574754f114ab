"""Rate independence on real nodes: one demo run per state rate (100 .. 1500 Hz).

The offline table (:mod:`grip_force_ros.lab.bench.state_rate`) is confirmed with the three node
processes over DDS: ``sim_instrument`` publishes at the rate under test (``publish_rate``)
and the controller expects it (``expected_state_rate``); the needle grasp of the demo,
recorded and analysed as ``grip-force demo`` does (:func:`grip_force_ros.lab.demo.run.run_task`;
sensorless, the sim's seeded sensor noise, the machine's own scheduling jitter).

``python -m grip_force_ros.lab.bench.state_rate_nodes [--config YAML] [--rates ...]
[--duration S] [--out DIR]`` prints one Markdown row per rate.
"""
from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from grip_force_ros.lab.bench.state_rate import RATES
from grip_force_ros.lab.demo.run import RunSpec, run_task
from grip_force_ros.lab.processes import pick_domain_ids
from grip_force_ros.params.files import instrument_path


def node_run(config: Path, rate: float, out_dir: Path, duration: float = 5.0) -> dict:
    """Run the demo's needle grasp with states at ``rate`` Hz; return its figures.

    Returns
    -------
    dict
        ``rate_hz``, ``hold_error_rel``, ``hold_error_rms_n``, ``overshoot`` (peak load-cell
        force over hold and pull above the steady target, share), ``settling_s``,
        ``state_rate_measured_hz`` (actuator states per second in the hold), ``problems``.
    """
    spec = RunSpec(config=config, duration=duration, label=f'{rate:g} Hz states',
                   sim_overrides={'publish_rate': rate},
                   controller_overrides={'expected_state_rate': rate})
    result = run_task(spec, out_dir, pick_domain_ids(1)[0], plot=False)
    m, data, windows = result.metrics, result.data, result.windows
    loaded = (data['t'] >= windows['hold'][0]) & (data['t'] <= windows['pull'][1])
    force = data['measured_force'][loaded]
    overshoot = float(np.nanmax(force) / m['target_force'] - 1.0)
    from grip_force_ros.lab.demo.series import read_bag_series
    series, _ = read_bag_series(result.bag)
    t = series['instrument/actuator/measured_js']['t']
    measured = (t.size - 1) / float(t[-1] - t[0]) if t.size > 1 else 0.0   # states per s
    return {'rate_hz': rate, 'hold_error_rel': m['hold_error_rel'],
            'hold_error_rms_n': m['hold_error_rms'], 'overshoot': overshoot,
            'settling_s': m['settling_time'], 'state_rate_measured_hz': measured,
            'problems': result.problems}


def main(argv=None) -> int:
    """Print one row per rate (``python -m grip_force_ros.lab.bench.state_rate_nodes``)."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--config', default=None)
    parser.add_argument('--rates', type=float, nargs='+', default=list(RATES))
    parser.add_argument('--duration', type=float, default=5.0)
    parser.add_argument('--out', default=None)
    args = parser.parse_args(argv)
    config = instrument_path(args.config)
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix='state_rate_nodes_'))
    print('| state rate | measured | hold error | hold rms | overshoot | settling to 5 % | problems |')
    print('|---|---|---|---|---|---|---|')
    for rate in args.rates:
        r = node_run(config, rate, out / f'{rate:g}Hz', args.duration)
        print(f"| {rate:g} Hz | {r['state_rate_measured_hz']:.0f} Hz | "
              f"{100 * r['hold_error_rel']:+.2f} % | {1e3 * r['hold_error_rms_n']:.0f} mN | "
              f"{100 * r['overshoot']:.1f} % | {1e3 * r['settling_s']:.0f} ms | "
              f"{'; '.join(r['problems']) or 'none'} |", flush=True)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
