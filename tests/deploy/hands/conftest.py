"""Simulated hands + buses for the transport tests; everything started here is stopped after the test."""

from __future__ import annotations

import pytest

from deploy.hands import make_hand_bus
from deploy.hands.finger_model import FingerModel
from deploy.hands.simulated import start_simulated_hand

TRANSPORTS = ("serial", "modbus", "can")
TEST_TIMEOUT_S = (
    0.1  # per try: a loaded 2-core CI box can stall a thread for tens of ms; faults cost 3 x this
)


class ManualClock:
    """Drives the finger model by hand so motion is exact and tests never sleep for it."""

    def __init__(self, t: float = 1000.0):
        self.t = t

    def __call__(self) -> float:
        return self.t

    def advance(self, dt: float) -> None:
        self.t += dt


@pytest.fixture(params=TRANSPORTS)
def transport(request) -> str:
    return request.param


@pytest.fixture
def hand_rig():
    """make(transport, side="right", hand_id=1, **sim_options) -> (sim, bus, clock); bus not yet connected."""
    made = []

    def make(
        transport: str,
        side: str = "right",
        hand_id: int = 1,
        *,
        retries: int = 2,
        timeout: float = TEST_TIMEOUT_S,
        safe_pose="hold",
        bus_options=None,
        **sim_options,
    ):
        clock = ManualClock()
        sim_options.setdefault("pace", False)
        sim_options.setdefault("model", FingerModel(clock=clock))
        sim = start_simulated_hand(transport, side, hand_id=hand_id, **sim_options)
        bus = make_hand_bus(
            transport,
            side,
            timeout=timeout,
            retries=retries,
            safe_pose=safe_pose,
            **sim.bus_kwargs(),
            **(bus_options or {}),
        )
        made.append((sim, bus))
        return sim, bus, clock

    yield make
    for sim, bus in reversed(made):
        try:
            bus.disconnect()
        finally:
            sim.stop()
