r"""The calibration fit as a command: an instrument's parameters from a load-cell grasp log.

    python -m grip_force_ros.identify.command --config X.yaml \
        --log CALIB.mcap|CALIB_DIR|CALIB.csv --out X_calibrated.yaml [--json]

Keeps the steady plateaus of the log (a few force levels), fits the
cable-pulley friction coefficient (or the ``--fit`` parameters) of the
grip-force model by least squares, prints the values with their standard
errors and the residual, and writes the calibrated YAML with a header comment.

The controller's ``~/calibrate`` runs it in a child process (``--json``);
``grip-force calibrate`` is the same command (:data:`HELP`, :func:`add_arguments`,
:func:`run`).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

HELP = 'fit instrument parameters (pulley friction, ...) from a load-cell calibration log'


def add_arguments(parser) -> None:
    parser.add_argument('--config', required=True, help='instrument YAML as shipped')
    parser.add_argument('--log', required=True,
                        help='calibration log: rosbag2 (directory or .mcap/.db3) or CSV')
    parser.add_argument('--out', help='calibrated YAML to write (default: <config>_calibrated.yaml '
                                      'next to the log)')
    parser.add_argument('--fit', default='pulley_friction_coefficient',
                        help='comma-separated schema parameters to fit (default %(default)s)')
    parser.add_argument('--object', default=None,
                        help="object in the jaws (default: the log's 'object' column, else needle)")
    parser.add_argument('--json', action='store_true', help='print the result as JSON')


def run(args) -> int:
    from grip_force_ros.identify import calibrated_yaml, fit_instrument
    from grip_force_ros.logs import LogError, read_log
    from grip_force_ros.params import ParameterError, load_params_file
    from grip_force_ros.params.files import instrument_path

    try:
        config = instrument_path(args.config)
        params = load_params_file(config)
        log = read_log(args.log)
        obj = args.object
        if obj is None and 'object' in log and len(log['object']):
            values = [str(o) for o in log['object'] if str(o)]
            obj = max(set(values), key=values.count) if values else None
        obj = obj or 'needle'
        names = [s.strip() for s in args.fit.split(',') if s.strip()]
        result = fit_instrument(params, log, fit=names, obj=obj)
    except (FileNotFoundError, LogError, ParameterError, ValueError) as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    out = Path(args.out) if args.out else Path(args.log).parent / f'{config.stem}_calibrated.yaml'
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(calibrated_yaml(config, result, args.log))
    report = {**result.as_dict(), 'config': str(config), 'log': str(args.log), 'out': str(out)}
    if args.json:
        print(json.dumps(report, indent=1))
        return 0
    print(f'{params.instrument_name}: {result.n_plateaus} steady plateaus, force levels '
          + ', '.join(f'{f:.2f}' for f in result.force_levels) + f' N ({obj})')
    for name, value in result.values.items():
        print(f'  {name}: {value:.5f} +/- {result.std_errors[name]:.5f} '
              f'(shipped {result.before[name]:.5f})')
    print(f'  residual rms {result.residual_rms:.4f} N '
          f'(shipped: {result.residual_rms_before:.4f} N)')
    print(f'wrote {out}')
    return 0


def main(argv: list[str] | None = None) -> int:
    """Parse ``argv`` (default ``sys.argv[1:]``) and run the fit; returns the exit code."""
    parser = argparse.ArgumentParser(prog='python -m grip_force_ros.identify.command', description=HELP)
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == '__main__':
    sys.exit(main())
