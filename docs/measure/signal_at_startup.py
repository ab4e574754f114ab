"""How often a signal sent while a Python process starts is lost (docs/reliability.md).

Starts ``python -c "import time; time.sleep(120)"`` (this interpreter, so this venv's ``.pth``
files run at start-up), sends it one signal at a random time in its first ``--window`` ms,
and counts the children still alive ``--wait`` s later: those lost the signal. A child that
lost a SIGINT writes "Exception ignored in: <function _get_module_lock.<locals>.cb ...>
KeyboardInterrupt" (Python discards what a weakref callback raises); the first such message
is printed.

    .venv/bin/python docs/measure/signal_at_startup.py --signal INT --trials 1500
    .venv/bin/python docs/measure/signal_at_startup.py --signal TERM --trials 1500

Seeded (``--seed``); one child at a time.
"""
from __future__ import annotations

import argparse
import random
import signal
import subprocess
import sys
import tempfile
import time


def trial(sig: int, delay: float, wait: float, err_path: str) -> bool:
    """Start one child, signal it after ``delay`` s; return whether it lived on (signal lost)."""
    with open(err_path, 'w') as err:
        child = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(120)'],
                                 stderr=err, stdin=subprocess.DEVNULL,
                                 preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    start = time.perf_counter()
    while time.perf_counter() - start < delay:   # busy wait: sleep's resolution is too coarse
        pass
    child.send_signal(sig)
    try:
        child.wait(timeout=wait)
        return False
    except subprocess.TimeoutExpired:
        child.kill()
        child.wait()
        return True


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--signal', default='INT', help='signal name without SIG (default INT)')
    parser.add_argument('--trials', type=int, default=1500)
    parser.add_argument('--window', type=float, default=30.0, help='ms after the start (default 30)')
    parser.add_argument('--wait', type=float, default=3.0, help='s a child has to end (default 3)')
    parser.add_argument('--seed', type=int, default=1)
    args = parser.parse_args(argv)
    sig = signal.Signals['SIG' + args.signal.upper()]
    rng = random.Random(args.seed)
    lost: list[float] = []
    first_message = ''
    with tempfile.NamedTemporaryFile(suffix='.err') as err:
        for _ in range(args.trials):
            delay = rng.uniform(0.0, args.window / 1000.0)
            if trial(sig, delay, args.wait, err.name):
                lost.append(delay)
                if not first_message:
                    with open(err.name) as text:
                        first_message = text.read().strip()
    print(f'{sig.name}: lost {len(lost)} of {args.trials} '
          f'(sent 0-{args.window:g} ms after the start; at {sorted(round(d * 1e3, 1) for d in lost)} ms)')
    if first_message:
        print('first lost child wrote:\n' + first_message)
    return 0


if __name__ == '__main__':
    sys.exit(main())
