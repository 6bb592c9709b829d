"""A counterexample as `swarmdsl test` prints and saves it: the failing run, where it
was found, the agents it starts with, whether it is 1-minimal, and the command that
replays it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from swarmdsl.testing.example import Example, example_command, param_text
from swarmdsl.testing.runner import RunResult

SHOWN_AGENTS = 12           # initial states printed with a counterexample


@dataclass
class Counterexample:
    example: Example
    result: RunResult
    properties: list[str] | None = None     # the properties its replay checks
    origin: str = "a drawn run"             # where it was found
    found_after: int = 0                    # hunting runs until it was found
    found_seconds: float = 0.0
    minimal: bool | None = None             # None: not shrunk by `shrink.py`
    shrink_runs: int = 0
    shrink_seconds: float = 0.0
    removal_checks: int = 0                 # one-agent removals checked to pass
    kept: list[str] = field(default_factory=list)   # agents that may not go, and why
    shrink_budget: float = 0.0

    @property
    def tick(self) -> int:
        return self.result.first_tick() or 0

    @property
    def agents(self) -> int:
        """How many agents the run started with."""
        return self.example.agent_count(self.result.program)

    @property
    def violations(self) -> list:
        """The violations at the failing tick (the ones a replay stops at)."""
        return [v for v in self.result.violations if v.tick == self.tick]

    def failure(self) -> dict:
        """What failed, as the saved example records it."""
        v = self.violations
        if v:
            return {"property": v[0].name, "keyword": v[0].keyword, "tick": v[0].tick,
                    "agents": list(v[0].agent_ids), "message": v[0].message()}
        return {"fault": str(self.result.fault), "tick": self.tick}

    def replay(self) -> Example:
        """The example cut to the failing tick (a shorter run fails the same way)."""
        ex = self.example
        return Example(ex.params, ex.seed, self.tick, ex.layout)

    def save(self, path: Path, option: str | None = "--save-example") -> None:
        self.replay().save(path, self.result.program, self.properties, self.failure(),
                           option)

    def command(self, filename: str, saved: Path | str) -> str:
        return example_command(filename, saved, self.properties)

    def describe(self, filename: str, saved: Path | str | None = None) -> str:
        r = self.result
        lines = []
        for v in self.violations:
            lines.append(f"{v.span}: {v.message()}")
        if r.fault is not None and isinstance(r.sim, _NoRun):
            lines.append(f"the program rejects these params: {r.fault}")
        elif r.fault is not None:
            lines.append(f"runtime fault: {r.fault}")
        ex = self.example
        params = ", ".join(f"{k}={param_text(v)}" for k, v in ex.params) or "defaults"
        lines.append(f"  swarm: {self.agents} agent{'s' * (self.agents != 1)}, "
                     f"{self.tick} tick{'s' * (self.tick != 1)}, seed {ex.seed}, "
                     f"params: {params}")
        lines += self._subsets()
        lines += self._initial_states()
        lines += self._minimality()
        if saved is not None:
            lines.append(f"  reproduce: {self.command(filename, saved)}")
        return "\n".join(lines)

    def _minimality(self) -> list[str]:
        """Whether the case is 1-minimal, as checked, or why it may not be."""
        if self.minimal is None:
            return []
        n, t = self.agents, self.tick
        kept = f" ({'; '.join(self.kept)})" if self.kept else ""
        runs = f"checked: {self.removal_checks + 1} run{'s' * (self.removal_checks != 0)}"
        if self.minimal and not self.removal_checks:
            return [f"  1-minimal: no agent of its {n} can be removed{kept}, and ending it "
                    f"one tick earlier makes it pass ({runs})"]
        if self.minimal:
            return [f"  1-minimal: removing any one of its {n} agent{'s' * (n != 1)}"
                    f"{kept}, or ending it one tick earlier, makes it pass ({runs})"]
        if self.kept and self.kept[0].startswith("its swarm could not"):
            return [f"  not shrunk: {self.kept[0]}; it may not be minimal"]
        more = max(2 * self.shrink_budget, 1.0)
        return [f"  shrinking stopped at its time budget: {n} agent{'s' * (n != 1)}, "
                f"{t} tick{'s' * (t != 1)}, may not be minimal (give it more time: "
                f"--shrink-budget {more:g})"]

    def _subsets(self) -> list[str]:
        """A line naming the kinds that started with fewer agents than their `count`,
        so a property that needs the whole count is seen for what it is."""
        layout, r = self.example.layout, self.result
        if layout is None or isinstance(r.sim, _NoRun):
            return []
        have = layout.counts()
        fewer = [f"`{k.name}` {have[k.name]} of {k.count}" for k in r.program.kinds
                 if k.name in have and have[k.name] < k.count]
        if not fewer:
            return []
        return [f"  fewer agents than the program's count: {', '.join(fewer)} "
                "(--fixed-counts keeps every kind's count)"]

    def _initial_states(self) -> list[str]:
        """One line per agent (the first few): id, kind, status, position, variables."""
        r = self.result
        if isinstance(r.sim, _NoRun):
            return []
        start = r.initial
        n = len(start["id"])
        lines = []
        skip = {"id", "kind", "status", "pos", "vel", "heading", "index", "sense",
                "max_speed", "status_name", "kind_name"}
        for row in range(min(n, SHOWN_AGENTS)):
            x, y = start["pos"][row]
            vx, vy = start["vel"][row]
            extra = "".join(f", {name}={_value(col[row])}" for name, col in start.items()
                            if name not in skip and not name.startswith("_")
                            and r.sim.agents.declared.get(name) is not None
                            and start["_declared"][name][row])
            kind = start["kind_name"][row]
            status = str(start["status_name"][row]).removeprefix(f"{kind}.")
            lines.append(f"    agent {int(start['id'][row])} ({kind}, {status}): "
                         f"pos=({number_text(x)}, {number_text(y)}), "
                         f"vel=({number_text(vx, 3)}, {number_text(vy, 3)}){extra}")
        if n > SHOWN_AGENTS:
            lines.append(f"    ... and {n - SHOWN_AGENTS} more")
        return lines


def _value(v) -> str:
    v = np.asarray(v)
    if v.dtype == bool:
        return "true" if bool(v) else "false"
    if v.ndim:
        return "(" + ", ".join(number_text(x) for x in v.reshape(-1)) + ")"
    return number_text(v)


def number_text(x, digits: int = 6) -> str:
    """A value as a reader wants it in a counterexample: a whole number as one
    (`5263440`, never `5.26344e+06`, which hides the last digits), other numbers with
    `digits` significant digits, in plain decimals unless tiny or huge (below 1e-4 or
    from 1e16 on); `nan`, `inf`, `-inf` as such."""
    x = float(x)
    if not math.isfinite(x):
        return "nan" if math.isnan(x) else ("inf" if x > 0 else "-inf")
    if x == int(x) and abs(x) < 2**53:
        return str(int(x))
    if not 1e-4 <= abs(x) < 1e16:
        return f"{x:.{digits}g}"
    whole = math.floor(math.log10(abs(x))) + 1          # digits before the point
    text = f"{x:.{max(digits - whole, 1)}f}"
    return text.rstrip("0").rstrip(".") if "." in text else text


class _NoRun:
    """Stands in for a Simulation when the drawn params did not compile."""

    tick = 0
