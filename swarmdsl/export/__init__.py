"""Exporters: a checked program translated for another platform.

`kilobot` writes C for the Kilobot's library (kilolib), built for the real robot with
avr-gcc or run in Kilombo, the C simulator of Kilobot programs ([kilobot.md]). What a
target cannot run is refused with a located error at `swarmdsl check --target TARGET`
as at export.
"""

TARGETS = ("kilobot",)


def check_target(target: str, program) -> None:
    """Raise the located refusals of `program` (a compiled Program) for `target`; print
    its located warnings (what runs, but differently, on the target) to stderr."""
    if target == "kilobot":
        import sys

        from swarmdsl.export.kilobot import translate

        warnings: list = []
        translate(program, warnings=warnings)
        for w in warnings:
            print(w.render(), file=sys.stderr)
        program.info.warnings.extend(warnings)    # counted in `check`'s summary
