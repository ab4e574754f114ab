"""Speed of the simulated instrument: cost of one 1 kHz control step (numpy only, no rclpy).

Run: ``.venv/bin/python -m grip_force_ros.lab.bench.sim_step`` (target: < 100 us per 1 ms
step, the sim node runs it in real time on a 2-core machine next to the controller).
Prints ``step() + measure()`` per object with the effects off, then on the needle with
every effect of :data:`grip_force_ros.sim.effects.EFFECT_NAMES` on at once.
"""
from __future__ import annotations

import math
import time

from grip_force_ros.effects import strengths_at
from grip_force_ros.params import make_params
from grip_force_ros.sim.plant import OBJECTS, InstrumentSim


def all_effects_on() -> dict[str, float]:
    """Every effect the sim has, at the effect registry's medium strength (each in its unit)."""
    return strengths_at('medium')


def time_steps(effects=None, obj='needle', steps=5000, dt=1e-3, repeats=3) -> float:
    """Best-of-``repeats`` mean wall time of ``step(); measure()`` (s per control step of ``dt`` s)."""
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


def main() -> int:
    """Print the cost of a 1 ms step per object, effects off, then needle with all effects."""
    all_on = all_effects_on()
    p = make_params()
    print(f'sim_rate {p.sim_rate:.0f} Hz -> {math.ceil(1e-3 * p.sim_rate)} sub-steps per 1 ms step')
    for obj in OBJECTS:
        print(f'{obj:7s} effects off : {time_steps(obj=obj) * 1e6:7.1f} us per 1 ms step (step + measure)')
    print(f'needle  all {len(all_on)} effects: {time_steps(all_on) * 1e6:7.1f} us per 1 ms step '
          '(step + measure)')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
