r"""Stop node executables with SIGINT, again and again, and count the errors their logs show.

Each run starts one executable (``sim_instrument``, ``controller`` or ``master``, the console
script beside an interpreter) from this Python process, in a ROS domain of its own with
loopback discovery, waits for its first log line and ``--after`` s more, sends SIGINT, and
records the exit code, the seconds from SIGINT to exit, and whether the log shows an error:
a traceback, or the EventsExecutor's lines for an exception it caught in a callback
(``[FATAL] ... Exception in 'timers' callback:`` then ``Error occurred at:``). Several
``--python`` interpreters (two virtual environments, two versions of the package) are
alternated run by run, in ABBA order, so that a drifting machine loads each alike::

    .venv/bin/python tools/stop_check.py --exe sim_instrument --runs 16 \
        --python /path/old/.venv/bin/python --python .venv/bin/python

Started as a background job of a shell, a node would inherit SIGINT ignored; started from
here it does not (docs/reliability.md, twenty-first round: stop 36's tries saw no error for
that reason). Run it beside ``grip-force load`` for a loaded machine.
"""
from __future__ import annotations

import argparse
import json
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from grip_force_ros.nodes.processes import log_errors, reserve_domains, ros_environment

#: Longest wait for a node's first log line, and for its exit after SIGINT (s).
START_LIMIT = 90.0
EXIT_LIMIT = 60.0


def stop_once(python: str, exe: str, after: float, domain_id: int, log: Path) -> dict:
    """Start ``exe`` under ``python``, SIGINT it ``after`` s after its first line; the outcome."""
    script = str(Path(python).parent / exe)
    with open(log, 'w') as out:
        proc = subprocess.Popen([python, script], stdout=out, stderr=subprocess.STDOUT,
                                env=ros_environment(domain_id))
    started = time.monotonic()
    while not log.read_text(errors='replace').strip() and time.monotonic() - started < START_LIMIT:
        time.sleep(0.05)
    time.sleep(after)
    sent = time.monotonic()
    proc.send_signal(signal.SIGINT)
    try:
        code = proc.wait(timeout=EXIT_LIMIT)
    except subprocess.TimeoutExpired:
        proc.kill()
        code = proc.wait()
    text = log.read_text(errors='replace')
    return {'python': python, 'exit_code': code, 'exit_s': round(time.monotonic() - sent, 3),
            'errors': log_errors(text)[:4],
            'log': str(log)}


def main(argv: list[str] | None = None) -> int:
    """Run the stops and print one line each, then a summary per interpreter."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--exe', default='sim_instrument', choices=['sim_instrument', 'controller', 'master'])
    parser.add_argument('--runs', type=int, default=8, help='stops in all (default 8)')
    parser.add_argument('--after', type=float, default=2.0,
                        help='seconds from the first log line to SIGINT (default 2)')
    parser.add_argument('--python', action='append', default=None,
                        help='interpreter of a virtual environment with the package (repeat to A/B; '
                             'default: this one)')
    parser.add_argument('--json', action='store_true', help='print the summary as JSON')
    args = parser.parse_args(argv)
    pythons = args.python or [sys.executable]
    results: dict[str, list[dict]] = {p: [] for p in pythons}
    with reserve_domains(1) as held, tempfile.TemporaryDirectory(prefix='stop_check_') as tmp:
        for run in range(args.runs):
            turn = run // len(pythons)
            python = pythons[(run % len(pythons)) if turn % 2 == 0 else (-1 - run % len(pythons))]
            outcome = stop_once(python, args.exe, args.after, held.ids[0], Path(tmp) / f'run{run}.log')
            results[python].append(outcome)
            if not args.json:
                seen = f"errors: {outcome['errors'][0]}" if outcome['errors'] else 'clean log'
                print(f"run {run}: {python}: exit {outcome['exit_code']} {outcome['exit_s']:.2f} s "
                      f"after SIGINT; {seen}", flush=True)
    summary = {python: {'stops': len(runs), 'with_errors': sum(bool(r['errors']) for r in runs),
                        'nonzero_exits': sum(r['exit_code'] != 0 for r in runs),
                        'exit_s_mean': round(sum(r['exit_s'] for r in runs) / len(runs), 3) if runs else None,
                        'exit_s_max': max((r['exit_s'] for r in runs), default=None)}
               for python, runs in results.items()}
    if args.json:
        print(json.dumps({'exe': args.exe, 'after_s': args.after, 'interpreters': summary}, indent=1))
    else:
        for python, s in summary.items():
            print(f"{python}: {s['with_errors']} of {s['stops']} stops with an error in the log, "
                  f"{s['nonzero_exits']} nonzero exits, SIGINT to exit {s['exit_s_mean']} s mean, "
                  f"{s['exit_s_max']} s max")
    return 0


if __name__ == '__main__':
    sys.exit(main())
