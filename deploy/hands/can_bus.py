"""Inspire hand over CAN 2.0B (python-can: socketcan, slcan, pcan, virtual, ... chosen by name).

Both hands on one channel share one python-can Bus (deploy.hands.shared_can): replies reach each hand by its id.

Register groups travel in chunks of at most 8 bytes (see can_frames). By default all chunks of one group are
sent back to back and their replies collected together (`pipeline=True`): every chunk has its own identifier,
so replies cannot be confused, and the bus is not left idle between frames. Set pipeline=False to wait for each
reply before sending the next request, for firmware that cannot queue requests.
"""

from __future__ import annotations

import queue
import time
from collections import Counter

import numpy as np

from deploy.hands import tables
from deploy.hands.can_frames import MAX_HAND_ID, RW_READ, RW_WRITE, Pending, chunks, classify_reply
from deploy.hands.register_bus import AttemptFailed, PortUnavailable, RegisterHandBus
from deploy.hands.shared_can import OPEN_ERRORS, LinkBroken, SharedCanBus
from deploy.hands.tables import Register

DEFAULT_TIMEOUT_S = 0.02


class CanHandBus(RegisterHandBus):
    transport = "can"
    batch_state_reads = True  # all state chunks go out back to back (one reply wait per cycle)

    def __init__(
        self,
        side: str,
        channel: str,
        *,
        interface: str = "socketcan",
        hand_id: int = 1,
        bitrate: int = 1_000_000,
        timeout: float = DEFAULT_TIMEOUT_S,
        retries: int = 2,
        chunk_bytes: int = 8,
        pipeline: bool = True,
        safe_pose="hold",
        bus_options: dict | None = None,
    ):
        self.channel = channel
        self.interface = interface
        self.bitrate = int(bitrate)
        self.chunk_bytes = int(chunk_bytes)
        self.pipeline = bool(pipeline)
        self.bus_options = dict(bus_options or {})
        self.error_frames = 0  # CAN error frames seen on the bus while waiting for replies
        self._read_plans: dict[tuple[str, ...], list] = {}
        self._link: SharedCanBus | None = None
        self._replies: queue.SimpleQueue | None = None
        super().__init__(
            side,
            hand_id=hand_id,
            timeout=timeout,
            retries=retries,
            safe_pose=safe_pose,
            hand_id_range=(1, MAX_HAND_ID),
        )

    def link_description(self) -> str:
        return f"CAN {self.interface}:{self.channel} @ {self.bitrate / 1e6:g} Mbit/s"

    def _open(self) -> None:
        try:
            self._link, self._replies = SharedCanBus.attach(self.interface, self.channel, self.bitrate,
                                                            self.bus_options, self.hand_id)
        except OPEN_ERRORS as exc:
            self._link = self._replies = None
            raise PortUnavailable(f"{type(exc).__name__}: {exc}") from exc

    def _close(self) -> None:
        if self._link is not None:
            self._link.detach(self.hand_id)
            self._link = self._replies = None

    def _read_block(self, regs: tuple[Register, ...]) -> list[np.ndarray]:
        return self._read_blocks([regs])[0]

    def _read_blocks(self, regs_per_block: list[tuple[Register, ...]]) -> list[list[np.ndarray]]:
        key = tuple(reg.name for regs in regs_per_block for reg in regs)
        if key not in self._read_plans:  # read requests never change: build them once per register set
            self._read_plans[key] = [
                [(reg, self._pending(RW_READ, reg, lambda a, n: bytes([n]))) for reg in regs]
                for regs in regs_per_block
            ]
        plan = self._read_plans[key]
        replies = self._exchange([p for block in plan for _, pend in block for p in pend])
        return [
            [tables.decode_values(reg, b"".join(replies[p] for p in pend)) for reg, pend in block]
            for block in plan
        ]

    def _pending(self, rw: int, reg: Register, payload) -> list[Pending]:
        return [
            Pending(rw, a, self.hand_id, payload(a, n), reg.name)
            for a, n in chunks(reg, reg.can_address, self.chunk_bytes)
        ]

    def _write_register(self, reg: Register, values: np.ndarray) -> None:
        raw = tables.encode_values(reg, values)
        base = reg.can_address
        pending = self._pending(RW_WRITE, reg, lambda a, n: raw[a - base : a - base + n])
        acks = self._exchange(pending)
        refused = [p for p in pending if acks[p] not in (b"", b"\x01")]
        if refused:
            raise self._fault(
                f"hand refused the write to {reg.name} at {refused[0].address} (ack data {acks[refused[0]].hex(' ')})"
            )

    def _exchange(self, pending: list[Pending]) -> dict[Pending, bytes]:
        link, replies = self._link, self._replies
        if link is None or replies is None:
            raise AttemptFailed("disconnected", "CAN bus is closed")
        got: dict[Pending, bytes] = {}
        seen: Counter = Counter()
        deadline = time.monotonic() + self.timeout
        try:
            while not replies.empty():  # late replies to an earlier try must not answer this one
                if isinstance(replies.get_nowait(), LinkBroken) and link.broken:  # else: already reopened
                    raise LinkBroken(link.broken)
            groups = [pending] if self.pipeline else [[p] for p in pending]
            for group in groups:
                for p in group:
                    link.send(p.message, timeout=self.timeout)
                self._collect(replies, {p.arbitration_id: p for p in group}, got, seen, deadline)
        except LinkBroken as exc:
            raise AttemptFailed("disconnected", str(exc)) from exc
        return got

    def _collect(
        self, replies: queue.SimpleQueue, outstanding: dict[int, Pending], got: dict, seen: Counter, deadline: float
    ) -> None:
        while outstanding:
            remaining = deadline - time.monotonic()
            try:
                msg = replies.get(timeout=remaining) if remaining > 0 else None
            except queue.Empty:
                msg = None
            if msg is None:
                break
            if isinstance(msg, LinkBroken):
                if self._link is None or self._link.broken:  # else: a stale marker, already reopened
                    raise msg
                continue
            if msg.is_error_frame:
                self.error_frames += 1
                seen["error_frame"] += 1
                continue
            pend = outstanding.get(msg.arbitration_id)
            if pend is None:
                continue  # another register of ours, late, or traffic for another node
            verdict = classify_reply(msg, pend)
            if verdict == "ok":
                got[pend] = bytes(msg.data)
                del outstanding[msg.arbitration_id]
            else:
                seen[verdict] += 1
        if outstanding:
            missing = ", ".join(f"{p.register}@{p.address}" for p in outstanding.values())
            kind = next((k for k in ("error_frame", "partial", "garbled") if seen[k]), "timeout")
            raise AttemptFailed(
                kind,
                f"no good reply for address(es) {missing} within {self.timeout * 1000:.0f} ms"
                + (f" ({dict(seen)})" if seen else ""),
            )
