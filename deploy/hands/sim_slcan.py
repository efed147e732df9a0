"""A USB-CAN adapter speaking slcan (Lawicel ASCII) on a pseudo-terminal, bridged to a python-can `virtual`
channel where simulated hands answer: the host opens it with python-can's own `slcan` interface.

    adapter = SimulatedSlcanAdapter(channel=sim.channel)     # sim: a SimulatedCanHand (or two, one channel)
    bus = make_hand_bus("can", "left", can_interface="slcan", can_channel=adapter.port, hand_id=1)

Host to adapter: commands ending in CR: O/L (open), C (close), S0-S8 / sxxyy (bit rate), V, N, F; frames
`T<8 hex id><dlc><data hex>` (extended) and `t<3 hex id>...` (standard), answered `Z`/`z` + CR as a real
adapter does. Adapter to host: every frame seen on the channel as `T...` + CR. Error frames have no slcan form
and are not forwarded. Faults: garble_next(n) sends a corrupt line instead of the next n frames (python-can's
parser raises on it); unplug()/plug() pull the adapter and put it back under the same path.
"""

from __future__ import annotations

import threading

import can

from deploy.hands.sim_link import PtyLink

CR = b"\r"
BELL = b"\a"
GARBLED_LINE = b"TZZZZZZZZ8" + b"Q" * 16 + CR  # not hex: int(..., 16) fails in the host's parser


class SimulatedSlcanAdapter:
    def __init__(self, channel: str, name: str = "slcan"):
        self.channel = channel
        self.link = PtyLink(name)
        self.bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
        self.frames_to_host = 0
        self.frames_from_host = 0
        self.commands: list[str] = []
        self.is_open = False
        self._garble = 0
        self._buffer = b""
        self._stop = threading.Event()
        self._threads = [threading.Thread(target=self._from_host, daemon=True, name="slcan-from-host"),
                         threading.Thread(target=self._to_host, daemon=True, name="slcan-to-host")]
        for t in self._threads:
            t.start()

    @property
    def port(self) -> str:
        return self.link.path

    def garble_next(self, n: int = 1) -> None:
        self._garble += int(n)

    def unplug(self) -> None:
        self.link.unplug()

    def plug(self) -> None:
        self.link.plug()

    def stop(self) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(timeout=2.0)
        self.bus.shutdown()
        self.link.close()

    # ----------------------------------------------------------------- host -> adapter -> CAN
    def _from_host(self) -> None:
        while not self._stop.is_set():
            self._buffer += self.link.read(0.02)
            while CR in self._buffer:
                line, self._buffer = self._buffer.split(CR, 1)
                self.link.write(self._answer(line.decode("ascii", "replace")))

    def _answer(self, line: str) -> bytes:
        if not line:
            return CR
        kind = line[0]
        if kind in "Tt":
            msg = parse_frame(line)
            if msg is None or not self.is_open:
                return BELL
            self.frames_from_host += 1
            self.bus.send(msg)
            return (b"Z" if kind == "T" else b"z") + CR
        self.commands.append(line)
        if kind in "OL":
            self.is_open = True
        elif kind == "C":
            self.is_open = False
        elif kind == "V":
            return b"V1013" + CR
        elif kind == "N":
            return b"NSIM1" + CR
        elif kind == "F":
            return b"F00" + CR
        elif kind not in "Ss":
            return BELL
        return CR

    # ----------------------------------------------------------------- CAN -> adapter -> host
    def _to_host(self) -> None:
        while not self._stop.is_set():
            msg = self.bus.recv(0.02)
            if msg is None or msg.is_error_frame or not self.is_open:
                continue
            if self._garble > 0:
                self._garble -= 1
                self.link.write(GARBLED_LINE)
                continue
            self.frames_to_host += 1
            self.link.write(format_frame(msg))


def format_frame(msg: can.Message) -> bytes:
    head = f"T{msg.arbitration_id:08X}" if msg.is_extended_id else f"t{msg.arbitration_id:03X}"
    return f"{head}{len(msg.data)}{bytes(msg.data).hex().upper()}".encode() + CR


def parse_frame(line: str) -> can.Message | None:
    try:
        extended = line[0] == "T"
        id_len = 8 if extended else 3
        arbitration_id = int(line[1:1 + id_len], 16)
        dlc = int(line[1 + id_len])
        data = bytes.fromhex(line[2 + id_len:2 + id_len + 2 * dlc])
    except (ValueError, IndexError):
        return None
    if len(data) != dlc:
        return None
    return can.Message(arbitration_id=arbitration_id, is_extended_id=extended, data=data)
