"""Every ```swarm example in the language documentation compiles and runs; the docs
show the commands and files the CLI really takes and writes."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from swarmdsl.compiler import compile_source
from swarmdsl.runtime.simulation import Simulation

DOCS = Path(__file__).resolve().parent.parent / "docs"


def _examples():
    for path in sorted(DOCS.glob("language*.md")):
        for i, block in enumerate(re.findall(r"```swarm\n(.*?)```", path.read_text(), re.S)):
            yield pytest.param(path, block, id=f"{path.stem}-{i}")


EXAMPLES = list(_examples())


def test_language_reference_has_examples():
    assert len(EXAMPLES) >= 7


@pytest.mark.parametrize("path, source", EXAMPLES)
def test_doc_example_runs(backend, path, source):
    # examples run as if saved in programs/, beside the shipped models
    program = compile_source(source, f"{path.name}-example.swarm",
                             program_dir=DOCS.parent / "programs")
    # the reference says agents should start in the world: its examples do
    outside = [w.message for w in program.info.warnings if "outside the world" in w.message]
    assert not outside, outside
    sim = Simulation(program, seed=0)
    sim.run(10)
    assert np.isfinite(sim.agents.cols["pos"]).all()


ROOT = DOCS.parent


def test_replay_commands_in_the_docs_are_the_one_test_prints():
    """`swarmdsl run` needs the program file: every documented replay names it, and the
    README shows the command `swarmdsl test` prints."""
    from swarmdsl.testing.example import example_command

    printed = example_command("FILE", "case.json")
    assert printed == "swarmdsl run FILE --headless --example case.json"
    assert printed in " ".join((ROOT / "README.md").read_text().split())
    for path in [ROOT / "README.md", *sorted(DOCS.glob("*.md"))]:
        text = " ".join(path.read_text().split())
        for command in re.findall(r"swarmdsl run [^`]*--example", text):
            assert not command.split()[2].startswith("-"), (path.name, command)


def test_outputs_doc_names_every_folder_test_writes_outside_named_folders(monkeypatch):
    from swarmdsl.testing.example import cache_folder

    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    monkeypatch.setenv("HOME", "~")             # the path as the doc spells it
    text = (DOCS / "outputs.md").read_text()
    section = text.split("## The user cache folder", 1)[1].split("\n## ", 1)[0]
    section = " ".join(section.split())
    assert f"`{cache_folder()}`" in section                   # ~/.cache/swarmdsl/examples
    assert "`hypothesis/` beside `examples/`" in section      # cli._hypothesis_home
    assert "The only file swarmdsl writes" not in text


def test_the_readme_first_run_writes_every_output_the_readme_names(backend, tmp_path, capsys):
    """The README promised `metrics.parquet` for its first command, whose program
    declared no metric: the command wrote none."""
    from swarmdsl.cli import main

    readme = (ROOT / "README.md").read_text()
    command = re.search(r"swarmdsl run (programs/\S+) --headless (.*?)--out \S+", readme)
    bullet = readme[readme.index("- `swarmdsl run FILE"):readme.index("- `swarmdsl check")]
    promised = re.findall(r"`(\w+\.(?:parquet|npz|json))`", bullet)
    assert command and {"agents.parquet", "metrics.parquet"} <= set(promised)
    out = tmp_path / "out"
    assert main(["run", str(ROOT / command.group(1)), "--headless", "--steps", "3",
                 "--out", str(out)]) == 0
    for name in promised:
        assert (out / name).exists(), name


def test_outputs_doc_example_of_a_row_computed_from_the_previous_row_is_true(backend, tmp_path):
    """docs/outputs.md says a row's variables were computed during the tick before it,
    from the previous row's positions, and shows a run's table: that run gives it."""
    import pyarrow.parquet as pq

    from swarmdsl.runtime.runner import Run

    text = (DOCS / "outputs.md").read_text()
    section = text[text.index("### Which tick a row's values belong to"):]
    source = re.search(r"```swarm\n(.*?)```", section, re.S).group(1)
    table = re.search(r"```\n( *tick.*?)```", section, re.S).group(1).splitlines()
    header, rows = table[0].split(), [line.split() for line in table[1:]]
    program = compile_source(source, "lag.swarm")
    assert Run(program, steps=len(rows) - 1, out=tmp_path).execute() == "completed"
    got = pq.read_table(tmp_path / "agents.parquet").to_pandas()[header]
    assert [[float(v) for v in row] for row in rows] == got.to_numpy().tolist()
