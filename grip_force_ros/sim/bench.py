"""Benchmark of the simulated instrument: cost of one 1 kHz control step (prints figures).

Run: ``.venv/bin/python -m grip_force_ros.sim.bench`` (target: < 100 us per 1 ms step,
the sim node runs it in real time on a 2-core machine next to the controller).
"""
from __future__ import annotations

import math
import time

from grip_force_ros.effects import strengths_at
from grip_force_ros.params import make_params
from grip_force_ros.sim.effects import EFFECT_NAMES
from grip_force_ros.sim.plant import OBJECTS, InstrumentSim

ALL_ON = strengths_at('medium')   # every effect the sim has, at the registry's medium strength


def time_steps(effects=None, obj='needle', steps=5000, dt=1e-3, repeats=3) -> float:
    """Best-of-``repeats`` mean wall time of ``step(); measure()`` (s per control step)."""
    best = math.inf
    params = make_params()
    for _ in range(repeats):
        sim = InstrumentSim(params, obj=obj, effects=effects, seed=0)
        start = time.perf_counter()
        for k in range(steps):
            sim.step(0.25 + 0.15 * math.sin(k * 0.003), dt)
            sim.measure()
        best = min(best, (time.perf_counter() - start) / steps)
    return best


def main() -> None:
    assert set(ALL_ON) == set(EFFECT_NAMES)
    p = make_params()
    print(f'sim_rate {p.sim_rate:.0f} Hz -> {math.ceil(1e-3 * p.sim_rate)} sub-steps per 1 ms step')
    for obj in OBJECTS:
        print(f'{obj:7s} effects off : {time_steps(obj=obj) * 1e6:7.1f} us per 1 ms step (step + measure)')
    print(f'needle  all effects: {time_steps(ALL_ON) * 1e6:7.1f} us per 1 ms step (step + measure)')


if __name__ == '__main__':
    main()
