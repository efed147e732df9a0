"""The Unitree wireless remote as an operator input: button bits from LowState's `wireless_remote` bytes.

The 40 bytes are Unitree's xRockerBtnDataStruct: 2 head bytes, the pressed buttons as a little-endian uint16 at
bytes 2..3, then the stick axes as floats (unused here). Bit map (as unitree_rl_gym decodes it): R1 0, L1 1,
START 2, SELECT 3, R2 4, L2 5, F1 6, F2 7, A 8, B 9, X 10, Y 11, up 12, right 13, down 14, left 15.

What the runtime does with them (README "Operator"):
    L1 + A held 0.5 s   confirm: stiffen from ZERO_TORQUE (ramp to the default pose), start the policy from HOLD
    SELECT              stop: DAMP, then exit (clean)
    B                   e-stop: DAMP now, then exit
A start is a deliberate two-handed chord held for START_HOLD_S, so a thumb slipping from B to A starts nothing;
a stop or e-stop is one press. Presses are debounced: a button must have been up for DEBOUNCE_S before going down
again counts as a new press (a bouncing contact is one press). Only presses count, so a button (or the chord) held
while the runtime starts, or held through a phase change, fires nothing by itself.

Liveness: a robot with no paired remote reports 40 zero bytes; a paired remote fills in its head and stick
floats. `remote_reporting` calls the bytes live when any of them is non-zero (an assumption about the robot's
firmware, to confirm on the hardware: see deploy/README.md). With --remote-estop the runtime treats a remote
that stops reporting as a fault.
"""

from __future__ import annotations

BUTTONS = {"R1": 0, "L1": 1, "START": 2, "SELECT": 3, "R2": 4, "L2": 5, "F1": 6, "F2": 7, "A": 8, "B": 9, "X": 10,
           "Y": 11, "up": 12, "right": 13, "down": 14, "left": 15}
SINGLE_PRESS = {"SELECT": "stop", "B": "estop"}
START_CHORD = ("L1", "A")
START_HOLD_S = 0.5
DEBOUNCE_S = 0.05
KEYS_OFFSET = 2  # bytes 2..3 of wireless_remote
SIM_HEAD = b"\xa5\x5a"  # the head our simulated robots give a live remote (the real value is not documented)


def keys_from_wireless_remote(raw) -> int:
    """The pressed-button bits from LowState.wireless_remote (40 bytes)."""
    data = bytes(raw)
    return int.from_bytes(data[KEYS_OFFSET:KEYS_OFFSET + 2], "little")


def remote_reporting(raw) -> bool:
    """Whether these wireless_remote bytes come from a paired, reporting remote (not all zero)."""
    return any(bytes(raw))


def keys_of(*buttons: str) -> int:
    """Button names -> bits, e.g. keys_of("L2", "B")."""
    return sum(1 << BUTTONS[b] for b in buttons)


def wireless_remote_bytes(keys: int, live: bool = True) -> bytes:
    """40 wireless_remote bytes with these buttons pressed (for simulated robots); live=False: no remote."""
    out = bytearray(40)
    if live:
        out[:KEYS_OFFSET] = SIM_HEAD
        out[KEYS_OFFSET:KEYS_OFFSET + 2] = int(keys).to_bytes(2, "little")
    return bytes(out)


class RemotePresses:
    """Turns successive button states (with their times) into operator events: debounced single presses for stop
    and e-stop, the held chord for start."""

    def __init__(self, chord: tuple[str, ...] = START_CHORD, hold_s: float = START_HOLD_S,
                 debounce_s: float = DEBOUNCE_S) -> None:
        self.chord_bits = keys_of(*chord)
        self.hold_s = hold_s
        self.debounce_s = debounce_s
        self._started = False
        self._up_since: dict[str, float | None] = {}  # None while the button is down
        self._chord_since: float | None = None
        self._chord_fired = False

    def update(self, keys: int | None, now: float) -> list[str]:
        if keys is None:
            return []
        if not self._started:  # the first state is the baseline: nothing held at start-up is a press
            self._started = True
            for name in SINGLE_PRESS:
                self._up_since[name] = None if keys & (1 << BUTTONS[name]) else float("-inf")
            self._chord_fired = keys & self.chord_bits == self.chord_bits
            return []
        events = []
        for name, event in SINGLE_PRESS.items():
            down = bool(keys & (1 << BUTTONS[name]))
            up_since = self._up_since[name]
            if down and up_since is not None:
                self._up_since[name] = None
                if now - up_since >= self.debounce_s:
                    events.append(event)
            elif not down and up_since is None:
                self._up_since[name] = now
        if keys & self.chord_bits == self.chord_bits:
            self._chord_since = now if self._chord_since is None else self._chord_since
            if not self._chord_fired and now - self._chord_since >= self.hold_s:
                self._chord_fired = True
                events.append("start")
        else:
            self._chord_since, self._chord_fired = None, False
        if "estop" in events and "start" in events:  # B with the chord: the e-stop wins
            events.remove("start")
        return events
