"""A 20-node behaviour tree ticking for a whole swarm, against the same behaviour as a
`when` chain and against a per-agent tree interpreter, ticks per second.

Run from the repository root: ``python -m benchmarks.bench_trees [--n 100000]``.

The tree is a reactive fallback of four guarded sequences and a default (20 nodes:
conditions, an `invert`, assignments); the `when` chain says the same with one
`when COND -> same_status { v = ... }` per branch. Both compile to closures and are
timed alternately, tick by tick, in one process, so a busy machine slows both alike.
The per-agent interpreter walks the same tree one agent at a time in Python (the way
tree libraries tick one robot's tree), timed on a few ticks. All three must give every
agent the same `v`.

Two measures: whole simulation ticks (the shared work of every tick included: the
variable updates, the commit, the motion step) and the status body alone (the tree
statement against the `when` chain, run on one frame of every agent, against the
per-agent interpreter's tree tick alone).
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from swarmdsl.compiler import compile_source
from swarmdsl.runtime.frame import AgentFrame
from swarmdsl.runtime.simulation import Simulation

HEAD = """param n = 100000
world {{ size 1000 x 1000 }}
agent bot {{
  count n
  var a = index % 10
  var b = index % 7
  var c = (index % 100) / 100
  var v = 0
  status s {{
    a = (a + 1.7) % 10
    b = (b + 0.9) % 7
    c = (c + 0.37) % 1
{body}
  }}
}}
"""

TREE = """    tree reactive fallback {
      sequence { a > 8; b < 3; v = 1 }
      sequence { a > 6; invert b < 5; v = 2 }
      sequence { a > 4; c > 0.5; v = 3 }
      sequence { a > 2; c > 0.2; v = 4 }
      sequence { v = 5 }
    }"""

WHENS = """    when a > 8 and b < 3 -> s { v = 1 }
    when a > 6 and not (b < 5) -> s { v = 2 }
    when a > 4 and c > 0.5 -> s { v = 3 }
    when a > 2 and c > 0.2 -> s { v = 4 }
    v = 5"""

# The same tree as plain Python objects, for the per-agent interpreter.
PY_TREE = ("fallback", [
    ("sequence", [("cond", lambda g: g["a"] > 8), ("cond", lambda g: g["b"] < 3),
                  ("set", 1)]),
    ("sequence", [("cond", lambda g: g["a"] > 6),
                   ("invert", ("cond", lambda g: g["b"] < 5)), ("set", 2)]),
    ("sequence", [("cond", lambda g: g["a"] > 4), ("cond", lambda g: g["c"] > 0.5),
                  ("set", 3)]),
    ("sequence", [("cond", lambda g: g["a"] > 2), ("cond", lambda g: g["c"] > 0.2),
                  ("set", 4)]),
    ("sequence", [("set", 5)]),
])


def tick_one(node, agent) -> bool:
    """One agent's tick of an instant tree: True for success, False for failure."""
    tag = node[0]
    if tag == "cond":
        return bool(node[1](agent))
    if tag == "set":
        agent["v"] = float(node[1])
        return True
    if tag == "invert":
        return not tick_one(node[1], agent)
    if tag == "sequence":
        return all(tick_one(k, agent) for k in node[1])
    return any(tick_one(k, agent) for k in node[1])      # fallback


def per_agent_step(agents: list[dict]) -> None:
    for g in agents:
        g["a"] = (g["a"] + 1.7) % 10
        g["b"] = (g["b"] + 0.9) % 7
        g["c"] = (g["c"] + 0.37) % 1
        tick_one(PY_TREE, g)


def count_nodes(node) -> int:
    if node[0] in ("cond", "set"):
        return 1
    if node[0] == "invert":
        return 1 + count_nodes(node[1])
    return 1 + sum(count_nodes(k) for k in node[1])


def body_times(sims: dict, reps: int) -> dict[str, float]:
    """Median seconds of one run of the status body over every agent, interleaved."""
    times: dict[str, list[float]] = {k: [] for k in sims}
    for i in range(reps):
        order = list(sims.items()) if i % 2 else list(reversed(sims.items()))
        for name, sim in order:
            kind = sim.program.kinds[0]
            status = kind.statuses[0]
            f = AgentFrame(sim, np.arange(sim.agents.n), kind, status.name)
            f.next_status = np.zeros(f.n, dtype=np.int32)
            t0 = time.perf_counter()
            status.run(f)
            times[name].append(time.perf_counter() - t0)
    return {k: statistics.median(v) for k, v in times.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100_000)
    ap.add_argument("--ticks", type=int, default=100)
    ap.add_argument("--interpreter-ticks", type=int, default=3)
    args = ap.parse_args()
    over = {"n": str(args.n)}
    sims = {"tree": Simulation(compile_source(HEAD.format(body=TREE), "tree.swarm", over), 0),
            "when": Simulation(compile_source(HEAD.format(body=WHENS), "when.swarm", over), 0)}
    for sim in sims.values():
        sim.run(3)
    times: dict[str, list[float]] = {k: [] for k in sims}
    for i in range(args.ticks):
        order = list(sims.items()) if i % 2 else list(reversed(sims.items()))
        for name, sim in order:
            t0 = time.perf_counter()
            sim.step()
            times[name].append(time.perf_counter() - t0)
    same = np.array_equal(sims["tree"].agents.cols["v"], sims["when"].agents.cols["v"])

    cols = sims["tree"].agents.cols
    idx = np.arange(args.n)
    agents = [{"a": float(i % 10), "b": float(i % 7), "c": (i % 100) / 100, "v": 0.0}
              for i in idx]
    ref_sim = Simulation(compile_source(HEAD.format(body=TREE), "tree.swarm", over), 0)
    ref_times = []
    for _ in range(args.interpreter_ticks):
        t0 = time.perf_counter()
        per_agent_step(agents)
        ref_times.append(time.perf_counter() - t0)
        ref_sim.step()
    cols = ref_sim.agents.cols
    ref_same = all(g["v"] == cols["v"][i] and g["a"] == cols["a"][i]
                   for i, g in enumerate(agents))

    still = HEAD.replace("    a = (a + 1.7) % 10\n    b = (b + 0.9) % 7\n    c = (c + 0.37) % 1\n",
                         "")
    bodies = body_times({"tree": Simulation(compile_source(still.format(body=TREE),
                                                           "tree.swarm", over), 0),
                         "when": Simulation(compile_source(still.format(body=WHENS),
                                                           "when.swarm", over), 0)},
                        args.ticks)
    ref_bodies = []
    for _ in range(args.interpreter_ticks):
        t0 = time.perf_counter()
        for g in agents:
            tick_one(PY_TREE, g)
        ref_bodies.append(time.perf_counter() - t0)
    ref_body = statistics.median(ref_bodies)

    tree = statistics.median(times["tree"])
    when = statistics.median(times["when"])
    ref = statistics.median(ref_times)
    print(f"{args.n:,} agents, a {count_nodes(PY_TREE)}-node tree, median of "
          f"{args.ticks} interleaved ticks")
    print(f"tree (vectorised)  {tree * 1e3:9.2f} ms/tick  {1 / tree:9.1f} ticks/s")
    print(f"when chain         {when * 1e3:9.2f} ms/tick  {1 / when:9.1f} ticks/s")
    print(f"per-agent tree     {ref * 1e3:9.2f} ms/tick  {1 / ref:9.2f} ticks/s "
          f"({args.interpreter_ticks} ticks)")
    print(f"tree / when chain: {tree / when:.2f}x the time; per-agent / tree: "
          f"{ref / tree:.0f}x")
    print("the tree statement alone against the when chain alone (one frame of every "
          "agent):")
    print(f"tree (vectorised)  {bodies['tree'] * 1e3:9.2f} ms")
    print(f"when chain         {bodies['when'] * 1e3:9.2f} ms")
    print(f"per-agent tree     {ref_body * 1e3:9.2f} ms")
    print(f"tree / when chain: {bodies['tree'] / bodies['when']:.2f}x the time; "
          f"per-agent / tree: {ref_body / bodies['tree']:.0f}x")
    print(f"same v as the when chain: {same}; same v as the per-agent interpreter: "
          f"{ref_same}")


if __name__ == "__main__":
    main()
