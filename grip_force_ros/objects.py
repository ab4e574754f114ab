"""What the jaw can hold: the one list of object kinds.

``'free'`` is nothing between the jaws (grip force 0); ``'rigid'``, ``'tissue'`` and
``'needle'`` (a 0.5 mm suture needle) each have their contact law in
:mod:`grip_force_ros.model.contact`. The model, the sim, the controller parameter
``object_kind``, the sim parameter ``sim_object``, the log column ``object``, the
diagnosis frames (an object's code is its index here) and the CLIs read this tuple.
Plain data, no imports from the package (the parameter schema reads it).
"""
from __future__ import annotations

__all__ = ['OBJECTS']

#: Object kinds, in the order of their codes (index) in diagnosis frames.
OBJECTS: tuple[str, ...] = ('free', 'rigid', 'tissue', 'needle')
