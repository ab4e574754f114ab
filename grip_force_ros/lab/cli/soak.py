"""`grip-force soak`: the closed loop at 1 kHz for minutes; memory, timing drift, missed periods."""
from __future__ import annotations

HELP = 'run master, sim and controller for minutes: memory growth, period drift, missed periods'


def add_arguments(parser) -> None:
    parser.add_argument('--minutes', type=float, default=10.0,
                        help='measured duration in minutes (default 10; plus a 15 s warm-up)')
    parser.add_argument('--config', default=None,
                        help='instrument YAML (path or shipped name) of the three processes '
                             "(default: the paper's needle driver)")
    parser.add_argument('--json', action='store_true', help='print the report as JSON')
    parser.add_argument('--out', help='also write the JSON report to this file')


def run(args) -> int:
    import json
    import sys

    from grip_force_ros.lab.faults.soak import run_soak

    if not args.minutes > 0:
        print('error: --minutes must be > 0', file=sys.stderr)
        return 2
    report = run_soak(args.minutes, args.config,
                      progress=lambda text: print(text, file=sys.stderr, flush=True))
    text = json.dumps(report, indent=1)
    if args.out:
        with open(args.out, 'w') as f:
            f.write(text + '\n')
    if args.json:
        print(text)
        return 0
    print(f"soak {report['minutes']:g} min at {report['control_rate_hz']:.0f} Hz ({report['config']})")
    for name, m in report['memory'].items():
        print(f"  RSS {name:24s} {m['rss_start_mb']:8.1f} -> {m['rss_end_mb']:8.1f} MB  "
              f"slope {m['slope_mb_per_min']:+.3f} MB/min")
    for label in ('first', 'last'):
        p = report[f'period_{label}_minute']
        if p:
            print(f"  period {label:5s} minute: mean {p['mean_ms']:.4f} ms, std {p['std_ms']:.4f}, "
                  f"p99 {p['p99_ms']:.3f}, max {p['max_ms']:.2f}, missed {p['missed']}")
    print(f"  missed periods (> 1.5 T) {report['missed_periods']} of {report['commands_received']} "
          f"commands ({report['commands_expected']} expected); controller late_periods "
          f"{report['controller_late_periods']}")
    print(f"  safe-state reports {report['safe_state_reports']}, non-finite commands "
          f"{report['non_finite_commands']}, max |I| {report['max_abs_command_a']} A "
          f"(limit {report['max_current_a']} A)")
    print(f"  CPU % of one core: {report['cpu_percent_of_one_core']}; load average "
          f"{report['load_average_1min']} on {report['cpu_count']} cores")
    return 0
