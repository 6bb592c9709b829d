"""Robot bodies at run time: profile speed limits, noisy vibration motion, believed
coordinates kept by odometry, LED colours, and what the viewer draws of them.

Believed coordinates live in the agent store as `believed` `(N, 2)` and `located` `(N,)`;
the LED as `led` `(N,)`, a packed 0xRRGGBB number. Odometry adds the *commanded*
displacement (velocity after the speed limit) to a located agent's belief each tick, while
its true position moves by the noisy one: belief and truth drift apart as a real
Kilobot's do.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from swarmdsl.ops import portable
from swarmdsl.runtime.frame import AgentFrame

LED_OFF = 0x505050


@dataclass(frozen=True)
class RobotSpec:
    """What the compiler hands the runtime, per kind index."""

    speed: np.ndarray             # (K,) units per tick (inf: no limit)
    heading_noise: np.ndarray     # (K,) radians
    speed_noise: np.ndarray       # (K,) fraction
    believe: dict = field(default_factory=dict)   # kind index -> closure(frame) -> (M, 2)
    origin: tuple[float, float] = (0.0, 0.0)      # world position of believed (0, 0)
    beliefs: bool = False
    led: bool = False


def unpack_led(packed: np.ndarray) -> np.ndarray:
    """(N,) packed 0xRRGGBB numbers -> (N, 3) uint8 colours."""
    v = np.asarray(packed).astype(np.int64)
    return np.stack([(v >> 16) & 255, (v >> 8) & 255, v & 255], axis=1).astype(np.uint8)


class RobotRuntime:
    """Runtime extension for robot profiles, beliefs and LEDs."""

    def __init__(self, sim, spec: RobotSpec):
        self.spec = spec
        self.commanded: np.ndarray | None = None

    def after_placement(self, sim) -> None:
        cols = sim.agents.cols
        kinds = cols["kind"]
        spec = self.spec
        cols["max_speed"] = np.minimum(cols["max_speed"], spec.speed[kinds])
        if spec.beliefs:
            sim.agents.declared["believed"][:] = True
            sim.agents.declared["located"][:] = True
            for kind in sim.program.kinds:
                believe = spec.believe.get(kind.index)
                rows = np.flatnonzero(kinds == kind.index)
                if believe is None or rows.size == 0:
                    continue
                cols["believed"][rows] = believe(AgentFrame(sim, rows, kind, None))
                cols["located"][rows] = True
        if spec.led:
            sim.agents.declared["led"][:] = True
            cols["led"][:] = LED_OFF

    def state_dict(self, sim) -> dict:
        """Nothing between ticks: beliefs and LEDs are agent columns, and the commanded
        velocity lives only from `motion` to `end_tick` of one tick."""
        return {}

    def load_state(self, sim, state: dict) -> None:
        self.commanded = None

    def motion(self, sim, vel: np.ndarray) -> np.ndarray:
        """The displacement agents really make this tick, given their commanded velocity."""
        self.commanded = vel
        kinds = sim.agents.cols["kind"]
        hn = self.spec.heading_noise[kinds]
        sn = self.spec.speed_noise[kinds]
        moving = np.any(vel != 0, axis=1)
        noisy = ((hn > 0) | (sn > 0)) & moving
        if not noisy.any():
            return vel
        n = vel.shape[0]
        rng = sim.rng.rows(sim.agents.cols["id"], np.arange(n), "motion")
        turn = rng.at("turn").standard_normal(n) * hn
        scale = np.maximum(1.0 + rng.at("speed").standard_normal(n) * sn, 0.0)
        c, s = portable.cos_array(turn), portable.sin_array(turn)
        x, y = vel[:, 0], vel[:, 1]
        out = np.stack([c * x - s * y, s * x + c * y], axis=1) * scale[:, None]
        # a run none of whose movers is noisy keeps its velocities (a batch: per replica)
        return np.where((moving & sim.run_any(noisy))[:, None], out, vel)

    def end_tick(self, sim) -> None:
        if not self.spec.beliefs or self.commanded is None:
            return
        cols = sim.agents.cols
        if self.commanded.shape[0] != cols["believed"].shape[0]:
            return
        step = np.where(cols["located"][:, None], self.commanded, 0.0)
        cols["believed"] = cols["believed"] + step
        self.commanded = None

    def decorate_snapshot(self, sim, snap) -> None:
        cols = sim.agents.cols
        if self.spec.led:
            snap.led = unpack_led(cols["led"])
        if self.spec.beliefs:
            world = cols["believed"] + np.asarray(self.spec.origin)
            snap.believed = np.where(cols["located"][:, None], world, cols["pos"])
