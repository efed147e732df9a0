"""The body's own health and identity, from what LowState reports beyond joint states.

    identity_faults   the robot is not the one the policy is for, or is already unhealthy: mode_machine differs
                      from the embodiment's, another rt/lowcmd publisher is active (sport mode left on), motor
                      error bits, a motor at or above the temperature limit. Before anything is commanded these
                      refuse the start; later they damp.
    TickWatch         the robot's `tick` must advance: a robot still publishing a frozen LowState looks fresh by
                      arrival time alone.
Backends that do not report a field (None) are not checked for it.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from deploy.body.base import BodyState
from deploy.embodiment import MODE_MACHINE_NAMES


def _machine(mode: int) -> str:
    return f"{mode} ({MODE_MACHINE_NAMES[mode]})" if mode in MODE_MACHINE_NAMES else str(mode)


def identity_faults(state: BodyState, joint_names: Sequence[str], expected_mode_machine: int | None,
                    max_motor_temp_c: float) -> list[str]:
    faults = []
    if expected_mode_machine is not None and state.mode_machine is not None \
            and state.mode_machine != expected_mode_machine:
        faults.append(f"robot reports mode_machine {_machine(state.mode_machine)}; "
                      f"the policy is for {_machine(expected_mode_machine)}")
    if state.other_commanders:
        faults.append(f"{state.other_commanders} other rt/lowcmd publisher(s) active (sport mode or another "
                      "controller still commanding the motors)")
    if state.motor_error is not None and np.any(state.motor_error):
        faults.extend(f"motor error: {joint_names[i]} motorstate 0x{int(state.motor_error[i]):08X}"
                      for i in np.flatnonzero(state.motor_error))
    if state.motor_temp_c is not None:
        hot = np.flatnonzero(np.asarray(state.motor_temp_c) >= max_motor_temp_c)
        faults.extend(f"motor over temperature: {joint_names[i]} at {float(state.motor_temp_c[i]):.0f} C "
                      f"(limit {max_motor_temp_c:.0f} C)" for i in hot)
    return faults


class TickWatch:
    """Fault when the reported tick has not changed for longer than `max_age_s` (clock time)."""

    def __init__(self, max_age_s: float):
        self.max_age_s = max_age_s
        self._tick: int | None = None
        self._changed_at = 0.0

    def fault(self, state: BodyState | None, now: float) -> str | None:
        if state is None or state.tick is None:
            return None
        if state.tick != self._tick:
            self._tick, self._changed_at = state.tick, now
            return None
        frozen_for = now - self._changed_at
        if frozen_for > self.max_age_s:
            return f"body tick frozen at {state.tick} for {frozen_for * 1e3:.1f} ms"
        return None
