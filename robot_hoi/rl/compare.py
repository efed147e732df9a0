"""Two recipes compared over their seeds: each seed's run evaluated under the same protocol, then per metric the
mean and spread over seeds, the interval of every episode pooled, and whether the two recipes separate.

They separate on a metric when both have at least MIN_SEEDS seeds, their pooled 95 % intervals do not overlap,
and every seed of the higher recipe scores above every seed of the lower one: a gain smaller than the spread
between seeds of one recipe is not a gain.
"""

from __future__ import annotations

from typing import Any

from robot_hoi.rl.evaluation import mean_interval, rate

MIN_SEEDS = 2
METRICS = ("success", "interaction_success", "duration_share")  # under our success definition


def episode_values(record: dict[str, Any], metric: str, definition: str = "ours") -> list[float]:
    """Every episode's value of `metric` in one evaluation record, all clips pooled."""
    values: list[float] = []
    for clip in record["clips"].values():
        per_episode = clip[definition]["per_episode"]
        if metric == "duration_share":
            values += [d / clip["clip_duration_s"] for d in per_episode["duration_s"]]
        else:
            values += per_episode[metric]
    return values


def recipe_summary(records: list[dict[str, Any]], metric: str) -> dict[str, Any]:
    """Per seed (record) the metric's value, their mean and range, and the pooled interval over all episodes."""
    per_seed = [episode_values(r, metric) for r in records]
    seed_means = [sum(v) / len(v) for v in per_seed]
    pooled = [x for v in per_seed for x in v]
    if metric == "duration_share":
        interval = mean_interval(pooled)
        lo, hi = interval["lo"], interval["hi"]
    else:
        r = rate(pooled)
        lo, hi = r["lo"], r["hi"]
    return {"seeds": seed_means, "mean": sum(seed_means) / len(seed_means), "min": min(seed_means),
            "max": max(seed_means), "pooled": sum(pooled) / len(pooled), "lo": lo, "hi": hi,
            "episodes": len(pooled)}


def verdict(a: dict[str, Any], b: dict[str, Any], names: tuple[str, str] = ("A", "B")) -> dict[str, Any]:
    """Whether recipe summaries `a` and `b` of one metric separate, and which (by name) is higher."""
    (higher, hi_s), (lower, lo_s) = sorted(zip(names, (a, b), strict=True), key=lambda ns: -ns[1]["pooled"])
    enough = len(a["seeds"]) >= MIN_SEEDS and len(b["seeds"]) >= MIN_SEEDS
    disjoint = None not in (hi_s["lo"], lo_s["hi"]) and hi_s["lo"] > lo_s["hi"]
    seeds_apart = hi_s["min"] > lo_s["max"]
    separate = enough and disjoint and seeds_apart
    if not enough:
        why = f"cannot tell: fewer than {MIN_SEEDS} seeds on a side"
    elif separate:
        why = f"{higher} is higher: the pooled intervals do not overlap and every seed of {higher} beats every " \
              f"seed of {lower}"
    elif not disjoint:
        why = "do not separate: the pooled intervals overlap"
    else:
        why = "do not separate: the pooled intervals are apart but the seeds overlap"
    return {"separate": separate, "higher": higher if separate else None, "intervals_disjoint": disjoint,
            "seeds_apart": seeds_apart, "statement": why}


def compare_records(a: list[dict[str, Any]], b: list[dict[str, Any]],
                    names: tuple[str, str] = ("A", "B")) -> dict[str, Any]:
    """Per metric: each recipe's summary under its name, and the verdict."""
    result = {}
    for metric in METRICS:
        sa, sb = recipe_summary(a, metric), recipe_summary(b, metric)
        result[metric] = {names[0]: sa, names[1]: sb, **verdict(sa, sb, names)}
    return result
