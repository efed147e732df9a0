"""Training budgets: stop after a wall time, a number of env samples or a number of iterations, whichever first.

Budget strings are comma-separated terms; the unit decides the kind:
  seconds/minutes/hours/days  "90s", "10m", "2h", "1.5d"      -> wall time
  thousand/million/billion    "200k", "5M", "1G"              -> env samples (transitions)
  iterations                  "300it"                         -> PPO iterations
Unit case matters: "m" is minutes, "M" is millions. A bare number is rejected as ambiguous.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace

from robot_hoi.errors import UserError

_TIME_UNITS = {"s": 1.0, "m": 60.0, "h": 3600.0, "d": 86400.0}
_SAMPLE_UNITS = {"k": 1e3, "M": 1e6, "G": 1e9}
_TERM = re.compile(r"^\s*(\d+(?:\.\d*)?|\.\d+)\s*(s|m|h|d|k|M|G|it)\s*$")


@dataclass(frozen=True)
class Budget:
    """Limits for one `learn` call (counted from the start of that call, not from an earlier run)."""

    wall_seconds: float | None = None
    samples: int | None = None
    iterations: int | None = None

    def __post_init__(self) -> None:
        if self.wall_seconds is None and self.samples is None and self.iterations is None:
            raise UserError("training budget: give at least one of wall time, samples or iterations")
        for name in ("wall_seconds", "samples", "iterations"):
            value = getattr(self, name)
            if value is not None and value <= 0:
                raise UserError(f"training budget: {name} must be positive, got {value}")

    def fraction_done(self, elapsed_s: float, samples: int, iterations: int) -> float:
        """Progress in [0, 1] against the limit that is closest to being reached."""
        parts = []
        if self.wall_seconds is not None:
            parts.append(elapsed_s / self.wall_seconds)
        if self.samples is not None:
            parts.append(samples / self.samples)
        if self.iterations is not None:
            parts.append(iterations / self.iterations)
        return min(1.0, max(parts))

    def scaled(self, fraction: float) -> Budget:
        """Each limit times `fraction` (at least 1 s, 1 sample, 1 iteration)."""

        def part(v):
            return None if v is None else type(v)(max(v * fraction, 1))

        return replace(self, wall_seconds=part(self.wall_seconds), samples=part(self.samples),
                       iterations=part(self.iterations))

    def exhausted(self, elapsed_s: float, samples: int, iterations: int) -> bool:
        return self.fraction_done(elapsed_s, samples, iterations) >= 1.0

    def describe(self) -> str:
        parts = []
        if self.wall_seconds is not None:
            parts.append(f"{self.wall_seconds:g} s")
        if self.samples is not None:
            parts.append(f"{self.samples:,} samples")
        if self.iterations is not None:
            parts.append(f"{self.iterations} iterations")
        return " or ".join(parts)


def parse_budget(text: str) -> Budget:
    """Parse e.g. "10m", "5M", "300it" or "2h,50M" into a Budget (raises UserError on anything else)."""
    wall: float | None = None
    samples: int | None = None
    iterations: int | None = None
    terms = [t for t in str(text).split(",") if t.strip()]
    if not terms:
        raise UserError(f"training budget {text!r}: empty; use e.g. '10m', '5M' or '300it'")
    for term in terms:
        match = _TERM.match(term)
        if match is None:
            raise UserError(
                f"training budget term {term.strip()!r}: expected a number with a unit "
                "(s, m, h, d for time; k, M, G for samples; it for iterations), e.g. '10m', '5M', '300it'"
            )
        number, unit = float(match.group(1)), match.group(2)
        if unit in _TIME_UNITS:
            if wall is not None:
                raise UserError(f"training budget {text!r}: wall time given twice")
            wall = number * _TIME_UNITS[unit]
        elif unit in _SAMPLE_UNITS:
            if samples is not None:
                raise UserError(f"training budget {text!r}: sample count given twice")
            samples = int(round(number * _SAMPLE_UNITS[unit]))
        else:
            if iterations is not None:
                raise UserError(f"training budget {text!r}: iteration count given twice")
            if number != int(number):
                raise UserError(f"training budget term {term.strip()!r}: iterations must be a whole number")
            iterations = int(number)
    return Budget(wall_seconds=wall, samples=samples, iterations=iterations)
