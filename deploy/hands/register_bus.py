"""What every Inspire transport shares: retries with debug logs, reopen after a lost link, connect guards,
clamping, a last-known-value cache with ages, error counters and the safe pose on disconnect.

A transport subclass only moves register values: `_open`, `_close`, `_read_block` and `_write_register`.
A failed try raises `AttemptFailed` (retried); a device-side rejection raises HandFaultError (not retried).
"""

from __future__ import annotations

import logging
import threading
import time
from abc import abstractmethod
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TypeVar

import numpy as np

from deploy.errors import DeployError, HandFaultError, HandLinkError
from deploy.hand_units import HAND_SIDES
from deploy.hands import tables
from deploy.hands.base import HandBus, HandState
from deploy.hands.tables import REGISTERS, Register

log = logging.getLogger("deploy.hands")
T = TypeVar("T")

SAFE_POSES = ("hold", "open")
ANGLE_OPEN = 1000


class AttemptFailed(Exception):
    """One try that did not produce a usable reply. `kind` is one of: timeout, checksum, garbled, partial,
    mismatch, disconnected, error_frame."""

    def __init__(self, kind: str, detail: str = ""):
        super().__init__(f"{kind}: {detail}" if detail else kind)
        self.kind = kind
        self.detail = detail


class PortUnavailable(Exception):
    """The port or CAN interface cannot be opened (missing, busy, no permission)."""


@dataclass
class LinkStats:
    requests: int = 0  # operations asked for (one register block read or written)
    attempts: int = 0  # tries put on the wire
    retries: int = 0  # tries after the first
    failures: Counter = field(default_factory=Counter)  # failed tries by AttemptFailed.kind
    link_errors: int = 0  # HandLinkError raised
    fault_errors: int = 0  # HandFaultError raised
    reconnects: int = 0  # successful reopen after a lost link


@dataclass(frozen=True)
class CachedValue:
    values: np.ndarray
    stamp: float  # time.monotonic() when the reply arrived

    @property
    def age(self) -> float:
        return time.monotonic() - self.stamp


def _as_six(name: str, values: Sequence[float]) -> np.ndarray:
    arr = np.asarray(values, dtype=np.float64)
    if arr.shape != (tables.NUM_DOF,):
        raise ValueError(f"{name} takes {tables.NUM_DOF} values, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} values must be finite, got {arr.tolist()}")
    return arr


class RegisterHandBus(HandBus):
    transport = ""
    batch_state_reads = False  # True: read_state is one operation (transports that pipeline requests)

    def __init__(
        self,
        side: str,
        *,
        hand_id: int,
        timeout: float,
        retries: int,
        safe_pose: str | Sequence[int] = "hold",
        hand_id_range: tuple[int, int] = (1, 254),
    ):
        if side not in HAND_SIDES:
            raise DeployError(f"hand side must be one of {HAND_SIDES}, got {side!r}")
        if not isinstance(hand_id, int) or not hand_id_range[0] <= hand_id <= hand_id_range[1]:
            raise DeployError(
                f"{self.transport} hand id must be an integer in {hand_id_range}, got {hand_id!r}"
            )
        if not timeout > 0:
            raise DeployError(f"hand bus timeout must be > 0 s, got {timeout!r}")
        if not isinstance(retries, int) or retries < 0:
            raise DeployError(f"hand bus retries must be an integer >= 0, got {retries!r}")
        self.side = side
        self.hand_id = hand_id
        self.timeout = float(timeout)
        self.retries = retries
        self.safe_pose = self._check_safe_pose(safe_pose)
        self.stats = LinkStats()
        self.last_command: np.ndarray | None = None  # last ANGLE_SET the hand acknowledged
        self.force_limits: np.ndarray | None = None
        self.speeds: np.ndarray | None = None
        self._cache: dict[str, CachedValue] = {}
        self._lock = threading.RLock()
        self._connected = False
        self._needs_reopen = False
        self._last_tries = 0
        self._attempt = 0

    # ----------------------------------------------------------------- transport hooks
    @abstractmethod
    def _open(self) -> None:
        """Open the port/interface; raise PortUnavailable when it cannot be opened."""

    @abstractmethod
    def _close(self) -> None:
        """Close quietly; must not raise."""

    @abstractmethod
    def _read_block(self, regs: tuple[Register, ...]) -> list[np.ndarray]:
        """One try at reading a gap-free span of register groups; values per group."""

    @abstractmethod
    def _write_register(self, reg: Register, values: np.ndarray) -> None:
        """One try at writing a register group (values already validated and clamped)."""

    @abstractmethod
    def link_description(self) -> str:
        """Where the hand is, e.g. 'serial /dev/ttyUSB1' or 'CAN socketcan:can0'."""

    # ----------------------------------------------------------------- HandBus
    @property
    def name(self) -> str:
        return f"{self.side} hand (id {self.hand_id}, {self.link_description()})"

    @property
    def is_connected(self) -> bool:
        return self._connected

    def connect(self) -> None:
        """Open and probe. A port that cannot be opened is the operator's to fix (DeployError); a hand that does
        not answer raises HandLinkError."""
        self._connect(DeployError)

    def _connect(self, port_error: type[Exception]) -> None:
        with self._lock:
            if self._connected:
                return
            try:
                self._open()
            except PortUnavailable as exc:
                raise port_error(f"{self.name}: cannot open: {exc}") from exc
            self._connected = True
            self._needs_reopen = False
            try:
                self._read_registers(("ANGLE_ACT",))
            except (HandLinkError, HandFaultError):
                self._close()
                self._connected = False
                raise
            log.info("%s: connected", self.name)

    def disconnect(self) -> None:
        with self._lock:
            if not self._connected:
                return
            try:
                self.apply_safe_pose()
            except (HandLinkError, HandFaultError) as exc:
                log.warning("%s: could not apply the safe pose before disconnecting: %s", self.name, exc)
            finally:
                self._close()
                self._connected = False
                log.info("%s: disconnected", self.name)

    def reconnect(self) -> None:
        """Close and reopen the link, then check that the hand answers. Raises HandLinkError (also when the
        port is gone: after a working connect() that is a hardware problem, not a bad port name)."""
        with self._lock:
            self._close()
            self._connected = False
            self._connect(HandLinkError)
            self.stats.reconnects += 1

    def configure(self, force_limits: Sequence[int], speeds: Sequence[int]) -> None:
        forces = self._checked_setting("FORCE_SET", force_limits)
        speeds_arr = self._checked_setting("SPEED_SET", speeds)
        with self._lock:
            self._write("FORCE_SET", forces)
            self.force_limits = forces
            self._write("SPEED_SET", speeds_arr)
            self.speeds = speeds_arr

    def clear_errors(self) -> None:
        with self._lock:
            self._write("CLEAR_ERROR", np.array([1], dtype=np.int64))

    def write_angles(self, units: Sequence[int]) -> None:
        reg = REGISTERS["ANGLE_SET"]
        command = np.clip(np.rint(_as_six("ANGLE_SET", units)), reg.low, reg.high).astype(np.int64)
        with self._lock:
            self._write("ANGLE_SET", command)
            self.last_command = command

    def read_state(self) -> HandState:
        with self._lock:
            if self.batch_state_reads:
                values = self._read_many(tables.STATE_BLOCKS)
                stamps = [self._cache["ANGLE_ACT"].stamp]
                tries_for_errors = self._last_tries
            else:
                stamps, values = [], {}
                for names in tables.STATE_BLOCKS:
                    values.update(self._read_registers(names))
                    stamps.append(self._cache[names[0]].stamp)
                    if "ERROR" in names:
                        tries_for_errors = self._last_tries
            state = HandState(
                angles=values["ANGLE_ACT"],
                forces=values["FORCE_ACT"],
                errors=values["ERROR"].astype(np.uint8),
                status=values["STATUS"].astype(np.uint8),
                temperatures=values["TEMP"].astype(np.uint8),
                stamp=min(stamps),
            )
            if state.has_fault:
                self.stats.fault_errors += 1
                exc = HandFaultError(
                    f"{self.name}: ERROR register reports {tables.describe_errors(state.errors)} "
                    f"(read in {tries_for_errors} {'try' if tries_for_errors == 1 else 'tries'}); "
                    "clear_errors() resets locked-rotor/over-current/motor/communication faults"
                )
                exc.state = state  # the runtime still gets the measurements
                exc.side, exc.hand_id = self.side, self.hand_id
                raise exc
            return state

    def read_register(self, name: str) -> np.ndarray:
        """Read any register group by name (e.g. "TEMP", "CURRENT", "FORCE_SET"), with retries; cached."""
        if name not in REGISTERS:
            raise ValueError(f"unknown Inspire register {name!r}; known: {', '.join(REGISTERS)}")
        with self._lock:
            return self._read_registers((name,))[name]

    # ----------------------------------------------------------------- safe pose and cache
    def safe_pose_units(self) -> np.ndarray | None:
        """ANGLE_SET for the safe pose: 'hold' keeps the last command (a grasped box is not dropped), 'open'
        opens the hand, a list of six values is sent as given. None: nothing to send (nothing was commanded)."""
        if isinstance(self.safe_pose, np.ndarray):
            return self.safe_pose
        if self.safe_pose == "open":
            return np.full(tables.NUM_DOF, ANGLE_OPEN, dtype=np.int64)
        return None if self.last_command is None else self.last_command.copy()

    def apply_safe_pose(self) -> None:
        pose = self.safe_pose_units()
        if pose is not None:
            self.write_angles(pose)

    def cached(self, name: str) -> CachedValue | None:
        """Last value read from register group `name`, with its arrival time (None if never read)."""
        return self._cache.get(name)

    def cache_age(self, name: str) -> float:
        entry = self._cache.get(name)
        return float("inf") if entry is None else entry.age

    @property
    def last_state(self) -> HandState | None:
        """The most recent value of every state register, stamped with the oldest of them."""
        names = [n for block in tables.STATE_BLOCKS for n in block]
        if any(n not in self._cache for n in names):
            return None
        c = self._cache
        return HandState(
            angles=c["ANGLE_ACT"].values,
            forces=c["FORCE_ACT"].values,
            errors=c["ERROR"].values.astype(np.uint8),
            status=c["STATUS"].values.astype(np.uint8),
            temperatures=c["TEMP"].values.astype(np.uint8),
            stamp=min(c[n].stamp for n in names),
        )

    # ----------------------------------------------------------------- engine
    def _checked_setting(self, name: str, values: Sequence[int]) -> np.ndarray:
        reg = REGISTERS[name]
        try:
            arr = _as_six(name, values)
        except ValueError as exc:
            raise DeployError(f"{self.side} hand: {exc}") from exc
        if np.any(arr < reg.low) or np.any(arr > reg.high) or np.any(arr != np.rint(arr)):
            raise DeployError(
                f"{self.side} hand: {name} takes integers in {reg.low}..{reg.high}, got {arr.tolist()}"
            )
        return arr.astype(np.int64)

    def _read_registers(self, names: tuple[str, ...]) -> dict[str, np.ndarray]:
        return self._read_many((names,))

    def _read_many(self, blocks: tuple[tuple[str, ...], ...]) -> dict[str, np.ndarray]:
        """Read several gap-free blocks in one operation (one retry loop), caching every group."""
        regs_per_block = [tables.contiguous(names) for names in blocks]
        label = "+".join(name for names in blocks for name in names)
        values = self._run(f"read {label}", lambda: self._read_blocks(regs_per_block))
        stamp = time.monotonic()
        out = {}
        for regs, block_values in zip(regs_per_block, values, strict=True):
            for reg, vals in zip(regs, block_values, strict=True):
                out[reg.name] = vals
                self._cache[reg.name] = CachedValue(vals, stamp)
        return out

    def _read_blocks(self, regs_per_block: list[tuple[Register, ...]]) -> list[list[np.ndarray]]:
        """One try at several blocks; transports that can overlap requests override this."""
        return [self._read_block(regs) for regs in regs_per_block]

    def _write(self, name: str, values: np.ndarray) -> None:
        reg = REGISTERS[name]
        if np.any(values < reg.low) or np.any(values > reg.high):  # last line of defence; callers clamp
            raise ValueError(f"{name} value outside {reg.low}..{reg.high}: {values.tolist()}")
        self._run(f"write {name}", lambda: self._write_register(reg, values))

    def _fault(self, what: str) -> HandFaultError:
        """A device-side rejection, raised from inside a try (never retried: the hand answered)."""
        tries = self.retries + 1
        return HandFaultError(
            f"{self.name}: {what} (on try {self._attempt} of {tries}; device faults are not retried)"
        )

    def _require_connected(self) -> None:
        if not self._connected:
            raise HandLinkError(f"{self.name}: not connected (call connect() first)")

    def _reopen(self) -> None:
        self._close()
        try:
            self._open()
        except PortUnavailable as exc:
            raise AttemptFailed("disconnected", f"reopen failed: {exc}") from exc
        self._needs_reopen = False
        self.stats.reconnects += 1
        log.info("%s: link reopened", self.name)

    def _run(self, what: str, attempt_fn: Callable[[], T]) -> T:
        self._require_connected()
        tries = self.retries + 1
        self.stats.requests += 1
        last: AttemptFailed | None = None
        for attempt in range(1, tries + 1):
            self.stats.attempts += 1
            if attempt > 1:
                self.stats.retries += 1
            self._attempt = attempt
            try:
                if self._needs_reopen:
                    self._reopen()
                result = attempt_fn()
                self._last_tries = attempt
                return result
            except AttemptFailed as exc:
                last = exc
                self.stats.failures[exc.kind] += 1
                if exc.kind == "disconnected":
                    self._needs_reopen = True
                log.debug("%s: %s, try %d/%d failed: %s", self.name, what, attempt, tries, exc)
            except HandFaultError:
                self.stats.fault_errors += 1
                raise
        self.stats.link_errors += 1
        assert last is not None
        raise HandLinkError(
            f"{self.name}: {what} failed after {tries} {'try' if tries == 1 else 'tries'} "
            f"(last: {last.kind}{': ' + last.detail if last.detail else ''})"
        )

    def _check_safe_pose(self, safe_pose: str | Sequence[int]) -> str | np.ndarray:
        if isinstance(safe_pose, str):
            if safe_pose not in SAFE_POSES:
                raise DeployError(
                    f"hand safe pose must be one of {SAFE_POSES} or six angles, got {safe_pose!r}"
                )
            return safe_pose
        try:
            pose = _as_six("safe pose", safe_pose)
        except (ValueError, TypeError) as exc:
            raise DeployError(f"hand safe pose: {exc}") from exc
        if np.any(pose < 0) or np.any(pose > ANGLE_OPEN):
            raise DeployError(f"hand safe pose angles must be in 0..{ANGLE_OPEN}, got {pose.tolist()}")
        return np.rint(pose).astype(np.int64)

    def __enter__(self):
        self.connect()
        return self

    def __exit__(self, *exc_info) -> None:
        self.disconnect()

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name} {'connected' if self._connected else 'closed'}>"
