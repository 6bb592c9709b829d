"""Which of a sweep's runs tick together as batches, and why the others run solo.

Params are compiled into the program, so only runs of one param combination (its
seeds) can share a batch. By default (`batch_runner.replicas_per_batch`) a combination's
runs are batched when they are small (at most SMALL_RUN_AGENTS agents each), as many to
a batch as fit in BATCH_AGENTS agents and no more than keep every worker busy; `--batch
R` asks for at most R replicas a batch, `--no-batch` for solo runs. Small runs that
would take numba's whole ticks by default (their whole-tick kernel kept on disk here,
and long enough to repay loading it: `choice.whole_saving`) run solo, which a batch
cannot do. A combination's runs
are split into batches of sizes as even as that allows. A program the batch refuses
(`batch_refusal`) runs solo, and `-v` says why. Each run keeps its own key, so a
started-again sweep plans the runs still missing, batched alike.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from swarmdsl.errors import SwarmError


@dataclass
class Plan:
    tasks: list[tuple[str, tuple]] = field(default_factory=list)   # (kind, arguments)
    notes: list[str] = field(default_factory=list)                 # what -v says
    batches: int = 0
    batched_runs: int = 0

    def solo(self, call: tuple) -> None:
        self.tasks.append(("one", call))


def plan_tasks(calls: list[tuple], batch: int | None, workers: int, program) -> Plan:
    """Tasks for `calls` (`run_one`'s arguments, in the sweep's order): `batch` None for
    the default rule, 0 for `--no-batch`, R for `--batch R`. `program` is the sweep's
    program at its own params: what the batch refuses is a construct of its text, the
    same for every param value, so a refused program is not compiled once per param
    combination here (the workers compile each once, as they run it)."""
    from swarmdsl.runtime.batch_runner import (
        SMALL_RUN_AGENTS,
        agents_of,
        batch_refusal_of,
        even_chunks,
        replicas_per_batch,
    )
    from swarmdsl.runtime.compiled.choice import LOAD, whole_saving
    from swarmdsl.sweep.worker import _compiled

    def whole_ticks(program, steps) -> bool:
        """Whether a solo run takes numba's whole ticks by default (`choice.choose`),
        which no batch does: the program's whole-tick kernel kept here, and a run long
        enough to repay loading it."""
        ticks = steps if steps is not None else program.world.steps
        gain = whole_saving(program, ticks * agents_of(program))
        return gain is not None and gain > LOAD

    plan = Plan()
    groups: dict[tuple, list[tuple]] = {}
    for call in calls:
        groups.setdefault(call[2], []).append(call)
    if batch == 0 or batch == 1:
        plan.tasks = [("one", call) for call in calls]
        plan.notes.append(f"{len(calls)} run{'s' * (len(calls) != 1)} solo "
                          f"({'--no-batch' if batch == 0 else '--batch 1'})")
        return plan
    refusal = batch_refusal_of(program)
    if refusal is not None:
        plan.tasks = [("one", call) for call in calls]
        plan.notes.append(f"{len(calls)} run{'s' * (len(calls) != 1)} solo: {refusal}")
        return plan
    for params, group in groups.items():
        label = ", ".join(f"{n}={v}" for n, v in params) or "the runs"
        if len(group) == 1:
            plan.solo(group[0])
            plan.notes.append(f"{label}: 1 run, solo (a batch holds runs of the same "
                              "params)")
            continue
        path, source, _params, _seed, steps, every, _folder, program_dir = group[0]
        try:
            program = _compiled(path, source, params, program_dir)
        except SwarmError:
            for call in group:      # each run records why in its row
                plan.solo(call)
            plan.notes.append(f"{label}: {len(group)} runs solo (the program does not "
                              "compile with these params)")
            continue
        refusal = batch_refusal_of(program)
        agents = agents_of(program)
        if refusal is not None:
            for call in group:
                plan.solo(call)
            plan.notes.append(f"{label}: {len(group)} runs solo: {refusal}")
            continue
        size = batch if batch is not None else replicas_per_batch(agents, len(calls),
                                                                   workers)
        if batch is None and size >= 2 and whole_ticks(program, steps):
            for call in group:
                plan.solo(call)
            plan.notes.append(f"{label}: {len(group)} runs solo: each takes whole ticks "
                              "from kernels kept on disk, faster than a batch of replicas")
            continue
        if size < 2:
            for call in group:
                plan.solo(call)
            why = (f"runs of {agents:,} agents are batched only with --batch R (the "
                   f"default batches runs of up to {SMALL_RUN_AGENTS:,})"
                   if agents > SMALL_RUN_AGENTS else "one run per worker keeps every "
                   "worker busy")
            plan.notes.append(f"{label}: {len(group)} runs solo: {why}")
            continue
        chunks = even_chunks(group, size)
        for chunk in chunks:
            if len(chunk) == 1:
                plan.solo(chunk[0])
                continue
            seeds = [call[3] for call in chunk]
            folders = {call[3]: call[6] for call in chunk} if chunk[0][6] else None
            plan.tasks.append(("batch", (path, source, params, seeds, steps, every,
                                         folders, program_dir)))
            plan.batches += 1
            plan.batched_runs += len(chunk)
        # a single run left over (only when no even split avoids one) runs solo: the
        # note counts only the batched runs
        sizes = [len(c) for c in chunks if len(c) > 1]
        plan.notes.append(f"{label}: {sum(sizes)} runs in {len(sizes)} batch"
                          f"{'es' * (len(sizes) != 1)} of "
                          f"{'up to ' * (len(set(sizes)) > 1)}{max(sizes)} "
                          f"replicas ({agents:,} agents a run)"
                          + (", 1 run solo (left over)" if len(chunks[-1]) == 1 else ""))
    return plan
