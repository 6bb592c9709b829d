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
    # Sensing model (lang_sensing.py): how far and where it sees, how well.
    sense_range: float = math.inf   # neighbours and field points beyond it are not sensed
    fov: str = "all"                # "all", "cone" or "front" (half-circle + side wedges)
    fov_angle: float = math.pi      # cone: half angle; front: each side wedge's width
    fov_reach: float = math.inf     # front: how far the side wedges reach
    neighbor_noise: float = 0.0     # units, standard deviation on a neighbour's offset
    neighbor_dropout: float = 0.0   # chance a neighbour in view is missed this tick
    neighbor_resolution: float = 0.0  # a sensed distance is rounded to this step
    field_noise: float = 0.0        # standard deviation added to a field reading
    field_dropout: float = 0.0      # chance a field reading is lost (reads 0)
    field_resolution: float = 0.0   # a field reading is rounded to this step

    def has_sensing_model(self) -> bool:
        return any(getattr(self, f) != getattr(PROFILES["generic"], f) for f in (
            "sense_range", "fov", "neighbor_noise", "neighbor_dropout",
            "neighbor_resolution", "field_noise", "field_dropout", "field_resolution"))

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
# Those in ABOVE_MIN must be above their min: a robot that senses or hears nothing at all
# is a mistake, not a model (leave `range` out to sense without limit).
NUMERIC_OPTIONS = {
    "body": ("body", 0.0, math.inf),
    "comm_range": ("comm_range", 0.0, math.inf),
    "speed": ("speed", 0.0, math.inf),
    "heading_noise": ("heading_noise", 0.0, math.inf),
    "speed_noise": ("speed_noise", 0.0, math.inf),
    "distance_noise": ("distance_noise", 0.0, math.inf),
    "loss": ("loss", 0.0, 1.0),
    "message_bytes": ("message_bytes", 0.0, math.inf),
    "range": ("sense_range", 0.0, math.inf),
    "neighbor_noise": ("neighbor_noise", 0.0, math.inf),
    "neighbor_dropout": ("neighbor_dropout", 0.0, 1.0),
    "neighbor_resolution": ("neighbor_resolution", 0.0, math.inf),
    "field_noise": ("field_noise", 0.0, math.inf),
    "field_dropout": ("field_dropout", 0.0, 1.0),
    "field_resolution": ("field_resolution", 0.0, math.inf),
}
# Options whose maximum is allowed but almost surely a mistake: warned about.
WARN_AT_MAX = {
    "loss": "a loss of 1 loses every message: no robot of this profile hears anything",
    "neighbor_dropout": "a neighbor_dropout of 1 drops every neighbour: no robot of this "
                        "profile senses another",
    "field_dropout": "a field_dropout of 1 drops every field reading (each reads 0)",
}
ABOVE_MIN = {
    "range": "a range of 0 senses nothing around the robot (every field point reads 0); "
             "leave `range` out to sense without limit",
    "comm_range": "a comm_range of 0 hears no message",
}
