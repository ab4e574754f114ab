"""flake8 (pycodestyle + pyflakes) over grip_force_ros/ and test/, as ament_flake8 runs it in ROS 2.

Settings: the [flake8] section of setup.cfg. Files left out: ``lint_files.EXCLUDED``.
"""
import subprocess
import sys

from lint_files import EXCLUDED, ROOT, lint_files


def test_flake8_is_clean():
    files = lint_files()
    assert len(files) > 100 and len(EXCLUDED) < 20
    run = subprocess.run([sys.executable, '-m', 'flake8', '--config', str(ROOT / 'setup.cfg'), *files],
                         cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0 and not run.stderr.strip(), \
        f'flake8 findings (settings in setup.cfg):\n{run.stdout}{run.stderr}'
