"""Static analysis of status graphs (check warnings and notes) and `swarmdsl graph`."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import cli_error

from swarmdsl.cli import main
from swarmdsl.compiler import compile_file
from swarmdsl.compiler.guards import disjoint, truth
from swarmdsl.compiler.parse import parse
from swarmdsl.compiler.status_graph import kind_graphs

FORAGING = Path(__file__).parent / "data" / "props" / "foraging.swarm"


def _messages(prog, severity="warning"):
    if severity == "note":
        return [(n.span.line, n.message) for n in prog.info.extra["notes"]]
    return [(w.span.line, w.message) for w in prog.info.warnings]


def test_unreachable_status_and_dead_end_are_flagged(compile_src):
    prog = compile_src("""agent a {
  count 2
  var t = 0
  status start { t += 1; when t > 3 -> stuck }
  status stuck { t = 0 }
  status orphan { when t > 9 -> start }
}
""")
    assert _messages(prog) == [   # in source order, as errors are
        (5, "status `stuck` of `a` has no way out: no transition leaves it"),
        (6, "status `orphan` of `a` is unreachable: no transition leads to it from the "
            "initial status"),
    ]


def test_single_status_kind_is_not_a_dead_end(compile_src):
    assert _messages(compile_src("agent a { count 1; status only { } }\n")) == []


def test_never_true_guard_is_flagged_and_its_target_unreachable(compile_src):
    prog = compile_src("""param lim = 3
agent a {
  count 2
  var t = 0
  status go { t += 1; when t > 5 and t < lim -> stop; when false -> stop }
  status stop { when true -> go }
}
""")
    got = _messages(prog)
    assert (5, "this condition is never true: `go` never goes to `stop` here") in got
    assert sum(m.startswith("this condition is never true") for _, m in got) == 2
    assert (6, "status `stop` of `a` is unreachable: no transition leads to it from the "
               "initial status") in got


def test_overlapping_guards_get_a_note_and_disjoint_ones_do_not(compile_src):
    prog = compile_src("""agent a {
  count 2
  var t = 0
  status s {
    t += 1
    when t > 5 -> x
    when t > 8 -> y
    when t < 2 -> x
  }
  status x { when true -> s; when t > 3 -> y }
  status y { when t == 1 -> s; when t == 2 -> x }
}
""")
    notes = _messages(prog, "note")
    assert (7, "in `a.s`, this condition and the one on line 6 can hold together; the first "
               "listed wins (`x` over `y`)") in notes
    assert (10, "this condition is always true: the `when`s after it in `x` never fire") \
        in notes
    assert not any(line in (8, 11) for line, _ in notes)   # t<2 vs t>8; t==1 vs t==2


@pytest.mark.parametrize("cond, expected", [
    ("x > 5 and x < 3", False), ("x >= 3 and x <= 3", None), ("x > 3 and x < 3", False),
    ("c and not c", False), ("status == a and status == b", False),
    ("random() < 0.1 and random() > 0.5", None), ("1 < 2 or c", True),
    ("not (x < 3) and x < 2", False), ("3 < x and x < 1", False), ("x > lim", None),
    ("lim > 5", False),
])
def test_guard_truth(cond, expected):
    tree = parse(f"param p = {cond}\n")
    assert truth(tree.decls[0].value, {"lim": 4}) is expected


def test_disjoint_needs_proof():
    a, b, c = (parse(f"param p = {t}\n").decls[0].value for t in ("x < 1", "x > 2", "y > 2"))
    assert disjoint(a, b, {}) and not disjoint(a, c, {})


def test_graph_has_exactly_the_statuses_and_transitions():
    prog = compile_file(FORAGING)
    (g,) = kind_graphs(prog.info.kinds, prog.info.params)
    assert g.statuses == ["seeking", "fooded", "foodless"]
    assert {(t.source, t.target) for t in g.transitions} == {
        ("seeking", "fooded"), ("seeking", "foodless"), ("fooded", "seeking"),
        ("foodless", "seeking")}
    assert g.initial == ["seeking"] and g.unreachable == [] and g.dead_ends == []


def test_graph_cli_dot_and_mermaid(tmp_path, capsys):
    assert main(["graph", str(FORAGING)]) == 0
    dot = capsys.readouterr().out
    assert dot.startswith('digraph "foraging" {')
    assert '"ant.seeking" [label="seeking", peripheries=2];' in dot
    assert '"ant.seeking" -> "ant.foodless" [label="steps > 40"];' in dot
    assert dot.count(" -> ") == 4
    out = tmp_path / "g.mmd"
    assert main(["graph", str(FORAGING), "-o", str(out)]) == 0
    mmd = out.read_text().splitlines()
    assert mmd[0] == "stateDiagram-v2"
    assert "  [*] --> seeking" in mmd and "  fooded --> seeking : steps <= 0" in mmd
    assert sum("-->" in line for line in mmd) == 5
    assert main(["graph", str(FORAGING), "--kind", "bee"]) == 2
    assert "no agent kind `bee`" in capsys.readouterr().err


def test_graph_marks_unreachable_and_multi_kind_mermaid(tmp_path, capsys):
    path = tmp_path / "two.swarm"
    path.write_text("agent a { count 1; status s { }; status lost { } }\n"
                    "agent b { count 1; status s { } }\n")
    assert main(["graph", str(path), "--format", "mermaid"]) == 0
    out = capsys.readouterr().out
    assert "  state a {" in out and "  state b {" in out
    assert "    note right of a_lost : unreachable" in out
    assert main(["graph", str(path)]) == 0
    assert '"a.lost" [label="lost", style="rounded,dashed"' in capsys.readouterr().out


def test_graph_mermaid_keeps_a_never_true_transition_and_says_so(tmp_path, capsys):
    """DOT dashes it; Mermaid cannot, and used to leave the edge out altogether."""
    path = tmp_path / "never.swarm"
    path.write_text("agent a { count 1; var t = 0; status go { t += 1; "
                    "when t > 2 and t < 1 -> note; when t >= 3 -> done }; "
                    "status note { when true -> go }; status done { } }\n")   # `note`:
    # a Mermaid keyword, so its id is `note_2`
    assert main(["graph", str(path), "--format", "mermaid"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert "  go --> note_2 : t > 2 and t < 1 (never true)" in out, out
    assert "  go --> done : t >= 3" in out
    assert "  note right of done : no way out" in out
    assert main(["graph", str(path)]) == 0
    assert '"a.go" -> "a.note" [label="t > 2 and t < 1", style=dashed' in \
        capsys.readouterr().out


def test_graph_mermaid_ids_never_clash(tmp_path, capsys):
    """`a`'s status `b_c` and `a_b`'s status `c` both read `a_b_c`: Mermaid drew one
    state with both kinds' edges. Each status now has its own id, labelled as written."""
    path = tmp_path / "clash.swarm"
    path.write_text("agent a { count 1; var t = 0; status b_c { when t > 3 -> idle }; "
                    "status idle { } }\n"
                    "agent a_b { count 1; var t = 0; status c { when t > 5 -> rest }; "
                    "status rest { when t > 9 -> c } }\n")
    assert main(["graph", str(path), "--format", "mermaid"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert "    [*] --> a_b_c" in out and "    a_b_c --> a_idle : t > 3" in out
    assert '    state "c" as a_b_c_2' in out and "    [*] --> a_b_c_2" in out
    assert "    a_b_rest --> a_b_c_2 : t > 9" in out


def test_graph_mermaid_keyword_status_names(tmp_path, capsys):
    """Mermaid reads `state`, `note`, `scale`, ... (any case) as keywords where an id
    stands, which broke the diagram; such statuses get an alias and keep their label."""
    path = tmp_path / "kw.swarm"
    path.write_text("agent r { count 1; var t = 0; status state { when t > 3 -> note }; "
                    "status note { when t > 5 -> Scale }; status Scale { } }\n")
    assert main(["graph", str(path), "--format", "mermaid"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert '  state "state" as state_2' in out and '  state "note" as note_2' in out
    assert '  state "Scale" as Scale_2' in out
    assert "  [*] --> state_2" in out and "  note_2 --> Scale_2 : t > 5" in out
    assert "  note right of Scale_2 : no way out" in out     # Mermaid's own `note`
    assert not any(line.split()[0].lower() in ("note", "scale") for line in out[1:]
                   if not line.startswith("  note right of "))


def test_check_prints_notes(tmp_path, capsys):
    assert main(["check", str(FORAGING)]) == 0
    err = capsys.readouterr().err
    assert "foraging.swarm:15:10: note: in `ant.seeking`, this condition and the one on " \
           "line 14 can hold together" in err


def test_aco_graph_has_exactly_its_statuses_and_transitions(capsys):
    aco = Path(__file__).resolve().parent.parent / "programs" / "aco.swarm"
    prog = compile_file(aco)
    (g,) = kind_graphs(prog.info.kinds, prog.info.params)
    assert g.statuses == ["seeking", "fooded", "foodless"]
    assert sorted((t.source, t.target) for t in g.transitions) == [
        ("fooded", "seeking"), ("foodless", "seeking"), ("seeking", "fooded"),
        ("seeking", "foodless")]
    assert main(["graph", str(aco), "--format", "mermaid"]) == 0
    edges = [line.split(" : ")[0].strip() for line in capsys.readouterr().out.splitlines()
             if "-->" in line]
    assert sorted(edges) == ["[*] --> seeking", "fooded --> seeking",
                             "foodless --> seeking", "seeking --> fooded",
                             "seeking --> foodless"]


@pytest.mark.parametrize("argv, said", [
    (["-o", "{d}/g.png"], "-o {d}/g.png: the file must end in .dot, .gv, .mmd or .md"),
    (["-o", "{d}/graph"], "-o {d}/graph: the file must end in .dot, .gv, .mmd or .md"),
    (["--format", "mermaid", "-o", "{d}/g.dot"], "--format mermaid: -o {d}/g.dot names a "
                                                  "dot file"),
    (["--format", "dot", "-o", "{d}/g.md"], "--format dot: -o {d}/g.md names a mermaid"),
])
def test_graph_refuses_a_file_name_its_text_does_not_fit(walk, tmp_path, capsys, argv,
                                                          said):
    """`-o graph.png` wrote DOT text into a file named as a picture, which no image
    viewer opens; Mermaid into a `.dot` file, which Graphviz cannot read."""
    argv = [a.format(d=tmp_path) for a in argv]
    err = cli_error(capsys, ["graph", str(walk), *argv])
    assert said.format(d=tmp_path) in err
    assert not any(tmp_path.glob("g*"))
