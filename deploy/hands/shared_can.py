"""One python-can Bus per CAN channel, shared by every hand on it, with replies routed by hand id.

Two Bus objects on one channel do not work everywhere: over an slcan, pcan or gs_usb adapter both would read and
write the same USB device and garble each other's stream. So the first hand on a channel opens the Bus, later
ones attach to it; one reader thread receives every frame and puts it in the queue of the hand whose id is in
the frame's low 14 bits (error frames go to every hand). Sends are serialised with a lock.

At this boundary every exception the driver raises is a link fault, not only can.CanError: python-can's slcan
parser raises ValueError or IndexError on a garbled stream, and the serial layer OSError or termios.error. A
fault marks the link broken and wakes every hand waiting on it; the next attach (a hand reopening its link)
reopens the Bus once for all of them.
"""

from __future__ import annotations

import logging
import queue
import socket
import struct
import threading

import can

from deploy.hands.can_frames import MAX_HAND_ID

log = logging.getLogger("deploy.hands")

OPEN_ERRORS = (can.CanError, OSError, ValueError, ImportError, NotImplementedError)
SOL_CAN_RAW = getattr(socket, "SOL_CAN_RAW", 101)  # linux/can.h: SOL_CAN_BASE + CAN_RAW
CAN_RAW_ERR_FILTER = 2  # linux/can/raw.h; Python's socket module does not export it
CAN_ERR_MASK = getattr(socket, "CAN_ERR_MASK", 0x1FFFFFFF)
RECV_POLL_S = 0.05  # how long the reader waits per recv before checking for close


class LinkBroken(Exception):
    """The shared Bus failed; `str()` says how. Put in a hand's queue to wake it."""


class SharedCanBus:
    _registry: dict[tuple[str, str], SharedCanBus] = {}
    _registry_lock = threading.Lock()

    def __init__(self, interface: str, channel: str, bitrate: int, options: dict):
        self.interface, self.channel, self.bitrate, self.options = interface, channel, bitrate, dict(options)
        self.queues: dict[int, queue.SimpleQueue] = {}
        self.broken: str | None = None
        self._bus: can.BusABC | None = None
        self._reader: threading.Thread | None = None
        self._stop = threading.Event()
        self._send_lock = threading.Lock()
        self._lock = threading.Lock()

    # ----------------------------------------------------------------- sharing
    @classmethod
    def attach(cls, interface: str, channel: str, bitrate: int, options: dict, hand_id: int) -> tuple:
        """(shared bus, this hand's reply queue); opens (or reopens a broken) Bus. Raises OPEN_ERRORS."""
        with cls._registry_lock:
            shared = cls._registry.get((interface, channel))
            if shared is None:
                shared = cls(interface, channel, bitrate, options)
                cls._registry[(interface, channel)] = shared
            with shared._lock:
                if hand_id in shared.queues:
                    raise ValueError(f"CAN hand id {hand_id} is already attached on {interface}:{channel}")
                if shared._bus is None or shared.broken:
                    try:
                        shared._open()
                    except BaseException:
                        if not shared.queues:
                            del cls._registry[(interface, channel)]
                        raise
                shared.queues[hand_id] = queue.SimpleQueue()
                shared._set_filters()
                return shared, shared.queues[hand_id]

    def detach(self, hand_id: int) -> None:
        with self._registry_lock, self._lock:
            self.queues.pop(hand_id, None)
            if self.queues:
                self._set_filters()
                return
            self._registry.pop((self.interface, self.channel), None)
            self._close()

    # ----------------------------------------------------------------- the Bus
    def _open(self) -> None:
        self._close()
        self._bus = can.Bus(interface=self.interface, channel=self.channel, bitrate=self.bitrate, **self.options)
        self.broken = None
        self._receive_error_frames()
        self._stop = threading.Event()
        self._reader = threading.Thread(target=self._read, args=(self._bus, self._stop), daemon=True,
                                        name=f"can-reader-{self.channel}")
        self._reader.start()

    def _close(self) -> None:
        self._stop.set()
        if self._reader is not None and self._reader is not threading.current_thread():
            self._reader.join(timeout=1.0)
        self._reader = None
        if self._bus is not None:
            try:
                self._bus.shutdown()
            except Exception as exc:  # noqa: BLE001 - a driver failing to close is still closed for us
                log.debug("CAN %s:%s: shutdown: %s", self.interface, self.channel, exc)
            self._bus = None

    def _set_filters(self) -> None:
        """SocketCAN filters in the kernel: only our hands' frames reach the socket (other interfaces: all)."""
        if self.interface == "socketcan" and self._bus is not None:
            self._bus.set_filters([{"can_id": h, "can_mask": MAX_HAND_ID, "extended": True} for h in self.queues])

    def _receive_error_frames(self) -> None:
        """SocketCAN delivers error frames only when asked; other interfaces report them or not on their own."""
        sock = getattr(self._bus, "socket", None)
        if self.interface != "socketcan" or sock is None:
            return
        try:
            sock.setsockopt(SOL_CAN_RAW, CAN_RAW_ERR_FILTER, struct.pack("=I", CAN_ERR_MASK))
        except OSError as exc:
            log.debug("CAN %s: error frames stay off: %s", self.channel, exc)

    def _read(self, bus: can.BusABC, stop: threading.Event) -> None:
        while not stop.is_set():
            try:
                msg = bus.recv(RECV_POLL_S)
            except Exception as exc:  # noqa: BLE001 - any driver exception is a link fault (module docstring)
                if not stop.is_set():
                    self._fail(f"receive failed: {type(exc).__name__}: {exc}")
                return
            if msg is None:
                continue
            targets = list(self.queues.values()) if msg.is_error_frame else \
                [self.queues.get(msg.arbitration_id & MAX_HAND_ID)]
            for q in targets:
                if q is not None:
                    q.put(msg)

    def _fail(self, reason: str) -> None:
        log.warning("CAN %s:%s link broken: %s", self.interface, self.channel, reason)
        self.broken = reason
        for q in list(self.queues.values()):
            q.put(LinkBroken(reason))

    def send(self, msg: can.Message, timeout: float) -> None:
        """Raises LinkBroken on any driver exception (module docstring)."""
        if self.broken or self._bus is None:
            raise LinkBroken(self.broken or "CAN bus is closed")
        try:
            with self._send_lock:
                self._bus.send(msg, timeout=timeout)
        except Exception as exc:  # noqa: BLE001 - any driver exception is a link fault (module docstring)
            raise LinkBroken(f"send failed: {type(exc).__name__}: {exc}") from exc
