"""pydocstyle (PEP 257) over grip_force_ros/ and test/, as ament_pep257 runs it in ROS 2.

Settings: the [pydocstyle] section of setup.cfg (the 'ament' convention for numpydoc
docstrings). Files left out: ``lint_files.EXCLUDED``.
"""
import subprocess
import sys

from lint_files import EXCLUDED, ROOT, lint_files


def test_pep257_is_clean():
    files = lint_files()
    assert len(files) > 100 and len(EXCLUDED) < 20
    run = subprocess.run([sys.executable, '-m', 'pydocstyle', f'--config={ROOT / "setup.cfg"}', *files],
                         cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0 and not run.stderr.strip(), \
        f'pydocstyle findings (settings in setup.cfg):\n{run.stdout}{run.stderr}'
