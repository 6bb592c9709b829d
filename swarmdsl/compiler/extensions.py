"""Imports the modules that extend the core language (each registers its names, calls,
actions and options in the tables of checker, codegen and runtime)."""

from swarmdsl.compiler import (  # noqa: F401  imported for their registrations
    draws,  # what the arguments of chance, normal and uniform must be
    init_order,  # initial values computed once what they read is (place after attrs)
    lang_beliefs,  # robots: beliefs and trilateration
    lang_fields,  # fields and regions
    lang_maps,  # internal maps: map, note, recall, age, known, best
    lang_memory,  # path memories and label sets
    lang_messaging,  # robots: messages
    lang_metrics,  # metric
    lang_motion,  # robot-relative motion: stop, forward, turn_left, turn_right
    lang_nn,  # nn("models/x.pt", ...)
    lang_objectives,  # objective NAME = TARGET; target, toward, approach, arrived
    lang_properties,  # invariant, eventually
    lang_refine,  # refined grids: world { refine SHAPE LEVELS }
    lang_robots,  # robot profiles
    lang_sensing,  # sensing models: range, field of view, noise, dropout, resolution
    lang_trees,  # behaviour trees: the checker's part
    lang_twins,  # physical twins: fields given by formulas (after lang_fields)
    placement,  # where agents start: a placement known at check time lies in the world
    resources,  # grid, pair and memory estimates
    tree_codegen,  # behaviour trees: their compilation to runtime tree nodes
)
