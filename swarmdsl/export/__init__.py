"""Exporters: a checked program translated for another platform.

`kilobot` writes C for the Kilobot's library (kilolib), built for the real robot with
avr-gcc or run in Kilombo, the C simulator of Kilobot programs ([kilobot.md]). What a
target cannot run is refused with a located error at `swarmdsl check --target TARGET`
as at export.
"""

TARGETS = ("kilobot",)


def check_target(target: str, program) -> None:
    """Raise the located refusals of `program` (a compiled Program) for `target`."""
    if target == "kilobot":
        from swarmdsl.export.kilobot import translate

        translate(program)
