"""The page-fault measurement of the node processes (grip_force_ros/lab/bench/page_faults.py)."""
import os
import subprocess
import sys

from grip_force_ros.lab.bench.page_faults import proc_stat, status_mib


def test_it_reads_faults_cpu_and_memory_of_a_process():
    minor, major, cpu = proc_stat(os.getpid())
    assert minor > 0 and major >= 0 and cpu > 0
    assert status_mib(os.getpid(), 'VmRSS') > 0 and status_mib(os.getpid(), 'NoSuchKey') == 0


def test_it_runs_as_a_module():
    run = subprocess.run([sys.executable, '-m', 'grip_force_ros.lab.bench.page_faults', '--help'],
                         capture_output=True, text=True, timeout=60)
    assert run.returncode == 0 and '--lock' in run.stdout
