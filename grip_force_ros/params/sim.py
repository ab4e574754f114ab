"""Simulated-instrument parameters (groups 'sim' and 'effects'). Owned by sim/."""
from grip_force_ros.params.schema import ParamSpec  # noqa: F401

SIM: list = []
EFFECTS: list = []
