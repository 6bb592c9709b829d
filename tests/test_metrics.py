"""Metrics: recorded values equal a direct computation from agents.parquet, summaries
in run.json, and mistakes located by the checker."""

from __future__ import annotations

import json

import numpy as np
import pyarrow.parquet as pq
import pytest
from conftest import REFERENCE
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


# ---- the swarm's geometry: clusters, the largest cluster, nearest-neighbour spacing ----

GEOMETRY = """
param n = 60
world {{ size 100 x 80; {edges} }}
agent a {{
  count n
  velocity random_direction() * 2
  status roaming {{
    let near = neighbors(15)
    velocity += 0.08 * sum(near : other.pos - pos) / max(count(near), 1)
    velocity = rotate(velocity, normal(0, 0.3))
    when count(near where dist < 8) >= 3 -> settled
  }}
  status settled {{ velocity = velocity * 0.5 }}
  metric groups = clusters(6)
}}
agent b {{
  count 7
  velocity (1.5, 0.5)
  status drifting {{ }}
}}
metric groups = clusters(6)
metric largest = largest_cluster(6)
metric share = largest_cluster(6) / count()
metric spacing = mean_nearest_distance()
metric settled_groups = clusters(10, status == settled)
metric settled_spacing = mean_nearest_distance(status == settled else -1)
"""
EDGES = {"wrap": "edges wrap", "repel": "edges repel 1.0"}


def _geometry_oracle(x, y, radius, box):
    """(clusters, largest, mean nearest distance) of points, by a dense distance matrix
    (no KD-tree, no pair table): the short way round measured as min(d, box - d)."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    n = len(x)
    if n == 0:
        return 0, 0, np.nan
    p = np.stack([x, y], 1)
    d = np.abs(p[:, None, :] - p[None, :, :])
    if box is not None:
        d = np.minimum(d % box, box - d % box)
    dist = np.sqrt((d ** 2).sum(-1))
    linked = dist <= radius
    np.fill_diagonal(linked, False)
    _k, labels = connected_components(csr_matrix(linked), directed=False)
    sizes = np.bincount(labels)
    np.fill_diagonal(dist, np.inf)
    nearest = dist.min(axis=1).mean() if n > 1 else np.nan
    return len(sizes), int(sizes.max()), nearest


def _expected_geometry(rows, box) -> dict[str, float]:
    """Every geometry metric of GEOMETRY at one tick of its agents.parquet."""
    x, y = rows.x.to_numpy(), rows.y.to_numpy()
    groups, largest, spacing = _geometry_oracle(x, y, 6, box)
    settled = (rows.status == "a.settled").to_numpy()
    a = (rows.kind == "a").to_numpy()
    s_groups, _l, s_spacing = _geometry_oracle(x[settled], y[settled], 10, box)
    a_groups, _l, _s = _geometry_oracle(x[a], y[a], 6, box)
    return {"groups": groups, "largest": largest, "share": largest / len(rows),
            "spacing": spacing, "settled_groups": s_groups,
            "settled_spacing": -1 if settled.sum() < 2 else s_spacing,
            "a.groups": a_groups}


def _assert_geometry_recorded(out, box) -> None:
    agents = pq.read_table(out / "agents.parquet").to_pandas()
    metrics = pq.read_table(out / "metrics.parquet").to_pandas()
    assert sorted(metrics.tick.unique()) == sorted(agents.tick.unique())
    settled_seen = False
    for tick, rows in agents.groupby("tick"):
        got = dict(zip(*(metrics[metrics.tick == tick][c] for c in ("name", "value")),
                       strict=True))
        want = _expected_geometry(rows, box)
        for name in ("groups", "largest", "settled_groups", "a.groups"):
            assert got[name] == want[name], (tick, name)
        for name in ("share", "spacing", "settled_spacing"):
            assert got[name] == pytest.approx(want[name], rel=1e-12), (tick, name)
        settled_seen |= want["settled_groups"] > 1
    assert 1 < want["groups"] < len(rows) and settled_seen   # a telling example


@pytest.mark.parametrize("edges", sorted(EDGES))
def test_geometry_metrics_equal_scipy_on_recorded_positions(backend, tmp_path, edges):
    """clusters, largest_cluster and mean_nearest_distance, over the swarm, a kind or
    the agents meeting a condition, recorded each tick as a dense-matrix computation on
    agents.parquet's positions finds them (the short way round in a wrap-around
    world)."""
    program = compile_source(GEOMETRY.format(edges=EDGES[edges]), "geometry.swarm")
    run = Run(program, seed=4, steps=24, out=tmp_path / "run", every=3, backend=backend)
    assert run.execute() == "completed"
    _assert_geometry_recorded(tmp_path / "run", (100.0, 80.0) if edges == "wrap" else None)


def test_geometry_metrics_are_the_same_bits_on_both_backends(tmp_path, other_backend):
    program = compile_source(GEOMETRY.format(edges=EDGES["wrap"]), "geometry.swarm")
    tables = []
    for backend in (REFERENCE, other_backend):
        out = tmp_path / backend
        assert Run(program, seed=9, steps=15, out=out, backend=backend).execute() == \
            "completed"
        tables.append(pq.read_table(out / "metrics.parquet"))
    assert tables[0].equals(tables[1])


def test_geometry_metrics_in_a_batch_are_each_replicas_solo_values(backend, tmp_path):
    """Replicas laid side by side never link across: each replica's clusters and
    spacing are its solo run's, bit for bit."""
    import swarmdsl
    from swarmdsl.runtime.batch import batch_refusal

    program = compile_source(GEOMETRY.format(edges=EDGES["wrap"]), "geometry.swarm")
    assert batch_refusal(program) is None
    results = swarmdsl.Batch(program, runs=[3, 5, 8], steps=12, every=2, backend=backend,
                             out=tmp_path / "batch").execute()
    assert [(r.replicas, r.solo) for r in results] == [(3, None)] * 3
    for r in results:
        solo = tmp_path / f"solo{r.seed}"
        assert Run(program, seed=r.seed, steps=12, every=2, out=solo,
                   backend=backend).execute() == "completed"
        assert pq.read_table(r.out / "metrics.parquet").equals(
            pq.read_table(solo / "metrics.parquet"))
        _assert_geometry_recorded(r.out, (100.0, 80.0))


def test_geometry_metrics_reach_a_sweeps_table(backend, tmp_path):
    """A sweep's summary table holds each run's cluster metrics: its `last` is the
    value scipy finds on the run's recorded last tick."""
    from swarmdsl.cli import main

    path = tmp_path / "geometry.swarm"
    path.write_text(GEOMETRY.format(edges=EDGES["wrap"]))
    out = tmp_path / "sweep"
    assert main(["sweep", str(path), "--set", "n=30,60", "--seeds", "2", "--steps", "8",
                 "--keep", "last,max", "--runs", "--out", str(out), "--workers", "1"]) == 0
    table = pq.read_table(out / "sweep.parquet").to_pandas()
    assert len(table) == 4 and (table.outcome == "completed").all()
    folders = {}
    for run_json in (out / "runs").glob("*/run.json"):
        meta = json.loads(run_json.read_text())
        folders[(meta["params"]["n"], meta["seed"])] = run_json.parent
    for row in table.to_dict("records"):
        agents = pq.read_table(folders[(row["n"], row["seed"])] / "agents.parquet"
                               ).to_pandas()
        last = agents[agents.tick == agents.tick.max()]
        want = _expected_geometry(last, (100.0, 80.0))
        assert row["largest.last"] == want["largest"]
        assert row["groups.last"] == want["groups"]
        assert row["a.groups.last"] == want["a.groups"]
        assert row["spacing.last"] == pytest.approx(want["spacing"], rel=1e-12)
        assert row["largest.max"] >= want["largest"]


def test_geometry_of_one_agent(backend):
    """One agent is one cluster of 1 and has no nearest neighbour (NaN, or the `else`);
    a kind with no agents has no clusters."""
    values = {"groups": 1, "largest": 1, "spacing": np.nan, "a.groups": 0,
              "settled_spacing": -1}
    program = compile_source(GEOMETRY.format(edges=EDGES["wrap"]).replace(
        "count 7", "count 1"), "few.swarm", {"n": "0"})
    from swarmdsl.runtime.metrics import evaluate
    from swarmdsl.runtime.simulation import Simulation

    sim = Simulation(program, 0, backend=backend)
    got = dict(zip([m.info.name for m in program.metrics], evaluate(program.metrics, sim),
                   strict=True))
    for name, want in values.items():
        assert got[name] == pytest.approx(want, nan_ok=True), name


def test_geometry_of_no_agents(backend):
    program = compile_source(GEOMETRY.format(edges=EDGES["wrap"]).replace(
        "count 7", "count 0"), "none.swarm", {"n": "0"})
    from swarmdsl.runtime.metrics import evaluate
    from swarmdsl.runtime.simulation import Simulation

    got = dict(zip([m.info.name for m in program.metrics],
                   evaluate(program.metrics, Simulation(program, 0, backend=backend)),
                   strict=True))
    assert got["groups"] == got["largest"] == got["a.groups"] == 0
    assert np.isnan(got["spacing"]) and got["settled_spacing"] == -1


_POINTS = st.lists(st.tuples(st.floats(0, 40, exclude_max=True),
                             st.floats(0, 30, exclude_max=True)), max_size=60)


@settings(max_examples=60)
@given(points=_POINTS, radius=st.floats(0.5, 12), wrap=st.booleans())
def test_cluster_sizes_and_spacing_match_a_dense_computation(points, radius, wrap):
    """Any points, within or across the edges of a wrap-around world: the clusters
    partition the agents, as the dense distance matrix links them."""
    from swarmdsl.runtime.metrics import cluster_sizes, mean_nearest_distance

    p = np.array(points, dtype=float).reshape(-1, 2)
    box = (40.0, 30.0) if wrap else None
    sizes = cluster_sizes(p, radius, box)
    groups, largest, spacing = _geometry_oracle(p[:, 0], p[:, 1], radius, box)
    assert sizes.sum() == len(p) and len(sizes) == groups
    assert sizes.max(initial=0) == largest
    assert mean_nearest_distance(p, box) == pytest.approx(spacing, rel=1e-12, abs=1e-12,
                                                          nan_ok=True)


@pytest.mark.parametrize("expr, where, message", [
    ("clusters(0)", 21, "the link radius of `clusters` must be positive, got 0"),
    ("largest_cluster(-3)", 28, "the link radius of `largest_cluster` must be positive, "
                                "got -3"),
    ("clusters(count())", 21, "the link radius of `clusters` must be a constant"),
    ("clusters()", 12, "`clusters` takes 1 or 2 arguments, got 0"),
    ("clusters(5, energy)", 24, "the condition of `clusters` (which agents it measures) "
                                "must be a boolean, got a number"),
    ("mean_nearest_distance(5)", 34, "the condition of `mean_nearest_distance` (which "
                                     "agents it measures) must be a boolean"),
    ("clusters(5 else 1)", 28, "`clusters` of no agents is well defined (0); `else` is "
                               "only for `mean_nearest_distance`"),
    ("mean(clusters(5))", 17, "`clusters` measures the whole swarm: it cannot go inside "
                              "a swarm aggregate"),
    ("cluster(5)", 12, "unknown function `cluster`"),
])
def test_geometry_metric_mistakes_are_located(expr, where, message):
    with pytest.raises(SwarmError) as info:
        compile_source(PROGRAM.format(expr=expr), "bad.swarm")
    assert f"bad.swarm:19:{where}: error: {message}" in str(info.value)
    if expr == "cluster(5)":
        assert "did you mean 'clusters'?" in info.value.render(PROGRAM.format(expr=expr))


def test_geometry_outside_a_metric_is_refused_at_the_call():
    text = PROGRAM.format(expr="1").replace(
        "energy = energy + normal(0, 1)", "energy = clusters(5)")
    with pytest.raises(SwarmError) as info:
        compile_source(text, "bad.swarm")
    assert "bad.swarm:9:14: error: `clusters` measures the whole swarm: it is for " \
        "`metric` declarations" in str(info.value)


def test_the_checker_knows_every_geometry_measure_the_runtime_computes():
    from swarmdsl.compiler.lang_metrics import MEASURES
    from swarmdsl.runtime.metrics import SWARM_MEASURES

    assert tuple(MEASURES) == SWARM_MEASURES
