"""The start-up hand bus budget: wire time per transport, lowering the hand rate, refusing a loop too fast."""

from __future__ import annotations

import pytest

from deploy.errors import DeployError
from deploy.hand_budget import cycle_wire_s, plan_hand_rate


def test_rs485_cycle_is_the_issue_s_10_6_ms_of_wire_plus_turnaround():
    seconds, transactions = cycle_wire_s("serial", 115200)
    assert transactions == 4  # write ANGLE_SET, read ANGLE_ACT, FORCE_ACT, ERROR..TEMP
    assert seconds - 4 * 1e-3 == pytest.approx(122 * 10 / 115200)  # 29 + 29 + 29 + 35 bytes = 10.6 ms
    assert cycle_wire_s("serial", 921600)[0] < seconds / 2


def test_modbus_and_can_cycles():
    modbus, n = cycle_wire_s("modbus", 115200)
    assert n == 4 and modbus > cycle_wire_s("serial", 115200)[0]  # CRC, function codes and 3.5-char silences
    can, frames = cycle_wire_s("can", 1_000_000)
    assert frames == 9 and can < 5e-3  # 12-byte groups in two frames, ERROR/STATUS/TEMP one each


def test_fits_lowers_or_refuses():
    assert plan_hand_rate("serial", 115200, 1, 50.0, 0.8, 0.5).every_n_ticks == 1
    lowered = plan_hand_rate("serial", 115200, 1, 100.0, 0.8, 0.5)
    assert lowered.every_n_ticks == 2 and "every 2 ticks (50.0 Hz)" in lowered.message
    with pytest.raises(DeployError, match="hand bus is too slow.*14.6 ms a cycle"):
        plan_hand_rate("serial", 115200, 1, 200.0, 0.8, 0.5)
    both_on_one_port = plan_hand_rate("serial", 115200, 2, 50.0, 0.8, 0.5)
    assert both_on_one_port.every_n_ticks == 2 and "2 hand(s)" in both_on_one_port.message
    assert plan_hand_rate("can", 1_000_000, 2, 100.0, 0.8, 0.5).every_n_ticks == 1
