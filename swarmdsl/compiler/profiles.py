"""Robot profiles: what an agent kind can sense and do.

`generic` is the thesis' multi-agent framework: every sense is available.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Profile:
    name: str
    senses: frozenset | None = None      # None: every sense
    doc: str = ""

    def allows(self, sense: str) -> bool:
        return self.senses is None or sense in self.senses


PROFILES: dict[str, Profile] = {
    "generic": Profile("generic", None, "the multi-agent framework: senses everything"),
}
