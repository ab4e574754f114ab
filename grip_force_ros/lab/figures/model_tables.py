"""Figure of docs/model.md (speed): accuracy of the fitted tables against the exact model.

Run: ``.venv/bin/python -m grip_force_ros.lab.figures.model_tables [config.yaml] [out.png]``
(defaults: the four-pulley config, ``docs/figures/model_tables_error.png``). The
numbers come from :func:`grip_force_ros.model.tables.table_errors`.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from grip_force_ros.model import GripForceModel
from grip_force_ros.model.tables import table_errors
from grip_force_ros.params import load_params_file
from grip_force_ros.lab.plotting import pyplot, save


def plot_table_errors(config: str, path: Path, samples: int = 4000) -> Path:
    """Figure of :func:`table_errors` over (0, peak) of M(I) for ``config``; returns ``path``."""
    params = load_params_file(config)
    model = GripForceModel(params)
    rising = model._rising_current()                                           # A
    currents = np.linspace(rising / samples, rising, samples)
    errors = table_errors(model, currents)
    eps = np.finfo(float).eps
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    ax.semilogy(currents, np.maximum(errors['efficiency'], eps / 8), '.', ms=2, color='C0',
                label='forward: fitted $\\lambda_n$ vs exact pulley chain')
    ax.semilogy(currents, np.maximum(errors['inverse'], eps / 8), '.', ms=2, color='C1',
                label='inverse: table (+ Newton past its end) vs bracketed scalar solve')
    ax.semilogy(currents, eps * errors['condition'], '-', color='0.4', lw=1,
                label='machine epsilon x condition M/(I dM/dI)')
    ax.axhline(model.CURRENT_FIT_TOLERANCE, color='C3', ls=':', lw=1,
               label='table tolerance (checked when built)')
    if errors['table_end_current'] is not None:
        ax.axvline(errors['table_end_current'], color='C1', ls='--', lw=1)
        ax.text(errors['table_end_current'], 3e-12, ' inverse table ends\n (Newton past it)', color='C1',
                fontsize=8, va='top')
    ax.axvline(params.max_current, color='k', ls='--', lw=1)
    ax.text(params.max_current, 3e-12, ' max_current', fontsize=8, va='top')
    ax.set_ylim(1e-17, 1e-9)
    ax.set_xlabel('motor current I (A), up to 2 max_current or just below the peak of M(I)')
    ax.text(0.99, 0.02, 'exact agreement (0) drawn at eps/8', transform=ax.transAxes, ha='right',
            fontsize=7, color='0.3')
    ax.set_ylabel('relative error (-)')
    ax.set_title(f'{Path(config).stem}: fitted tables against the exact model', fontsize=10)
    ax.legend(fontsize=8, loc='upper left', ncol=2)
    return save(fig, Path(path))


def main(argv: list[str] | None = None) -> int:
    """Write the figure (arguments: config YAML, output PNG) and print its path."""
    args = argv if argv is not None else sys.argv[1:]
    config = args[0] if args else 'config/four_pulley_needle_driver.yaml'
    out = Path(args[1] if len(args) > 1 else 'docs/figures/model_tables_error.png')
    print(plot_table_errors(config, out))
    return 0


if __name__ == '__main__':
    sys.exit(main())
