"""Round trip of a state -> command loop, measured where the states are published.

The instrument (here the sim node, on hardware its driver) stamps each state it
publishes; the controller's command carries the stamp of the state it was
computed from (docs/ros_interface.md). The instrument's own clock then gives the
round trip of every command exactly: arrival minus stamp, no clock sync needed.

Plain values in (integer nanoseconds), plain values out; no rclpy.
"""
from __future__ import annotations

from collections import deque

import numpy as np


class LoopLatency:
    """Round trips of commands that answer recently published states.

    Parameters
    ----------
    memory : int
        How many of the newest state stamps are remembered (a command answering an
        older state is counted in ``other_commands``); at 1 kHz, 256 = 0.256 s.
    capacity : int
        Round trips kept between two :meth:`summary` calls (older ones are dropped).
    """

    def __init__(self, memory: int = 256, capacity: int = 4096):
        self._recent: deque[int] = deque(maxlen=memory)   # ns, stamps of the newest states
        self._waiting: set[int] = set()                    # ns, those not answered yet
        self._round_trips = np.zeros(capacity, np.int64)   # ns
        self._n = 0
        self.states = 0            # states published (since the last summary)
        self.answered = 0          # states answered by at least one command
        self.unanswered = 0        # states that left the memory without an answer
        self.other_commands = 0    # commands carrying no remembered, unanswered stamp

    def state_published(self, stamp_ns: int) -> None:
        """Note a published state's stamp (ns)."""
        recent = self._recent
        if len(recent) == recent.maxlen:
            oldest = recent[0]
            if oldest in self._waiting:
                self._waiting.discard(oldest)
                self.unanswered += 1
        recent.append(stamp_ns)
        self._waiting.add(stamp_ns)
        self.states += 1

    def command_received(self, stamp_ns: int, arrival_ns: int) -> int | None:
        """Note a command's arrival (``arrival_ns`` on the states' clock); its round trip (ns) or None.

        None when the command does not answer a remembered, still unanswered state
        (a timer-fallback command stamped with the controller's clock, a second
        answer to the same state, or an answer to a forgotten one).
        """
        if stamp_ns not in self._waiting:
            self.other_commands += 1
            return None
        self._waiting.discard(stamp_ns)
        self.answered += 1
        round_trip = arrival_ns - stamp_ns
        if self._n < self._round_trips.size:
            self._round_trips[self._n] = round_trip
            self._n += 1
        return round_trip

    def summary(self, reset: bool = True) -> dict:
        """Round-trip figures since the last reset.

        Returns
        -------
        dict
            ``round_trips``, ``p50_ms``, ``p99_ms``, ``max_ms`` (ms; NaN without a
            sample), ``states``, ``answered``, ``unanswered``, ``other_commands``.
        """
        rt = self._round_trips[:self._n] * 1e-6                     # ms
        if rt.size:
            p50, p99 = np.percentile(rt, [50.0, 99.0])
            peak = rt.max()
        else:
            p50 = p99 = peak = float('nan')
        out = {'round_trips': int(rt.size), 'p50_ms': float(p50), 'p99_ms': float(p99),
               'max_ms': float(peak), 'states': self.states, 'answered': self.answered,
               'unanswered': self.unanswered, 'other_commands': self.other_commands}
        if reset:
            self._n = 0
            self.states = self.answered = self.unanswered = self.other_commands = 0
        return out
