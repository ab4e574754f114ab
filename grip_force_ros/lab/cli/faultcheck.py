"""`grip-force faultcheck`: run the fault catalogue against the real controller node."""
from __future__ import annotations

HELP = ('inject every catalogued fault into a real controller node (the instrument: a probe, '
        'and the sim_instrument process) and check its outcome; then a negative control')


def add_arguments(parser) -> None:
    parser.add_argument('--json', action='store_true',
                        help='print the report as JSON (with per-case details)')
    parser.add_argument('--config', default=None,
                        help='instrument YAML (path or shipped name) of the controller under test '
                             "(default: the paper's needle driver)")
    parser.add_argument('--only', nargs='*', metavar='PATTERN',
                        help='run only cases whose name or category contains a pattern')
    parser.add_argument('--list', action='store_true', help='list the catalogue and exit')
    parser.add_argument('--plant', choices=('both', 'probe', 'sim_instrument'), default='both',
                        help="the instrument side: the probe's simulation, the shipped sim_instrument "
                             'process (cases that involve the instrument), or both (default)')
    parser.add_argument('--negative-control', choices=('auto', 'on', 'off'), default='auto',
                        help='also run each deliberately broken controller build against the cases '
                             'that must catch it (auto: when the whole catalogue runs)')


def run(args) -> int:
    import json
    import sys

    from grip_force_ros.lab.faults.catalogue import OUTCOMES, catalogue, select

    cases = select(catalogue(), args.only)
    if args.list:
        for c in cases:
            print(f'{c.name:40s} {c.category:20s} {c.outcome:13s} {c.description}')
        print(f'{len(cases)} cases; outcomes:')
        for key, text in OUTCOMES.items():
            print(f'  {key:13s} {text}')
        return 0
    if not cases:
        print('no case matches', args.only, file=sys.stderr)
        return 2

    from grip_force_ros.lab.faults.runner import PLANTS, run_faultcheck

    def progress(detail):
        if args.json:
            return
        if 'defect' in detail:   # negative control: a broken build must be caught
            mark = 'caught' if detail['caught'] else 'MISSED'
            print(f"{mark} defect {detail['defect']:30s} by {sorted(detail['caught_by']) or 'no case'}",
                  flush=True)
            return
        mark = 'ok  ' if detail.get('passed') else 'FAIL'
        extra = f" ({detail['why']})" if not detail.get('passed') else ''
        print(f"{mark} {detail['name']:50s} {detail['outcome']}{extra}", flush=True)

    plants = PLANTS if args.plant == 'both' else (args.plant,)
    negative = args.negative_control == 'on' or (args.negative_control == 'auto' and not args.only)
    report = run_faultcheck(cases, config=args.config, progress=progress, plants=plants,
                            negative_control=negative)
    if args.json:
        print(json.dumps(report, indent=1, default=str))
    else:
        summary = {k: report[k] for k in ('cases', 'passed', 'crashes', 'limit_violations',
                                          'failures', 'seconds')}
        summary['negative_control'] = {k: report['negative_control'][k] for k in ('cases', 'caught')}
        stale = [d for d in report['details'] if d.get('controller_steps_after_timeout')]
        if stale:
            wall = [d['safe_after_last_input_ms'] for d in stale if d.get('safe_after_last_input_ms')]
            print(f"watchdog ({len(stale)} cases): safe at control period "
                  f"<= {max(d['controller_steps_after_timeout'] for d in stale)} after the timeout, "
                  f"{min(wall):.1f}-{max(wall):.1f} ms after the last published input")
        jumps = [d.get('max_resume_jump') or 0.0 for d in report['details']]
        print(f'largest current step at a resume after the safe state: {max(jumps) * 1e3:.3f} mA')
        print(json.dumps(summary))
    negative = report['negative_control']
    ok = (report['passed'] == report['cases'] and report['crashes'] == 0
          and report['limit_violations'] == 0 and negative['caught'] == negative['cases'])
    return 0 if ok else 1
