"""A Ctrl-C as a pybind11 extension lets it out, for the tests of the demo and the monitor."""


def raise_as_pybind11_does(*args, **kwargs):
    """Raise the TypeError pybind11 raises when a Ctrl-C comes while it converts a value.

    rclpy's ``deserialize_message`` raises it so: "Unable to convert function return value
    to a Python type!", caused by the KeyboardInterrupt.
    """
    try:
        raise KeyboardInterrupt
    except KeyboardInterrupt as interrupt:
        raise TypeError('Unable to convert function return value to a Python type!') from interrupt
