"""pyserial URL handler `simhand://NAME`: the host's serial port wired in-process to a simulated Inspire device.

deploy's simulated serial hand normally runs a thread on a pseudo-terminal. Under sim2sim that costs a thread
hand-off per request (milliseconds on a busy machine, and several workers share the cores), so the "direct"
hand link keeps the same device object and the same frames but moves the bytes in memory: `write()` gives the
request bytes to the device, which parses them with its own frame parser and answers at once; `read()` returns
the reply bytes. deploy's SerialHandBus opens the URL with pyserial's `serial_for_url` like any port.

Devices are registered by name with `register_device` (sim2sim.hands does it).
"""

from __future__ import annotations

import threading

import serial
from serial.serialutil import PortNotOpenError, SerialBase, SerialException

SCHEME = "simhand://"
_DEVICES: dict[str, object] = {}
_LOCK = threading.Lock()

if "sim2sim" not in serial.protocol_handler_packages:
    serial.protocol_handler_packages.append("sim2sim")


class DeviceLink:
    """Stands in for the device's PtyLink: request bytes in, reply bytes out, nothing on a file descriptor."""

    def __init__(self, name: str):
        self.path = SCHEME + name
        self.to_device = bytearray()
        self.to_host = bytearray()
        self.plugged = True

    def read(self, timeout: float) -> bytes:
        data = bytes(self.to_device)
        self.to_device.clear()
        return data

    def write(self, data: bytes) -> None:
        if self.plugged:
            self.to_host += data

    def plug(self) -> None:
        self.plugged = True

    def unplug(self) -> None:
        self.plugged = False
        self.to_device.clear()
        self.to_host.clear()

    def close(self) -> None:
        self.unplug()


def register_device(name: str, device) -> str:
    """Serve `device` (a deploy SimulatedSerialHand / SimulatedModbusHand, not started) under simhand://name."""
    old_link = getattr(device, "link", None)
    device.link = DeviceLink(name)
    if old_link is not None and hasattr(old_link, "close"):
        old_link.close()  # the pty it opened for its own thread is not needed
    with _LOCK:
        _DEVICES[name] = device
    return device.link.path


def unregister_device(name: str) -> None:
    with _LOCK:
        _DEVICES.pop(name, None)


class Serial(SerialBase):
    """Host end of a simhand:// link."""

    def open(self) -> None:
        if self._port is None:
            raise SerialException("port must be configured before it can be used")
        name = str(self._port)[len(SCHEME):]
        with _LOCK:
            self._device = _DEVICES.get(name)
        if self._device is None or not self._device.link.plugged:
            raise SerialException(f"could not open port {self._port}: no simulated hand there")
        self.is_open = True

    def close(self) -> None:
        self.is_open = False

    def _reconfigure_port(self) -> None:
        return None

    def _link(self) -> DeviceLink:
        if not self.is_open:
            raise PortNotOpenError()
        link = self._device.link
        if not link.plugged:
            raise SerialException("device unplugged")
        return link

    @property
    def in_waiting(self) -> int:
        return len(self._link().to_host)

    def read(self, size: int = 1) -> bytes:
        link = self._link()
        data = bytes(link.to_host[:size])
        del link.to_host[:size]
        return data

    def write(self, data) -> int:
        link = self._link()
        link.to_device += bytes(data)
        self._device._serve_once(0.0)  # the device parses and answers now, in this thread
        return len(data)

    def reset_input_buffer(self) -> None:
        self._link().to_host.clear()

    def reset_output_buffer(self) -> None:
        return None

    def flush(self) -> None:
        return None
