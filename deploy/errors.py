"""Errors raised by the onboard runtime.

`DeployError` and its subclasses marked `user_error = True` are problems the operator can fix (a bad policy file,
config, port or flag): the CLI prints them as one line and exits 2. Hardware faults are separate classes so the
runtime can count, retry and react to them without confusing them with bad input.
"""


class DeployError(Exception):
    """Bad input to the runtime (policy file, motion file, config, port). The message names the file and problem."""

    user_error = True


class ContractError(DeployError):
    """A policy file does not follow the ONNX contract, or does not match the embodiment."""


class HardwareError(Exception):
    """A device misbehaved at run time. Not a user error: the runtime reacts (retry, reconnect, safe stop)."""

    user_error = False


class HandLinkError(HardwareError):
    """No reply, timeout, bad checksum after retries, or a disconnected hand bus."""


class HandFaultError(HardwareError):
    """The hand itself reports error bits (locked rotor, over-temperature, over-current, motor, communication)."""


class BodyLinkError(HardwareError):
    """The body's low-level link (DDS) is missing, silent, or returns malformed state."""


class MissingDependencyError(DeployError):
    """An optional package (e.g. cyclonedds for the real body) is not installed."""
