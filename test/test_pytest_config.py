"""The suite's pytest configuration keeps what a failure says."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_a_failed_assertion_keeps_its_whole_message(tmp_path):
    """At the default verbosity (and under ``-q``) pytest cuts a non-string assertion message
    to 240 characters, keeping its two ends. The ROS tests' failure reports are such messages
    (a tuple of the CLI's result and the processes' states and stacks), whose middle matters.
    With the suite's pytest.ini the middle survives. (The inner
    pytest keeps its temporary files here: the user's numbered ones, which keep the last three
    sessions' node logs, are left to the sessions that made them.)"""
    test = tmp_path / 'test_cut.py'
    test.write_text("def test_report():\n"
                    "    assert False, ('x' * 300 + 'MIDDLE' + 'y' * 300, 'report')\n")
    run = subprocess.run([sys.executable, '-m', 'pytest', '-q', '-p', 'no:cacheprovider',
                          '-c', str(ROOT / 'pytest.ini'), '--rootdir', str(tmp_path),
                          '--basetemp', str(tmp_path / 'basetemp'), str(test)],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 1, run.stdout + run.stderr
    message = [line for line in run.stdout.splitlines() if line.startswith('E ')]
    assert any('MIDDLE' in line for line in message), run.stdout
