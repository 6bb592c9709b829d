"""`nn(...)` on a Kilobot: a program's small network written out as C, its weights in
flash (`PROGMEM` on the AVR; a 2 KB RAM could not hold the 2D matrix's 1,400).

The weights are read with the runtime's own safe loader (`runtime.nn.load_model`: a
plain tensor `state_dict`, never a pickle that runs code), so the C computes what the
language's forward pass computes: the sidecar's input normalisation and clip, the
layers with their activation, the output de-normalisation, in 32-bit floats. Only
numbers Python prints reach the C.
"""

from __future__ import annotations

from swarmdsl.export.kilobot_c import Refusal, number

FLASH_BUDGET = 16 * 1024    # bytes of weights a program may take of the 32 KB flash
_ACTIVATION = {"relu": "fmaxf(s, 0.0f)", "tanh": "tanhf(s)",
               "sigmoid": "1.0f / (1.0f + expf(-s))"}

ROM = """\
#ifdef __AVR__
#include <avr/pgmspace.h>
#define KB_ROM PROGMEM
#define kb_rom(p) pgm_read_float(p)
#else
#define KB_ROM
#define kb_rom(p) (*(p))
#endif
"""


def network_c(index: int, path, span) -> tuple[str, int, int]:
    """The C of the network at `path` (`kb_nn<index>(in, out)`), its weights' bytes and
    its activations' (two floats a unit of its widest layer, on the stack); a Refusal
    at `span` (its first call) when it cannot be read or is too big."""
    from swarmdsl.runtime.nn import ModelError, load_model

    try:
        model = load_model(path)
    except ModelError as exc:
        raise Refusal(f"the network `{path.name}` ({exc.message})", span) from None
    info = model.info
    layers = [(p.detach().cpu().numpy().astype(float)) for p in model._module.parameters()]
    count = sum(p.size for p in layers)
    if count * 4 > FLASH_BUDGET:
        raise Refusal(f"the network `{path.name}` of {count} weights ({count * 4} bytes)",
                      span, f"a Kilobot program keeps its networks within {FLASH_BUDGET} "
                      "of the ATmega328P's 32768 bytes of flash")
    widths = info.layer_widths
    flat = [number(v, span) for p in layers for v in p.ravel()]
    rows = ",\n    ".join(", ".join(flat[i:i + 6]) for i in range(0, len(flat), 6))
    width = max(widths)
    norm = info.input_norm
    lines = []
    for i in range(info.n_in):
        z = f"(x[{i}] - {number(norm.shift[i], span)}) / {number(norm.scale[i], span)}"
        if norm.clip is not None:
            z = f"kb_clamp({z}, {number(norm.clip[0], span)}, {number(norm.clip[1], span)})"
        lines.append(f"    a[{i}] = {z};\n")
    offset = 0
    for k, (n_in, n_out) in enumerate(zip(widths, widths[1:], strict=False)):
        weights, biases = offset, offset + n_in * n_out
        offset = biases + n_out
        act = _ACTIVATION[info.activation] if k < len(widths) - 2 else "s"
        lines.append(
            f"    for (uint16_t o = 0; o < {n_out}; o++) {{\n"
            f"        float s = kb_rom(&p[{biases} + o]);\n"
            f"        for (uint16_t i = 0; i < {n_in}; i++) "
            f"s += kb_rom(&p[{weights} + o * {n_in} + i]) * a[i];\n"
            f"        z[o] = {act};\n    }}\n"
            f"    for (uint16_t o = 0; o < {n_out}; o++) a[o] = z[o];\n")
    out = info.output_norm
    lines += [f"    y[{o}] = a[{o}] * {number(out.scale[o], span)} + "
              f"{number(out.shift[o], span)};\n" for o in range(info.n_out)]
    name = "-".join(str(w) for w in widths)
    c = (f"/* network {index}: {name} {info.activation}, {count} weights in flash */\n"
         f"static const float kb_nn{index}_p[{count}] KB_ROM = {{\n    {rows}\n}};\n\n"
         f"static void kb_nn{index}(const float *x, float *y)\n{{\n"
         f"    const float *p = kb_nn{index}_p;\n    float a[{width}], z[{width}];\n"
         + "".join(lines) + "}\n\n")
    return c, count * 4, 2 * 4 * width
