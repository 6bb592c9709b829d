"""The runs a sweep asks for: `--set` grids and ranges crossed with replicate seeds.

Values keep the text the user typed where it is exact (`0.5`, not `0.5000000000000001`
from accumulating a float step), so a table's params read as they were asked for.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation

from swarmdsl.errors import SwarmOptionError

MAX_RUNS = 1_000_000
MAX_SEED = 2**63 - 1            # a run's seed is an int64 (runtime.arguments)


@dataclass(frozen=True)
class Task:
    index: int                  # position in the sweep's order: rows are sorted by it
    params: tuple               # ((name, value text), ...) in --set order
    seed: int


def parse_axis(item: str) -> tuple[str, list[str]]:
    """`name=a:b:step` (inclusive range), `name=v1,v2,...` or `name=v` -> values as text."""
    name, eq, spec = item.partition("=")
    name, spec = name.strip(), spec.strip()
    if not eq or not name or not spec:
        raise SwarmOptionError(f"--set {item}: expected NAME=VALUES, e.g. --set eta=0:5:0.5 "
                               "or --set n=100,400")
    if ":" in spec:
        parts = spec.split(":")
        if len(parts) != 3:
            raise SwarmOptionError(f"--set {item}: a range is START:STOP:STEP, "
                                   "e.g. eta=0:5:0.5")
        try:
            start, stop, step = (Decimal(p.strip()) for p in parts)
        except InvalidOperation:
            raise SwarmOptionError(f"--set {item}: START, STOP and STEP must be numbers"
                                   ) from None
        if not (start.is_finite() and stop.is_finite() and step.is_finite()):
            raise SwarmOptionError(f"--set {item}: START, STOP and STEP must be finite "
                                   "numbers")
        if step <= 0:
            raise SwarmOptionError(f"--set {item}: STEP must be a positive number")
        # compared, not read off the count: int() truncates toward zero, so a STOP less
        # than one STEP below START would count 1 and run START, outside the range
        if stop < start:
            raise SwarmOptionError(f"--set {item}: STOP is below START")
        count = int((stop - start) / step) + 1
        if count > MAX_RUNS:
            raise SwarmOptionError(f"--set {item}: {count:,} values is too many")
        values = [_text(start + i * step) for i in range(count)]
    else:
        values = [v.strip() for v in spec.split(",")]
        if any(not v for v in values):
            raise SwarmOptionError(f"--set {item}: an empty value in the list")
        _refuse_repeats(item, values)
    return name, values


def _refuse_repeats(item: str, values: list[str]) -> None:
    """A value listed twice (`eta=1,1`, `eta=1,1.0`, `on=true,True`) is refused, as a seed
    given twice is: it ran the same runs twice, counted as two replicates in the table
    and in `plot sweep`'s mean and band."""
    seen: dict = {}
    for value in values:
        try:
            same = Decimal(value).normalize()
        except InvalidOperation:
            same = value.lower()    # a boolean: `true` and `True` are one value
        if same in seen:
            raise SwarmOptionError(f"--set {item}: {value} is the same value as "
                                   f"{seen[same]}; list each value once")
        seen[same] = value


def _text(d: Decimal) -> str:
    s = format(d.normalize(), "f")
    return "0" if s in ("-0", "") else s


def seeds_of(count: int | None, seed_list: str | None) -> list[int]:
    if count is not None and seed_list is not None:
        raise SwarmOptionError("give --seeds N or --seed-list A,B,..., not both")
    if seed_list is not None:
        try:
            seeds = [int(s) for s in seed_list.split(",")]
        except ValueError:
            raise SwarmOptionError(f"--seed-list {seed_list}: expected whole numbers, "
                                   "e.g. 1,2,3") from None
        if len(set(seeds)) != len(seeds):
            raise SwarmOptionError(f"--seed-list {seed_list}: a seed appears twice")
        if any(not 0 <= s <= MAX_SEED for s in seeds):
            # checked here, not only by each run: a seed past int64 fails every run and
            # then cannot be stored in the table's int64 `seed` column at all
            raise SwarmOptionError(f"--seed-list {seed_list}: seeds are from 0 to "
                                   f"{MAX_SEED:,}")
        return seeds
    count = 1 if count is None else count
    if count < 1:
        raise SwarmOptionError(f"--seeds {count}: must be 1 or more")
    return list(range(count))


def tasks_of(sets: list[str], seeds: list[int]) -> list[Task]:
    """Every combination of the axes (the first --set varies slowest), each seed innermost."""
    axes = [parse_axis(s) for s in sets]
    names = [n for n, _ in axes]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise SwarmOptionError(f"--set {sorted(dup)[0]} is given twice; list its values "
                               "in one --set")
    total = len(seeds)
    for _, values in axes:
        total *= len(values)
    if total > MAX_RUNS:
        raise SwarmOptionError(f"the sweep asks for {total:,} runs (at most {MAX_RUNS:,})")
    out = []
    for combo in itertools.product(*(values for _, values in axes)):
        for seed in seeds:
            out.append(Task(len(out), tuple(zip(names, combo, strict=True)), seed))
    return out
