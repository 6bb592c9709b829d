"""The behaviour-tree programs do what docs/experiments.md says, read from their
recorded outputs: patrol robots visit every waypoint and never run flat; aco_bt's
trails link the nest to the food sources like aco.swarm's."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from conftest import assert_near_sources_linked_first, first_links, runs_linking_every_source

from swarmdsl.compiler import compile_file
from swarmdsl.runtime.runner import Run

PROGRAMS = Path(__file__).resolve().parent.parent / "programs"
WAYPOINTS = np.array([(40, 40), (160, 40), (160, 160), (40, 160)], dtype=float)


def test_patrol_robots_visit_every_waypoint_and_never_run_out(backend, tmp_path):
    # 2,000 ticks (seeds 1-3): every robot has been to recharge by tick 1,500 and
    # visited each waypoint 7 times or more by 2,000, battery above 28 throughout
    Run(compile_file(PROGRAMS / "patrol.swarm"), seed=1, steps=2000, out=tmp_path,
        every=1).execute()
    rows = pq.read_table(tmp_path / "agents.parquet").to_pandas()
    assert rows["battery"].min() > 0
    for robot, track in rows.groupby("id"):
        pos = track[["x", "y"]].to_numpy()
        near = np.linalg.norm(pos[:, None, :] - WAYPOINTS[None], axis=2) <= 2.5
        visits = (np.diff(near.astype(int), axis=0) == 1).sum(axis=0)
        assert (visits >= 3).all(), (robot, visits)       # every waypoint, lap after lap
        assert (track["status"] == "charging").any(), robot  # and it went to recharge


def test_aco_bt_links_near_sources_first(backend, tmp_path):
    # 500 ticks: over seeds 0-7 `beta` linked by tick 200 and `gamma` by 750 (seeds
    # 0-2: by 300), alpha before beta before gamma in every one
    assert_near_sources_linked_first([first_links(PROGRAMS / "aco_bt.swarm", tmp_path, seed,
                                                  500) for seed in range(3)])


@pytest.mark.slow
def test_aco_bt_links_every_source_in_most_seeds(backend, tmp_path):
    links = [first_links(PROGRAMS / "aco_bt.swarm", tmp_path, seed, 3000)
             for seed in range(10)]
    assert len(runs_linking_every_source(links)) >= 6, links
