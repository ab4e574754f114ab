"""Controller parameters (group 'controller'). Owned by control/; see control/README."""
from grip_force_ros.params.schema import ParamSpec  # noqa: F401

CONTROLLER: list = []
