"""What a hunt tried, so that a pass says what it rests on.

"Exercised by 75 of 75 runs" counted a run as soon as one agent was checked, while no
run had more than 16 of the program's 80 agents. A `Coverage` keeps, over every run of
a hunt: per property the runs that exercised it and the agent-ticks at which it was
checked (and, for an implication-shaped invariant or an `always`, at which its premise
or trigger held); the largest swarm and the longest run; whether any run had the
program's declared counts and reached its horizon; and how many runs were the program
as written and how many were drawn, with the sizes drawn.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class PropertyCoverage:
    """What the hunt's runs did to one property."""

    runs: int = 0               # runs that exercised it (`monitor.py`)
    agent_ticks: int = 0        # agent-ticks (swarm property: ticks) it was checked
    premise_runs: int = 0       # runs in which its premise (trigger) held at least once
    premise_ticks: int = 0      # agent-ticks its premise held
    premise_measured: bool = False


@dataclass
class Coverage:
    """What every run of a hunt (not its shrinking) tried, added run by run."""

    declared: dict[str, int]            # each kind's count in the program as written
    horizon: int                        # the program's own horizon, in ticks
    runs: int = 0
    as_written: int = 0                 # runs of the program as written
    as_written_seeds: list[int] = field(default_factory=list)
    sizes: list[int] = field(default_factory=list)      # drawn runs: agents at the start
    largest: int = 0                    # most agents any run started with
    longest: int = 0                    # most ticks any run made
    reached_counts: bool = False        # a run started with every declared count
    reached_horizon: bool = False       # a run made the program's horizon
    properties: dict[str, PropertyCoverage] = field(default_factory=dict)

    def add(self, result, drawn: bool) -> None:
        """Count one run (a `RunResult`)."""
        self.runs += 1
        start = result.initial
        counts: dict[str, int] = {}
        if start is not None:
            for kind in start["kind_name"]:
                counts[str(kind)] = counts.get(str(kind), 0) + 1
        agents = sum(counts.values())
        ticks = int(getattr(result.sim, "tick", 0))
        if drawn:
            self.sizes.append(agents)
        self.largest = max(self.largest, agents)
        self.longest = max(self.longest, ticks)
        if start is not None and all(counts.get(k, 0) >= n for k, n in self.declared.items()):
            self.reached_counts = True
        if ticks >= self.horizon:
            self.reached_horizon = True
        for name in result.exercised:
            self._of(name).runs += 1
        for name, n in result.agent_ticks.items():
            self._of(name).agent_ticks += n
        for name, n in result.premise_ticks.items():
            c = self._of(name)
            c.premise_ticks += n
            c.premise_runs += n > 0
        for name in result.premised:
            self._of(name).premise_measured = True

    def _of(self, name: str) -> PropertyCoverage:
        return self.properties.setdefault(name, PropertyCoverage())

    def of(self, name: str) -> PropertyCoverage:
        return self.properties.get(name, PropertyCoverage())

    def tried(self) -> str:
        """What the runs were, for the summary line: `3 of the program as written (80
        agents, seeds 0-2), 72 drawn (1 to 80 agents, median 41)`."""
        parts = []
        if self.as_written:
            total = sum(self.declared.values())
            seeds = self.as_written_seeds
            shown = f"seed {seeds[0]}" if len(seeds) == 1 else \
                f"seeds {seeds[0]}-{seeds[-1]}"
            parts.append(f"{self.as_written} of the program as written ({total} "
                         f"agent{'s' * (total != 1)}, {shown})")
        if self.sizes:
            s = sorted(self.sizes)
            median = s[len(s) // 2]
            parts.append(f"{len(s)} drawn ({s[0]} to {s[-1]} agents, median {median})")
        return ", ".join(parts)

    def warnings(self, steps: int, steps_why: str) -> list[str]:
        """What no run reached: the declared counts, the program's horizon."""
        out = []
        if not self.reached_counts:
            counts = ", ".join(f"`{k}` {n}" for k, n in self.declared.items())
            out.append(f"no run had the program's declared counts ({counts}; the "
                       f"largest swarm tried had {self.largest} agents): its pass says "
                       "nothing of a swarm that large")
        if not self.reached_horizon:
            out.append(f"no run reached the program's horizon of {self.horizon} ticks "
                       f"(the longest ran {self.longest}; runs of up to {steps} ticks, "
                       f"{steps_why})")
        return out
