"""Behaviour trees in the tools: `swarmdsl graph` draws them, `run --tree-leaf` records
each agent's active leaf."""

from __future__ import annotations

from pathlib import Path

import pyarrow.parquet as pq

from swarmdsl.cli import main
from swarmdsl.compiler import compile_source
from swarmdsl.runtime.runner import Run

PATROL = Path(__file__).resolve().parent.parent / "programs" / "patrol.swarm"

LEAFY = """world { size 100 x 100 }
agent bot {
  count 2
  var t = 0
  status s {
    t += 1
    tree sequence { wait(2); t > 0 }
    on success -> done
  }
  status done { }
}
"""


def test_graph_dot_draws_each_tree_beside_its_status(capsys):
    assert main(["graph", str(PATROL)]) == 0
    dot = capsys.readouterr().out
    assert dot.count("digraph") == 1 and dot.rstrip().endswith("}")
    assert 'subgraph "cluster_tree_robot.patrol"' in dot
    nodes = [line for line in dot.splitlines() if line.strip().startswith('"tree:')
             and "[label=" in line]
    edges = [line for line in dot.splitlines() if line.strip().startswith('"tree:')
             and "->" in line]
    assert len(nodes) == 11 and len(edges) == 10          # a tree: one parent each
    assert '[label="reactive fallback", shape=box' in nodes[0]
    assert any('label="move_to(p, 2, cruise)", shape=box, style=bold' in n for n in nodes)
    assert any('label="battery < low", shape=ellipse' in n for n in nodes)
    assert '"robot.patrol" -> "tree:robot.patrol:0" [style=dashed' in dot


def test_graph_mermaid_adds_one_flowchart_per_tree(tmp_path, capsys):
    assert main(["graph", str(PATROL), "--format", "mermaid"]) == 0
    text = capsys.readouterr().out
    assert text.startswith("stateDiagram-v2")
    chart = text[text.index("flowchart TD"):]
    assert chart.count(" --> ") == 10
    assert 'n0(["reactive fallback"])' in chart
    out = tmp_path / "g.md"
    assert main(["graph", str(PATROL), "-o", str(out)]) == 0
    assert out.read_text().count("```mermaid") == 2


def test_run_records_the_active_leaf_when_asked(backend, tmp_path):
    program = compile_source(LEAFY, "leafy.swarm")
    Run(program, steps=4, out=tmp_path / "a", tree_leaf=True, backend=backend).execute()
    rows = pq.read_table(tmp_path / "a" / "agents.parquet").to_pandas()
    one = rows[rows["id"] == 0]["tree_leaf"]
    assert one.isna().tolist() == [True, False, False, False, True]   # tick 0; done
    assert one.tolist()[1:4] == ["7:21 wait(2)", "7:21 wait(2)", "7:30 t > 0"]
    Run(compile_source(LEAFY, "leafy.swarm"), steps=2, out=tmp_path / "b",
        backend=backend).execute()
    assert "tree_leaf" not in pq.read_table(tmp_path / "b" / "agents.parquet").column_names


def test_run_records_each_agents_tree_result_beside_its_leaf(backend, tmp_path):
    program = compile_source(LEAFY, "leafy.swarm")
    Run(program, steps=4, out=tmp_path / "a", tree_leaf=True, backend=backend).execute()
    rows = pq.read_table(tmp_path / "a" / "agents.parquet").to_pylist()
    one = [r["tree_result"] for r in rows if r["id"] == 0]
    assert one == [None, "running", "running", "success", None]   # tick 0; done
    Run(compile_source(LEAFY, "leafy.swarm"), steps=2, out=tmp_path / "b",
        backend=backend).execute()
    assert "tree_result" not in pq.read_table(tmp_path / "b" / "agents.parquet").column_names


def test_a_named_trees_leaves_are_recorded_with_each_uses_arguments(backend, tmp_path):
    # both uses were recorded as `move_to(p, 2, s)`: which one an agent ran was lost
    source = """world { size 100 x 100 }
tree go(p, s) { sequence { move_to(p, 2, s); other_p > 0 } }
agent bot {
  count 2
  var other_p = 1
  var p0 = (80, 80)
  status s {
    tree fallback { sequence { index == 0; go((10, 10), 1) }; go(p0 + (1, 0), 2) }
  }
}
"""
    program = compile_source(source, "uses.swarm")
    assert "2:28 move_to((10, 10), 2, 1)" in program.tree_leaf_names
    assert "2:28 move_to((p0 + (1, 0)), 2, 2)" in program.tree_leaf_names
    assert "2:46 other_p > 0" in program.tree_leaf_names     # `other_p` is not `p`
    Run(program, steps=2, out=tmp_path / "a", tree_leaf=True, backend=backend).execute()
    rows = pq.read_table(tmp_path / "a" / "agents.parquet").to_pandas()
    last = rows[rows.tick == 2].set_index("id")["tree_leaf"]
    assert last[0] == "2:28 move_to((10, 10), 2, 1)"
    assert last[1] == "2:28 move_to((p0 + (1, 0)), 2, 2)"


def test_cli_run_tree_leaf(backend, tmp_path, capsys):
    src = tmp_path / "leafy.swarm"
    src.write_text(LEAFY)
    assert main(["run", str(src), "--headless", "--steps", "3", "--out",
                 str(tmp_path / "o"), "--tree-leaf"]) == 0
    names = pq.read_table(tmp_path / "o" / "agents.parquet").column_names
    assert names[-2:] == ["tree_leaf", "tree_result"]


def test_viewer_colours_agents_by_active_leaf(backend):
    pytest = __import__("pytest")
    pygame = pytest.importorskip("pygame")
    from swarmdsl.runtime.simulation import Simulation
    from swarmdsl.runtime.trees import record_active_leaf
    from swarmdsl.viz.frames import FrameRenderer, RenderOptions
    from swarmdsl.viz.palette import leaf_colours, leaf_legend_entries
    from swarmdsl.viz.viewer import ViewState

    src = LEAFY.replace("count 2", "count 2\n  place (20 + 60 * index, 50)").replace(
        "wait(2)", "wait(index)")
    sim = Simulation(compile_source(src, "leafy.swarm"), seed=0, backend=backend)
    record_active_leaf(sim)
    sim.step()
    snap = sim.snapshot()
    assert snap.tree_leaf.tolist() == [2, 1]   # agent 0: wait(0) done, on to `t > 0`
    colours = leaf_colours(snap)
    assert colours[0].tolist() != colours[1].tolist()
    assert [e[:2] for e in leaf_legend_entries(snap)] == [("8:21 wait(index)", 1),
                                                          ("8:34 t > 0", 1)]
    by_leaf = FrameRenderer(128, 128).render(snap, RenderOptions(by_tree_leaf=True))
    by_status = FrameRenderer(128, 128).render(snap, RenderOptions())
    assert not (by_leaf == by_status).all()
    state = ViewState(RenderOptions())
    state.handle(pygame, pygame.event.Event(pygame.KEYDOWN, key=pygame.K_t, unicode="t"))
    assert state.options.by_tree_leaf


def test_viewer_shows_the_running_path_of_a_clicked_agent(backend):
    pytest = __import__("pytest")
    pygame = pytest.importorskip("pygame")
    from swarmdsl.runtime.simulation import Simulation
    from swarmdsl.runtime.trees import record_active_leaf
    from swarmdsl.viz.frames import FrameRenderer, RenderOptions
    from swarmdsl.viz.viewer import ViewState

    sim = Simulation(compile_source(LEAFY.replace("count 2", "count 1\n  place (50, 50)"),
                                    "leafy.swarm"), seed=0, backend=backend)
    record_active_leaf(sim)
    sim.step()
    snap = sim.snapshot()
    renderer = FrameRenderer(128, 128)
    state = ViewState(RenderOptions())
    state.handle(pygame, pygame.event.Event(pygame.MOUSEBUTTONDOWN, pos=(64, 64), button=1))
    assert state.click == (64, 64)
    state.selected = renderer.agent_at(snap, state.click)
    assert state.selected == 0
    assert state.selection_note(snap) == "agent 0 (s): sequence > wait(2)"
    assert renderer.agent_at(snap, (2, 2)) is None          # nobody near a corner


def test_run_records_tree_memory_when_asked(backend, tmp_path):
    program = compile_source(LEAFY.replace("wait(2)", "wait(3)"), "leafy.swarm")
    Run(program, steps=3, out=tmp_path, tree_memory=True, backend=backend).execute()
    rows = pq.read_table(tmp_path / "agents.parquet").to_pandas()
    one = rows[rows["id"] == 0]
    # the sequence's running child (0: the wait) and the wait's elapsed ticks
    assert one["tree:bot.s:1:elapsed"].tolist() == [0, 1, 2, 3]
    assert one["tree:bot.s:1:stamp"].tolist() == [-2, 0, 1, 2]
    assert one["tree:bot.s:stamp"].tolist() == [-2, 0, 1, 2]


def test_tree_options_on_a_program_without_trees_say_so(backend, walk, tmp_path, capsys):
    """`--tree-leaf` recorded a column of nulls without a word."""
    assert main(["run", str(walk), "--headless", "--steps", "2", "--tree-leaf",
                 "--tree-memory", "--out", str(tmp_path / "out")]) == 0
    err = capsys.readouterr().err
    assert (f"warning: --tree-leaf and --tree-memory: {walk} has no behaviour tree, "
            "so there is nothing to record") in err


def test_tree_options_on_a_tree_program_are_quiet(backend, capsys):
    patrol = Path(__file__).resolve().parent.parent / "programs" / "patrol.swarm"
    assert main(["run", str(patrol), "--headless", "--steps", "1", "--tree-leaf"]) == 0
    assert "warning" not in capsys.readouterr().err
