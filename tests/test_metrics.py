"""Metrics: recorded values equal a direct computation from agents.parquet, summaries
in run.json, and mistakes located by the checker."""

from __future__ import annotations

import json

import numpy as np
import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmdsl.compiler import compile_source
from swarmdsl.compiler.errors import SwarmError
from swarmdsl.runtime.runner import Run

PROGRAM = """
param n = 30
world {{ size 100 x 100; edges wrap }}
agent a {{
  count n
  velocity random_direction() * uniform(0.5, 2)
  var energy = uniform(0, 10)
  status s {{
    energy = energy + normal(0, 1)
    velocity = rotate(velocity, normal(0, 0.3))
  }}
  metric kind_energy = mean(energy)
}}
agent b {{
  count 5
  velocity (1, 0)
  status t {{ }}
}}
metric m = {expr}
"""

# metric expression -> oracle over one tick's rows of agents.parquet (both kinds)
CASES = {
    "mean(speed)": lambda d, c: np.hypot(d["vx"], d["vy"]).mean(),
    "count(pos.x < {c})": lambda d, c: np.count_nonzero(d["x"] < c),
    "length(mean(normalize(vel)))": lambda d, c: np.linalg.norm(
        (np.stack([d["vx"], d["vy"]], 1)
         / np.hypot(d["vx"], d["vy"])[:, None]).mean(axis=0)),
    "max(pos.y) - min(pos.y)": lambda d, c: d["y"].max() - d["y"].min(),
    "sum(if kind == a then 1 else 0)": lambda d, c: np.count_nonzero(d["kind"] == "a"),
    "all(pos.x >= {c})": lambda d, c: float(np.all(d["x"] >= c)),
}


def _run(tmp_path, expr: str, seed: int, steps: int, every: int):
    program = compile_source(PROGRAM.format(expr=expr), "metric.swarm")
    out = tmp_path / f"run-{seed}-{steps}-{every}"
    run = Run(program, seed=seed, steps=steps, out=out, every=every)
    assert run.execute() == "completed"
    return out


@settings(max_examples=15)
@given(case=st.sampled_from(sorted(CASES)), c=st.integers(0, 100),
       seed=st.integers(0, 2**31), steps=st.integers(0, 12), every=st.integers(1, 5))
def test_recorded_metric_equals_direct_computation(backend, tmp_path_factory, case, c, seed, steps,
                                                   every):
    tmp = tmp_path_factory.mktemp("m")
    out = _run(tmp, case.format(c=c), seed, steps, every)
    agents = pq.read_table(out / "agents.parquet").to_pandas()
    metrics = pq.read_table(out / "metrics.parquet").to_pandas()
    assert list(metrics.columns) == ["tick", "name", "value"]
    m = metrics[metrics.name == "m"]
    assert list(m.tick) == sorted(agents.tick.unique())
    for tick, value in zip(m.tick, m.value, strict=True):
        rows = agents[agents.tick == tick]
        d = {k: rows[k].to_numpy() for k in ("x", "y", "vx", "vy", "kind")}
        assert value == pytest.approx(CASES[case](d, c), rel=1e-9, abs=1e-9)
        per_kind = metrics[(metrics.name == "a.kind_energy") & (metrics.tick == tick)]
        assert per_kind.value.item() == pytest.approx(
            rows[rows.kind == "a"].energy.mean(), rel=1e-12)


def test_run_json_summarises_each_metric(backend, tmp_path):
    out = _run(tmp_path, "mean(pos.x)", seed=3, steps=20, every=2)
    summary = json.loads((out / "run.json").read_text())["metrics"]
    assert set(summary) == {"m", "a.kind_energy"}
    metrics = pq.read_table(out / "metrics.parquet").to_pandas()
    m = metrics[metrics.name == "m"]
    assert summary["m"]["last"] == m.value.iloc[-1]
    assert summary["m"]["min"] == m.value.min()
    assert summary["m"]["max"] == m.value.max()
    assert summary["m"]["mean"] == pytest.approx(m.value[m.tick >= 10].mean())


def test_program_without_metrics_writes_no_metrics_file(backend, tmp_path):
    program = compile_source("agent a { count 3; status s { } }", "none.swarm")
    Run(program, steps=3, out=tmp_path).execute()
    assert (tmp_path / "agents.parquet").exists()
    assert not (tmp_path / "metrics.parquet").exists()
    assert "metrics" not in json.loads((tmp_path / "run.json").read_text())


@pytest.mark.parametrize("expr, message", [
    ("mean(normalize(vel))", "a metric is one number, got a vector"),
    ("speed", "`speed` is a value of each agent"),
    ("count(neighbors(3))", "metrics cannot query neighbours"),
    ("mean(random())", "cannot draw random numbers"),
    ("mean(bogus)", "unknown name `bogus`"),
])
def test_metric_mistakes_are_located(expr, message):
    with pytest.raises(SwarmError) as info:
        compile_source(PROGRAM.format(expr=expr), "bad.swarm")
    text = str(info.value)
    assert message in text
    assert text.startswith("bad.swarm:19:")



# ---- a top-level metric over kinds that do not all declare its variable ----

def _first_tick(program) -> dict[str, float]:
    from swarmdsl.runtime.metrics import MetricLog
    from swarmdsl.runtime.simulation import Simulation

    log = MetricLog(program)
    log.sample(Simulation(program, 0))
    _ticks, values = log.pending()
    return dict(zip(log.names, values[0], strict=True))


PARTIAL = """
agent a {{ count 3; var s = 4; status x {{ }} }}
agent b {{ count 1; status y {{ }} }}
metric m = {expr}
"""


@pytest.mark.parametrize("expr, value, hint", [
    ("mean(s)", 3.0, "declare the metric inside `agent a` to reduce over that kind "
                     "(reported as `a.m`)"),
    ("count(s < 5)", 4.0, "narrow it to the kind: `count(kind == a and ...)`"),
])
def test_a_variable_only_some_kinds_declare_is_warned_where_the_default_counts(
        backend, expr, value, hint):
    """The default is no mistake in the arithmetic (b reads s as 0, so the mean of
    4, 4, 4 and 0 is 3), but rarely what the experimenter meant."""
    prog = compile_source(PARTIAL.format(expr=expr), "p.swarm")
    col = len("metric m = ") + expr.index("(") + 2   # 1-based, after the bracket
    assert [(str(w), w.hint) for w in prog.info.warnings] == [
        (f"p.swarm:4:{col}: warning: `s` is a variable of `a` only: this "
         f"`{expr[:expr.index('(')]}` over every agent reads it as 0 for the agents of "
         "`b`", hint)]
    assert _first_tick(prog)["m"] == value


@pytest.mark.parametrize("expr, value", [
    ("count(kind == a and s < 5)", 3.0),   # the narrowing idiom
    ("sum(s)", 12.0),                      # b's zeros add nothing
    ("mean(if kind == a then s else 4)", 4.0),
])
def test_a_metric_that_narrows_to_the_kind_or_sums_is_not_warned(backend, expr, value):
    prog = compile_source(PARTIAL.format(expr=expr), "p.swarm")
    assert prog.info.warnings == []
    assert _first_tick(prog)["m"] == value


def test_a_variable_every_kind_declares_or_a_per_kind_metric_is_not_warned():
    both = ("agent a { count 3; var s = 4; status x { }; metric own = mean(s) }\n"
            "agent b { count 1; var s = 2; status y { } }\nmetric m = mean(s)\n")
    assert compile_source(both, "p.swarm").info.warnings == []


def test_vicsek_orders_at_low_noise_and_not_at_high_noise(backend):
    from pathlib import Path

    from swarmdsl.compiler import compile_file

    path = Path(__file__).resolve().parent.parent / "programs" / "vicsek.swarm"
    order = {}
    for eta in ("0.5", "5.5"):
        run = Run(compile_file(path, {"eta": eta, "n": "200", "size": "7"}), seed=1,
                  steps=200)
        run.show_progress = False
        assert run.execute() == "completed"
        order[eta] = run.metrics.summary()["polarisation"]["mean"]
    assert order["0.5"] > 0.9
    assert order["5.5"] < 0.25


# ---- aggregates over no agents: 0, (0, 0) for a vector, or the `else` ----

EMPTY = """
param n = 0
param m = 2
agent a {{
  count n
  var v = (1, 2)
  status s {{ v += (1, 0) }}
  metric of_a = {expr}
}}
agent b {{
  count m
  velocity (3, 4)
  status t {{ }}
}}
metric of_all = {expr}
"""

OF_NO_AGENTS = [
    ("length(mean(vel))", 0.0),
    ("mean(v).x + mean(v).y", 0.0),            # a vector mean over no agents is (0, 0)
    ("length(sum(v))", 0.0),
    ("mean(v else (3, 4)).y", 4.0),
    ("min(v.x) + max(v.y)", 0.0),
    ("max(v.x else -1)", -1.0),
    ("count() + count(v.x > 0)", 0.0),
    ("all(v.x > 0)", 1.0),
    ("any(v.x > 0)", 0.0),
]


def _sampled(expr: str, overrides=None) -> dict[str, float]:
    """Each metric's value, the same at tick 0 and tick 1."""
    from swarmdsl.runtime.metrics import MetricLog
    from swarmdsl.runtime.simulation import Simulation

    program = compile_source(EMPTY.format(expr=expr), "empty.swarm", overrides)
    sim = Simulation(program, 0)
    log = MetricLog(program)
    log.sample(sim)
    sim.step()
    log.sample(sim)
    ticks, values = log.pending()
    assert list(ticks) == [0, 1]
    assert (values[0] == values[1]).all()
    return dict(zip(log.names, values[1], strict=True))


@pytest.mark.parametrize(("expr", "value"), OF_NO_AGENTS)
def test_a_metric_of_a_kind_with_no_agents(backend, expr, value):
    assert _sampled(expr)["a.of_a"] == value     # `b` has agents, `a` none


@pytest.mark.parametrize(("expr", "value"), OF_NO_AGENTS)
def test_a_metric_of_a_swarm_with_no_agents(backend, expr, value):
    assert _sampled(expr, {"m": "0"}) == {"of_all": value, "a.of_a": value}


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_vicsek_with_no_agents_records_its_metrics(tmp_path, backend):
    from pathlib import Path

    from swarmdsl.cli import main

    program = Path(__file__).parent.parent / "programs" / "vicsek.swarm"
    out = tmp_path / "v0"
    assert main(["run", str(program), "--headless", "--steps", "5", "--set", "n=0",
                 "--out", str(out), "--backend", backend]) == 0
    metrics = pq.read_table(out / "metrics.parquet").to_pandas()
    polar = metrics[metrics.name == "polarisation"]
    assert list(polar.tick) == [0, 1, 2, 3, 4, 5]
    assert (polar.value == 0.0).all()


def test_a_batchs_rows_logged_at_once_are_each_replicas_log(monkeypatch):
    """`MetricLog.add_rows` (a batch's every replica at one tick) keeps what `add_row`
    per replica keeps: the same samples, counts and summaries, a repeated tick once,
    and chunks gathered as they fill."""
    from swarmdsl.runtime import metrics
    from swarmdsl.runtime.metrics import MetricLog

    monkeypatch.setattr(metrics, "_CHUNK", 3)
    program = compile_source(PROGRAM.format(expr="mean(energy)"), "m.swarm")
    rng = np.random.default_rng(1)
    one = [MetricLog(program) for _ in range(4)]
    rows = [MetricLog(program) for _ in range(4)]
    for tick in (0, 1, 1, 2, 3, 5, 6, 7):
        values = rng.standard_normal((4, len(program.metrics)))
        for log, row in zip(one, values, strict=True):
            log.add_row(tick, row)
        MetricLog.add_rows(rows, tick, values.copy())
    for a, b in zip(one, rows, strict=True):
        assert a.count == b.count == 7 and a.last_tick == b.last_tick == 7
        assert a.pending_bytes == b.pending_bytes
        for x, y in zip(a.pending(), b.pending(), strict=True):
            assert x.tobytes() == y.tobytes()
        assert a.summary() == b.summary()
