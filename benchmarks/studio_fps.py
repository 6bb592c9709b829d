"""Studio frame rate: frames drawn per second in a real browser while a run plays.

Run from the repository root: ``python -m benchmarks.studio_fps [--seconds 10]``
(needs the `studio` extra, playwright and Debian's chromium at /usr/bin/chromium).

For each swarm size, `swarmdsl studio` serves `benchmarks/models/studio_walkers.swarm`
(agents at constant speed with a noisy turn and no neighbour query, so the simulation's
own cost stays small next to streaming and drawing), headless chromium opens the page,
presses play and counts the frames the page drew over `--seconds` (the page's own
counter, `window.studio.frames`), and the ticks the run advanced. Before that, paused,
it has each frame drawn ask for the next: the frame rate of streaming and drawing alone,
what the studio adds to the simulation's own cost. Server, simulation and
browser share the machine, as a user's do. `--program` measures another program (it
should have a param `n` for the swarm size).
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PROGRAM = ROOT / "benchmarks" / "models" / "studio_walkers.swarm"
CHROMIUM = "/usr/bin/chromium"
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync"]
TOKEN = "benchmark"


def measure(program: Path, n: int, seconds: float, backend: str, browser) -> dict:
    env = dict(os.environ, SWARMDSL_STUDIO_TOKEN=TOKEN, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen(
        [sys.executable, "-m", "swarmdsl", "studio", str(program), "--no-browser",
         "--port", "0", "--set", f"n={n}", "--backend", backend],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env, cwd=ROOT)
    try:
        url = proc.stdout.readline().rsplit(" at ", 1)[1].strip()
        page = browser.new_page(viewport={"width": 1400, "height": 900})
        page.goto(url)
        page.wait_for_function("window.studio && window.studio.frames > 0", timeout=120_000)
        counters = "[window.studio.frames, window.studio.frame.header.tick]"
        # paused, every frame drawn asks for another (a `layers` message makes the
        # server send one): the studio's own cost, streaming and drawing, without ticks
        page.evaluate("""() => { const s = window.studio, draw = s.drawPending.bind(s);
            s.drawPending = () => { draw(); if (s.streamOnly) s.sendLayers(); };
            s.streamOnly = true; s.sendLayers(); }""")
        time.sleep(1)
        f0, _ = page.evaluate(counters)
        start = time.perf_counter()
        time.sleep(seconds)
        f1, _ = page.evaluate(counters)
        stream_fps = (f1 - f0) / (time.perf_counter() - start)
        page.evaluate("window.studio.streamOnly = false")
        page.click("[data-role=play]")
        # numba compiles its kernels on the first ticks: measure after they ran
        page.wait_for_function("window.studio.frame.header.tick >= 5", timeout=300_000)
        f0, t0 = page.evaluate(counters)
        start = time.perf_counter()
        time.sleep(seconds)
        f1, t1 = page.evaluate(counters)
        elapsed = time.perf_counter() - start
        size = page.evaluate("[window.studio.canvas.width, window.studio.canvas.height]")
        page.close()
        return {"n": n, "fps": (f1 - f0) / elapsed, "ticks_per_s": (t1 - t0) / elapsed,
                "stream_fps": stream_fps, "canvas": size}
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default="10000,100000")
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--program", type=Path, default=PROGRAM)
    parser.add_argument("--backend", default="numba", choices=("numba", "numpy"))
    args = parser.parse_args(argv)
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        print(f"{'agents':>8}  {'playing: frames/s':>17}  {'ticks/s':>8}  "
              f"{'paused, streaming only: frames/s':>32}  canvas")
        for n in (int(s) for s in args.sizes.split(",")):
            r = measure(args.program, n, args.seconds, args.backend, browser)
            print(f"{r['n']:>8,}  {r['fps']:>17.1f}  {r['ticks_per_s']:>8.1f}  "
                  f"{r['stream_fps']:>32.1f}  {r['canvas'][0]}x{r['canvas'][1]}",
                  flush=True)
        browser.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
