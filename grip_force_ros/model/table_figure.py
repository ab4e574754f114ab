"""Accuracy of the fitted tables against the exact computation, as numbers and as a figure.

Run: ``.venv/bin/python -m grip_force_ros.model.table_figure [config.yaml] [out.png]``
(defaults: the four-pulley config, ``docs/figures/model_tables_error.png``).
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from grip_force_ros.model.instrument import GripForceModel
from grip_force_ros.params import load_params_file


def table_errors(model: GripForceModel, currents: np.ndarray) -> dict:
    """Relative errors (-) of the vectorised fast path at ``currents`` (A), zero wrist.

    Returns
    -------
    dict
        ``efficiency``: fitted lambda_n against the exact pulley chain;
        ``inverse``: the vectorised inverse of the needle grip force against the
        bracketed scalar solve; ``condition``: ``M / (I dM/dI)``, how much a relative
        error of the torque grows in the current (the floor any solver shares);
        ``table_end_current`` (A): where the inverse table ends (past it: Newton).
    """
    currents = np.asarray(currents, float)
    zero = np.zeros(())
    forward = model.forward(currents, zero, zero, 'needle')
    exact_efficiency = model._chain_efficiency(model.tension_per_amp * currents, zero)
    torque = forward.grip_force * model._tip                                  # N*m (needle: F_J = M / tip)
    exact_current = np.array([model._solve_current(float(t), 0.0, 0.0) for t in torque])
    inverse = model.inverse(forward.grip_force, zero, zero, 'needle')
    slope = np.array([(model._torque_scalar(i * (1 + 1e-7), 0.0) - model._torque_scalar(i, 0.0)) / (i * 1e-7)
                      for i in exact_current])                                 # dM/dI (N*m/A)
    fit = model._current_fit_built()
    return {'efficiency': np.abs(forward.efficiency / exact_efficiency - 1.0),
            'inverse': np.abs(inverse / exact_current - 1.0),
            'condition': torque / (exact_current * slope),
            'table_end_current': None if fit is None else model._solve_current(fit.top, 0.0, 0.0)}


def plot_table_errors(config: str, path: Path, samples: int = 4000) -> Path:
    """Figure of :func:`table_errors` over (0, peak) of M(I) for ``config``; returns ``path``."""
    from grip_force_ros.plotting import pyplot, save
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
    ax.axhline(model.CURRENT_FIT_TOLERANCE, color='C3', ls=':', lw=1, label='table tolerance (checked when built)')
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
    args = argv if argv is not None else sys.argv[1:]
    config = args[0] if args else 'config/four_pulley_needle_driver.yaml'
    out = Path(args[1] if len(args) > 1 else 'docs/figures/model_tables_error.png')
    print(plot_table_errors(config, out))
    return 0


if __name__ == '__main__':
    sys.exit(main())
