"""The RAM model of `swarmdsl export kilobot`: globals, network buffers and the
deepest call chain counted against the ATmega328P's 2048 bytes, refused located beyond
it, and its stack estimate above what avr-gcc itself reports for the shipped programs."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

from swarmdsl.cli import main
from swarmdsl.compiler import compile_file
from swarmdsl.export import kilobot_memory as memory
from tests.test_lang_nn import write_model

ROOT = Path(__file__).resolve().parent.parent
AVR = shutil.which("avr-gcc")

NETWORK = """world {{ size 200 x 200; steps 10 }}
agent bot {{
  robot kilobot
  count 1
  place (100, 100)
  var out = 0
  status s {{
    out = nn("models/wide.pt", tick)
  }}
}}
"""


@pytest.mark.parametrize(("hidden", "refused"), [(1300, True), (100, False)])
def test_a_network_whose_activations_overflow_the_stack_is_refused_at_its_call(
        tmp_path, capsys, hidden, refused):
    """A 1-1300-1 network fits the flash (15.6 KB of weights) but its activations, two
    floats a unit of its widest layer on the stack (10.4 KB), do not fit a 2 KB robot:
    refused at the call, with the RAM it would need; a 1-100-1 one fits."""
    write_model(tmp_path / "models", "wide", 1, 1, hidden=(hidden,))
    path = tmp_path / "net.swarm"
    path.write_text(NETWORK.format())
    code = main(["check", "--target", "kilobot", str(path)])
    err = capsys.readouterr().err
    if not refused:
        assert code == 0, err
        return
    assert code == 2
    first = err.splitlines()[0]
    assert first.startswith(f"{path}:8:11: error: a robot needing ")
    need = int(re.search(r"needing (\d+) bytes", first)[1])
    assert need > 2 * 4 * hidden
    assert f"the network `wide.pt` {memory.FRAME + 2 * 4 * hidden}" in first


def _stack_usage(folder: Path, name: str) -> dict[str, int]:
    """avr-gcc's `-fstack-usage` of the exported program: bytes by function."""
    subprocess.run(["avr-gcc", "-mmcu=atmega328p", "-Os", "-std=gnu99", "-funsigned-char",
                    "-fpack-struct", "-fshort-enums", "-fstack-usage", "-c", f"{name}.c",
                    "-o", f"{name}.o"], cwd=folder, check=True, capture_output=True)
    out = {}
    for line in (folder / f"{name}.su").read_text().splitlines():
        where, size, _kind = line.split("\t")
        out[where.rsplit(":", 1)[-1]] = int(size)
    return out


@pytest.mark.skipif(not AVR, reason="avr-gcc is not installed (Debian: gcc-avr avr-libc)")
@pytest.mark.parametrize("source", ["kilobot/gradient", "kilobot/orbit", "spring1d",
                                    "matrix2d", "matrix2d_nn"])
def test_the_stack_model_is_above_what_avr_gcc_reports(tmp_path, source):
    """The model's stack (main, kilo_start, loop and the deepest status chain) is at
    least the frames avr-gcc reports for main, loop and every other function of the
    program together (no chain can be deeper than all of them; the interrupts are
    counted apart in both)."""
    if source.endswith("_nn"):
        pytest.importorskip("torch")
    path = ROOT / "programs" / f"{source}.swarm"
    name = path.stem
    assert main(["export", "kilobot", str(path), "-o", str(tmp_path)]) == 0
    frames = _stack_usage(tmp_path, name)
    isr = {"kb_message_rx", "kb_message_tx", "kb_json_state"}
    measured = sum(v for k, v in frames.items() if k not in isr and k != "setup")
    info = compile_file(path).info
    networks = {}
    if source.endswith("_nn"):
        from swarmdsl.export.kilobot_nn import network_c
        for res in info.facts.resolutions():
            if res[0] == "nn":
                networks[res[1]] = network_c(0, res[1], None)[2]
    deepest = max(memory.status_stack(info, d, networks)[0]
                  for k in info.kinds for d in k.status_decls.values())
    assert memory.base(info) + deepest >= measured, (frames, deepest)
