"""Robot profiles: what an agent kind can sense, how far it hears, how it moves.

`generic` is the thesis' multi-agent framework: every sense, exact motion. `kilobot` is
the KBS framework's robot: distances and messages only, a 9-byte message heard within two
body diameters, noisy vibration motion. Programs declare their own profiles with
`robot NAME { like kilobot; comm_range 80 }` (see `lang_robots.py`).

Units: one world unit is 1 mm and one tick 0.1 s for the built-in kilobot, so its body is
33 units wide, it hears up to 66 units away and it moves 1 unit per tick (1 cm/s, thesis
§2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

# Every sense a profile can grant. Extensions may add entries (name -> what it allows).
SENSES: dict[str, str] = {
    "position": "its own global position `pos`",
    "heading": "its own global heading `heading`",
    "bearing": "where a neighbour is: `other.pos`",
    "motion": "how a neighbour moves: `other.vel`, `other.speed`, `other.heading`",
    "state": "a neighbour's status, kind, id and variables: `other.NAME`",
    "distance": "distances to neighbours: `neighbors()`, `dist`",
    "message": "`broadcast(NAME, value)` and `heard()`",
    "led": "an LED colour: `led(...)`",
}

# Bytes one message value takes, by type (a Kilobot program packs a number in 2 bytes).
VALUE_BYTES = {"num": 2, "bool": 1, "vec": 4}


@dataclass(frozen=True)
class Profile:
    """One robot profile. Lengths are world units, speeds units per tick.

    `senses` None grants every sense. `comm_range` None means two body diameters.
    """

    name: str
    senses: frozenset | None = None
    doc: str = ""
    body: float = 10.0
    comm_range: float | None = 100.0
    speed: float = math.inf
    heading_noise: float = 0.0      # radians, standard deviation per tick of motion
    speed_noise: float = 0.0        # fraction of the commanded speed, standard deviation
    distance_noise: float = 0.0     # units, standard deviation of a measured distance
    loss: float = 0.0               # chance that one message does not arrive
    message_bytes: float = math.inf

    def allows(self, sense: str) -> bool:
        return self.senses is None or sense in self.senses

    @property
    def range(self) -> float:
        """How far this robot hears messages."""
        return self.comm_range if self.comm_range is not None else 2.0 * self.body

    def derive(self, name: str, **changes) -> Profile:
        return replace(self, name=name, doc=f"like {self.name}", **changes)


PROFILES: dict[str, Profile] = {
    "generic": Profile("generic", None, "the multi-agent framework: senses everything"),
    "kilobot": Profile(
        "kilobot", frozenset({"distance", "message", "led"}),
        "the KBS framework: distances and messages only, noisy vibration motion",
        body=33.0, comm_range=None, speed=1.0, heading_noise=0.1, speed_noise=0.1,
        message_bytes=9),
}

# Options of a `robot NAME { ... }` block that set a number: option -> (field, min, max).
NUMERIC_OPTIONS = {
    "body": ("body", 0.0, math.inf),
    "comm_range": ("comm_range", 0.0, math.inf),
    "speed": ("speed", 0.0, math.inf),
    "heading_noise": ("heading_noise", 0.0, math.inf),
    "speed_noise": ("speed_noise", 0.0, math.inf),
    "distance_noise": ("distance_noise", 0.0, math.inf),
    "loss": ("loss", 0.0, 1.0),
    "message_bytes": ("message_bytes", 0.0, math.inf),
}
