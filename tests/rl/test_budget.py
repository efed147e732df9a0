from __future__ import annotations

import pytest

from robot_hoi.errors import UserError
from robot_hoi.rl.budget import Budget, parse_budget


@pytest.mark.parametrize(
    "text, expected",
    [
        ("90s", Budget(wall_seconds=90)),
        ("10m", Budget(wall_seconds=600)),
        ("2h", Budget(wall_seconds=7200)),
        ("1.5d", Budget(wall_seconds=129600)),
        ("5M", Budget(samples=5_000_000)),
        ("200k", Budget(samples=200_000)),
        ("1G", Budget(samples=1_000_000_000)),
        ("300it", Budget(iterations=300)),
        ("2h, 50M,10it", Budget(wall_seconds=7200, samples=50_000_000, iterations=10)),
    ],
)
def test_parse_budget(text, expected):
    assert parse_budget(text) == expected


@pytest.mark.parametrize("text", ["", "100", "10x", "5m,6m", "1.5it", "-3s", "m", "10 min"])
def test_parse_budget_rejects(text):
    with pytest.raises(UserError):
        parse_budget(text)


def test_budget_needs_a_positive_limit():
    with pytest.raises(UserError):
        Budget()
    with pytest.raises(UserError):
        Budget(samples=0)


def test_first_limit_reached_wins():
    budget = Budget(wall_seconds=100, samples=1000)
    assert budget.fraction_done(10, 500, 3) == pytest.approx(0.5)
    assert not budget.exhausted(10, 999, 3)
    assert budget.exhausted(10, 1000, 3)
    assert budget.exhausted(100, 0, 3)
    assert Budget(iterations=4).fraction_done(0, 0, 1) == pytest.approx(0.25)
