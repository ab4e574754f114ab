"""`grip-force import-rig`: convert MRDLab rig runs (XY.TXT) to CSV logs of the data contract."""
from __future__ import annotations

import json
import sys
from pathlib import Path

HELP = 'convert MRDLab rig runs (XY.TXT) to CSV logs (jaw_torque contract), one per run'


def add_arguments(parser) -> None:
    parser.add_argument('directory', nargs='?', default=None,
                        help='rig folder with XY.TXT files (default: '
                             '../shared/data/mis-tool-characterization/Tool_4_Maryland_L_2)')
    parser.add_argument('--out', required=True, metavar='DIR', help='output folder for the CSVs')
    parser.add_argument('--rows', type=int, default=None,
                        help='only the first ROWS samples of each run (quick looks)')
    parser.add_argument('--json', action='store_true', help='print a JSON summary')


def _csv_with_provenance(path: Path, run, log) -> None:
    from grip_force_ros.logs import write_csv
    from grip_force_ros.lab.rig import constants as C
    write_csv(path, log)
    body = path.read_text(encoding='utf-8')
    lines = [f'# {C.ATTRIBUTION}',
             f'# run {run.name}: {run.frequency_hz:g} Hz sine, resisting torque '
             f'{run.torque_level_percent:g} %; jaw_torque N*m closing-positive, angles rad, '
             f'current A closing-positive']
    path.write_text('\n'.join(lines) + '\n' + body, encoding='utf-8')


def run(args) -> int:
    from grip_force_ros.lab.rig import RigDataError, default_data_dir, run_files, read_run, \
        to_contract_log
    from grip_force_ros.lab.rig import constants as C
    directory = Path(args.directory) if args.directory else default_data_dir()
    out = Path(args.out)
    try:
        files = run_files(directory)
    except RigDataError as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for path in files:
        try:
            rig_run = read_run(path, rows=args.rows)
        except RigDataError as exc:
            print(f'error: {exc}', file=sys.stderr)
            return 1
        log = to_contract_log(rig_run)
        dest = out / f'{rig_run.name}.csv'
        _csv_with_provenance(dest, rig_run, log)
        written.append({'run': rig_run.name, 'csv': str(dest), 'rows': len(rig_run),
                        'frequency_hz': rig_run.frequency_hz,
                        'torque_level_percent': rig_run.torque_level_percent,
                        'mean_jaw_torque_mNm': round(float(log['jaw_torque'].mean()) * 1e3, 3)})
        if not args.json:
            print(f'{path.name} -> {dest} ({len(rig_run)} rows, {rig_run.frequency_hz:g} Hz, '
                  f'{rig_run.torque_level_percent:g} %)', file=sys.stderr)
    (out / 'README.md').write_text(
        '# Imported rig runs\n\n' + C.ATTRIBUTION + '\n\nColumns: t (s), current (A, back-end '
        'motor, positive closes), motor_angle (rad, input disk, positive closing), wrist_angle '
        '(rad, 0: not moved on the rig), jaw_angle (rad, 0 = most closed count 885, positive '
        'open), jaw_torque (N*m, positive closing), object (rigid), current_command (A), '
        'motor_shaft_angle (rad, gearbox output), disk_torque (N*m), load_command (A, '
        'front-end), trajectory_angle (rad). See docs/real_data.md.\n', encoding='utf-8')
    if args.json:
        print(json.dumps({'source': str(directory), 'out': str(out), 'runs': written}, indent=1))
    return 0
