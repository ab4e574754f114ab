"""Sim-to-real gap diagnosis (numpy/scipy only, no rclpy).

>>> from grip_force_ros.lab.diagnosis import diagnose              # doctest: +SKIP
>>> result = diagnose(['run.mcap'], params=p)                  # doctest: +SKIP
>>> result['verdict']['effect'], result['verdict']['gap_after']  # doctest: +SKIP

``diagnose(train_logs, test_logs=None, params=None, **options) -> dict`` follows the
docs/design.md JSON (verdict, ranking, regions) and adds ``split`` and ``calibration``.
``run_diagnosis`` returns the same plus held-out series for plots;
``write_report`` writes the Markdown report with PNG figures; ``run_blindcheck``
runs the blind check on simulated logs. See docs/diagnosis.md.
"""
from grip_force_ros.lab.diagnosis.effects import EFFECT_NAMES, EFFECTS, NONE
from grip_force_ros.lab.diagnosis.engine import Diagnosis, diagnose, run_diagnosis
from grip_force_ros.lab.diagnosis.frame import DiagnosisError, build_frame, capstan_tension, load_decimated

__all__ = ['EFFECT_NAMES', 'EFFECTS', 'NONE', 'Diagnosis', 'DiagnosisError', 'diagnose', 'run_diagnosis',
           'build_frame', 'capstan_tension', 'load_decimated', 'write_report', 'run_blindcheck']


def write_report(*args, **kwargs):
    """Markdown report with PNG plots (see :func:`grip_force_ros.lab.diagnosis.report.write_report`)."""
    from grip_force_ros.lab.diagnosis.report import write_report as _write
    return _write(*args, **kwargs)


def run_blindcheck(*args, **kwargs):
    """Blind check (see :func:`grip_force_ros.lab.diagnosis.blind.run_blindcheck`)."""
    from grip_force_ros.lab.diagnosis.blind import run_blindcheck as _run
    return _run(*args, **kwargs)
