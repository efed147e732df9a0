"""Inspire hand buses: RS485 vendor frames, Modbus RTU and CAN behind one HandBus interface.

    bus = make_hand_bus("serial", "right", port="/dev/ttyUSB1")
    bus.connect(); bus.configure([1000] * 6, [1000] * 6); bus.write_angles([500] * 6); state = bus.read_state()

`deploy.hands.simulated.start_simulated_hand` starts a device that speaks the same bytes, for tests and sim2sim.
"""

from __future__ import annotations

from collections.abc import Sequence

from deploy.errors import DeployError
from deploy.hands.base import HandBus, HandState

__all__ = ["TRANSPORTS", "HandBus", "HandState", "make_hand_bus"]

TRANSPORTS = ("serial", "modbus", "can")
DEFAULT_BAUDRATE = 115200  # the Inspire hands' factory RS485 setting
DEFAULT_CAN_BITRATE = 1_000_000


def make_hand_bus(
    transport: str,
    side: str,
    *,
    port: str | None = None,
    hand_id: int = 1,
    baudrate: int = DEFAULT_BAUDRATE,
    can_channel: str | None = None,
    can_interface: str | None = None,
    can_bitrate: int = DEFAULT_CAN_BITRATE,
    timeout: float | None = None,
    retries: int = 2,
    safe_pose: str | Sequence[int] = "hold",
    **transport_options,
) -> HandBus:
    """A (not yet connected) bus to one Inspire hand.

    transport "serial": vendor EB 90 frames on RS485 (port = device path or pyserial URL);
    "modbus": Modbus RTU on RS485 (slave id = hand_id); "can": CAN 2.0B on can_channel through any python-can
    interface (can_interface: socketcan (default), slcan, pcan, virtual, ...). timeout (seconds per try) defaults
    per transport; retries = extra tries after the first. safe_pose ("hold", "open" or six angles) is applied by
    disconnect(). Extra keyword options go to the transport class (e.g. chunk_bytes, pipeline for CAN).
    """
    options = dict(hand_id=hand_id, retries=retries, safe_pose=safe_pose, **transport_options)
    if timeout is not None:
        options["timeout"] = timeout
    if transport in ("serial", "modbus"):
        if not port:
            raise DeployError(f"{side} hand: the {transport} transport needs a port (e.g. /dev/ttyUSB1)")
        if transport == "serial":
            from deploy.hands.serial_bus import SerialHandBus

            return SerialHandBus(side, port, baudrate=baudrate, **options)
        from deploy.hands.modbus_bus import ModbusHandBus

        return ModbusHandBus(side, port, baudrate=baudrate, **options)
    if transport == "can":
        if not can_channel:
            raise DeployError(f"{side} hand: the can transport needs can_channel (e.g. can0)")
        from deploy.hands.can_bus import CanHandBus

        return CanHandBus(
            side, can_channel, interface=can_interface or "socketcan", bitrate=can_bitrate, **options
        )
    raise DeployError(f"unknown hand transport {transport!r}; use one of {', '.join(TRANSPORTS)}")
