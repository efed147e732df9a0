"""The Unitree wireless remote as an operator input: button bits from LowState's `wireless_remote` bytes.

The 40 bytes carry the pressed buttons as a little-endian uint16 at bytes 2..3 (then the stick axes as floats;
unused here). Bit map (as unitree_rl_gym decodes it): R1 0, L1 1, START 2, SELECT 3, R2 4, L2 5, F1 6, F2 7,
A 8, B 9, X 10, Y 11, up 12, right 13, down 14, left 15.

What the runtime does with them (README "Operator"):
    START or A   confirm: stiffen from ZERO_TORQUE (ramp to the default pose), start the policy from HOLD
    SELECT       stop: DAMP, then exit (clean)
    B            e-stop: DAMP now, then exit
Only presses count (a button going down), so a button held while the runtime starts, or held through a phase
change, fires nothing by itself.
"""

from __future__ import annotations

BUTTONS = {"R1": 0, "L1": 1, "START": 2, "SELECT": 3, "R2": 4, "L2": 5, "F1": 6, "F2": 7, "A": 8, "B": 9, "X": 10,
           "Y": 11, "up": 12, "right": 13, "down": 14, "left": 15}
BUTTON_EVENTS = {"START": "start", "A": "start", "SELECT": "stop", "B": "estop"}
KEYS_OFFSET = 2  # bytes 2..3 of wireless_remote


def keys_from_wireless_remote(raw) -> int:
    """The pressed-button bits from LowState.wireless_remote (40 bytes)."""
    data = bytes(raw)
    return int.from_bytes(data[KEYS_OFFSET:KEYS_OFFSET + 2], "little")


def keys_of(*buttons: str) -> int:
    """Button names -> bits, e.g. keys_of("L2", "B")."""
    return sum(1 << BUTTONS[b] for b in buttons)


def wireless_remote_bytes(keys: int) -> bytes:
    """40 wireless_remote bytes with these buttons pressed (for simulated robots)."""
    out = bytearray(40)
    out[KEYS_OFFSET:KEYS_OFFSET + 2] = int(keys).to_bytes(2, "little")
    return bytes(out)


class RemotePresses:
    """Turns successive button states into operator events on presses only."""

    def __init__(self) -> None:
        self._previous: int | None = None

    def update(self, keys: int | None) -> list[str]:
        if keys is None:
            return []
        previous, self._previous = self._previous, keys
        if previous is None:  # the first state is the baseline: a button held at start-up is not a press
            return []
        pressed = keys & ~previous
        return [event for name, event in BUTTON_EVENTS.items() if pressed & (1 << BUTTONS[name])]
