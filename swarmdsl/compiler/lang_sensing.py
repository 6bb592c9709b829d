"""Sensing models in the language: `robot NAME { range R; fov ...; neighbor_noise S;
field_dropout P; ... }` and the field-sensing calls that respect them.

The numeric options are rows of `profiles.NUMERIC_OPTIONS`; `fov` is parsed here. A
program whose kinds use a profile with a sensing model gets the `runtime/sensing.py`
extension, which `neighbors()` consults, and its field readings (`sample`, `gradient`,
`ahead`, `cone`) pass through the model of the reading agent's profile.
"""

from __future__ import annotations

import math

import numpy as np

from swarmdsl.compiler import (
    ast,
    codegen,
    lang_robots,
    lang_twins,  # noqa: F401  wrap `sample` after the twins do
    program,
    stream_places,
)
from swarmdsl.compiler.batching import per_replica
from swarmdsl.ops import portable

_FOV_USAGE = "`fov all`, `fov cone HALF_ANGLE` or `fov front WEDGE_ANGLE [WEDGE_REACH]`"


def _fov(chk, opt: ast.Option):
    from swarmdsl.runtime.sensing import FOV_CODES

    args = opt.args
    if not args or not isinstance(args[0], ast.Name) or args[0].id not in FOV_CODES:
        chk.fail(f"a field of view is {_FOV_USAGE} (angles in radians)",
                 args[0].span if args else opt.span)
        return None
    shape = args[0].id
    want = {"all": (0, 0), "cone": (1, 1), "front": (1, 2)}[shape]
    if not want[0] <= len(args) - 1 <= want[1]:
        chk.fail(f"`fov {shape}` takes {want[1] or 'no'} number{'s' if want[1] > 1 else ''}"
                 f": {_FOV_USAGE}", opt.span)
        return None
    nums = []
    for a in args[1:]:
        v = chk._const(a, "the field of view")
        if v is None:
            return None
        if isinstance(v, bool) or not isinstance(v, int | float) or v < 0:
            chk.fail(f"the field of view takes numbers at least 0, got {v}", a.span)
            return None
        nums.append(float(v))
    if shape == "cone" and not 0 < nums[0] <= math.pi:
        chk.fail(f"a cone's half angle is in radians, above 0 and at most pi, got "
                 f"{nums[0]:g}", args[1].span)
        return None
    if shape == "front" and nums[0] > math.pi / 2:
        chk.fail(f"a side wedge is at most pi/2 wide (it ends straight behind), got "
                 f"{nums[0]:g}", args[1].span)
        return None
    changes = {"fov": shape}
    if nums:
        changes["fov_angle"] = nums[0]
    if len(nums) > 1:
        changes["fov_reach"] = nums[1]
    return changes


lang_robots.ROBOT_OPTIONS["fov"] = _fov


# ---- the runtime spec ----

def _profiles(info):
    return [lang_robots.profile_of(info, k) for k in info.kinds]


def _program_hook(info, prog, gen) -> None:
    profs = _profiles(info)
    if not any(p.has_sensing_model() for p in profs):
        return
    from swarmdsl.runtime.sensing import FOV_CODES, Sensing, SensingSpec

    def col(name, conv=float):
        return np.array([conv(getattr(p, name)) for p in profs])

    spec = SensingSpec(col("sense_range"), col("fov", FOV_CODES.get).astype(np.int64),
                       col("fov_angle"), col("fov_reach"), col("neighbor_noise"),
                       col("neighbor_dropout"), col("neighbor_resolution"),
                       col("field_noise"), col("field_dropout"), col("field_resolution"))
    make = per_replica(lambda sim: Sensing(sim, spec))
    make.spec = spec      # what `run -v` says of each kind's sensing
    if spec.views_only:   # the whole-tick kernel tests the views in its pair loops
        make.views = spec
    prog.extensions.append(make)


program.PROGRAM_HOOKS.append(_program_hook)


# ---- field readings through the model ----

def _uses_model(gen) -> bool:
    return any(p.has_sensing_model() for p in _profiles(gen.info))


def _unit(angle):
    angle = np.asarray(angle, dtype=np.float64)
    return np.stack([portable.cos_array(angle), portable.sin_array(angle)], axis=-1)


def _points(gen, call):
    """closure(frame) -> (M, 2) where the reading is taken, or None (at the agent)."""
    def pos(f):
        return np.asarray(f.state("pos"), dtype=np.float64)

    def per_agent(f, v):
        return np.broadcast_to(np.asarray(v, dtype=np.float64), (f.n,))

    if call.name == "sample" and len(call.args) == 2:
        at = gen.expr(call.args[1])   # evaluated again: draws are keyed by their place
        return lambda f: np.broadcast_to(np.asarray(at(f), np.float64), (f.n, 2))
    if call.name in ("ahead", "cone"):
        dist = gen.expr(call.args[1])
        turn = gen.expr(call.args[2]) if call.name == "ahead" and len(call.args) == 3 \
            else (lambda f: 0.0)
        return lambda f: pos(f) + per_agent(f, dist(f))[:, None] * _unit(
            per_agent(f, f.state("heading")) + per_agent(f, turn(f)))
    return None


def _wrap(name: str):
    inner_codegen = codegen.CALL_CODEGEN[name]

    def cg(gen, call):
        inner = inner_codegen(gen, call)
        if not _uses_model(gen):
            return inner
        where = _points(gen, call)
        site = stream_places.place_of(gen.info, call)   # its place, not its line

        def read(f):
            values = inner(f)
            sensing = getattr(f.sim, "sensing", None)
            if sensing is None:
                return values
            return sensing.field_reading(f, values, site,
                                         None if where is None else where(f))
        return read
    codegen.CALL_CODEGEN[name] = cg


for _name in ("sample", "gradient", "ahead", "cone"):
    _wrap(_name)
