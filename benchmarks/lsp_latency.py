"""The language server's diagnostics latency on a ~500-line program.

Run from the repository root: ``python -m benchmarks.lsp_latency [--repeat 30]``.

The program (`program()`) is 20 agent kinds of a boids-like flock, each with its
params, two statuses, `let`s, filtered aggregates and a transition, plus comments: 500
lines that check (a realistic file, not padding). Three texts are timed: the program,
the program with an edit that the checker refuses (an unknown name), and the program
cut in the middle of a line (a syntax error, as while typing).

A second program, `one_kind()`, puts ~500 lines in one agent kind of 44 statuses:
there an edit re-parses the whole kind (see below).

Each round makes one edit in one declaration (a number typed, a different one each
round); the figures are medians over the rounds:
- `analyse, whole parse`: the analysis in-process (parse, check, build, the index) as
  `swarmdsl check` would parse, all of it;
- `analyse, changed declarations parsed`: the same with the document's `ChunkParser`,
  as the server does (`swarmdsl/lsp/chunks.py`: the unchanged declarations are kept);
- `round trip`: from a `textDocument/didChange` written to `swarmdsl lsp`'s standard
  input to its `textDocument/publishDiagnostics` read back (what an editor waits for),
  wall clock.
The in-process figures are CPU time of this process (`time.process_time`): on a shared
machine the wall clock also counts the other processes' turns; the round trip is what
a user waits for, the load included (the load average is printed first).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def program(kinds: int = 20) -> str:
    head = ["# A benchmark program: many flocks, each with its own weights.",
            "param radius = 40", "param cruise = 2", "", "world {", "  size 2000 x 2000",
            "  grid 20", "  edges wrap", "}", ""]
    body = []
    for k in range(kinds):
        body += [
            f"# flock {k}: separation, cohesion and alignment, then rest when crowded",
            f"param sep{k} = 0.{k % 9 + 1}",
            f"param coh{k} = 0.{(k + 3) % 9 + 1}",
            f"agent flock{k} {{",
            "  count 10",
            "  velocity random_direction() * cruise",
            "  var tired = 0",
            "  status flying {",
            "    let near = neighbors(radius)",
            "    let sep = sum(near where dist < 0.4 * radius : normalize(pos - other.pos))",
            "    let coh = sum(near where dist > 0.5 * radius : (other.pos - pos) / radius)",
            "    let ali = sum(near : other.vel - vel) / max(count(near), 1)",
            f"    velocity = normalize(velocity + sep{k} * sep + coh{k} * coh + ali) * cruise",
            "    tired += 1",
            "    when tired > 100 and count(near) > 5 -> resting { tired = 0 }",
            "  }",
            "  status resting {",
            "    velocity = (0, 0)",
            "    tired += 1",
            "    when tired > 20 -> flying { tired = 0 }",
            "  }",
            f"  invariant calm{k}: speed <= cruise * 1.000001",
            "}",
            "",
        ]
    return "\n".join(head + body) + "\n"


def one_kind(statuses: int = 44) -> str:
    """~500 lines in one agent kind: an edit anywhere re-parses the whole kind."""
    lines = ["# A benchmark program: one kind with many statuses.", "param radius = 40",
             "param cruise = 2", "", "world {", "  size 2000 x 2000", "  grid 20",
             "  edges wrap", "}", "", "agent walker {", "  count 200",
             "  velocity random_direction() * cruise", "  var tired = 0"]
    for k in range(statuses):
        nxt = (k + 1) % statuses
        lines += [
            f"  # phase {k}",
            f"  status phase{k} {{",
            "    let near = neighbors(radius)",
            "    let sep = sum(near where dist < 0.4 * radius : normalize(pos - other.pos))",
            "    let coh = sum(near where dist > 0.5 * radius : (other.pos - pos) / radius)",
            "    let ali = sum(near : other.vel - vel) / max(count(near), 1)",
            f"    velocity = normalize(velocity + 0.{k % 9 + 1} * sep + coh + ali) * cruise",
            "    tired += 1",
            f"    when tired > {50 + k} and count(near) > 5 -> phase{nxt} {{ tired = 0 }}",
            "  }",
            "",
        ]
    lines += ["  invariant calm: speed <= cruise * 1.000001", "}"]
    return "\n".join(lines) + "\n"


def texts(base: str) -> dict[str, str]:
    lines = base.splitlines(keepends=True)
    middle = len(lines) // 2
    wrong = base.replace("tired += 1", "tired += unknown_rate", 1)
    cut = "".join(lines[:middle]) + lines[middle][: len(lines[middle]) // 2] + "\n" \
        + "".join(lines[middle + 1:])
    return {"checks": base, "a check error": wrong, "a syntax error (cut line)": cut}


class _Client:
    def __init__(self):
        env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT),
                                                            os.environ.get("PYTHONPATH", "")])}
        self.proc = subprocess.Popen([sys.executable, "-m", "swarmdsl", "lsp"], cwd=ROOT,
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env)
        self.id = 0

    def send(self, msg: dict) -> None:
        body = json.dumps({"jsonrpc": "2.0", **msg}).encode()
        self.proc.stdin.write(b"Content-Length: %d\r\n\r\n" % len(body) + body)
        self.proc.stdin.flush()

    def read(self) -> dict:
        length = 0
        while True:
            line = self.proc.stdout.readline()
            if line in (b"\r\n", b"\n", b""):
                break
            if line.lower().startswith(b"content-length:"):
                length = int(line.split(b":")[1])
        return json.loads(self.proc.stdout.read(length))

    def until(self, pred) -> dict:
        while True:
            msg = self.read()
            if pred(msg):
                return msg

    def request(self, method, params) -> dict:
        self.id += 1
        rid = self.id
        self.send({"id": rid, "method": method, "params": params})
        return self.until(lambda m: m.get("id") == rid)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=30, help="rounds (default 30)")
    args = parser.parse_args(argv)
    from swarmdsl.lsp.analysis import analyse
    from swarmdsl.lsp.chunks import ChunkParser

    client = _Client()
    client.request("initialize", {"processId": None, "rootUri": None, "capabilities": {}})
    client.send({"method": "initialized", "params": {}})
    version = 0
    print(f"load average before: {os.getloadavg()[0]:.1f}")
    print("| program | text | diagnostics | analyse, whole parse (CPU ms) | analyse, "
          "changed declarations parsed (CPU ms) | round trip (wall ms) |")
    print("|---|---|---:|---:|---:|---:|")
    cases = [(name, label, text) for name, base in (("20 kinds", program()),
                                                   ("1 kind, 44 statuses", one_kind()))
             for label, text in texts(base).items()]
    for name, label, text in cases:
      uri = (ROOT / "benchmarks" / f"lsp_bench_{version}.swarm").as_uri()
      version += 1
      client.send({"method": "textDocument/didOpen", "params": {"textDocument": {
          "uri": uri, "languageId": "swarm", "version": version, "text": text}}})
      client.until(lambda m: m.get("method") == "textDocument/publishDiagnostics")
      chunked = ChunkParser()
      analyse(text, "bench.swarm", parser=chunked)     # warm
      whole, in_process, trip = [], [], []
      count = 0
      for r in range(args.repeat):
          # one edit in one declaration, a different one each round (typing a digit)
          edited = re.sub(r"tired > (\d+)", lambda m, r=r: f"tired > {int(m.group(1)) + r + 1}",
                          text, count=1)
          t0 = time.perf_counter()
          analyse(edited, "bench.swarm")
          whole.append(time.perf_counter() - t0)
          t0 = time.perf_counter()
          result = analyse(edited, "bench.swarm", parser=chunked)
          in_process.append(time.perf_counter() - t0)
          count = len(result.diagnostics)
          version += 1
          t0 = time.perf_counter()
          client.send({"method": "textDocument/didChange", "params": {
              "textDocument": {"uri": uri, "version": version},
              "contentChanges": [{"text": edited}]}})
          client.until(lambda m: m.get("method") == "textDocument/publishDiagnostics")
          trip.append(time.perf_counter() - t0)
      ms = [statistics.median(x) * 1000 for x in (whole, in_process, trip)]
      print(f"| {name} ({text.count(chr(10))} lines) | {label} | {count} | "
            f"{ms[0]:.0f} | {ms[1]:.0f} | {ms[2]:.0f} |")
    client.request("shutdown", None)
    client.send({"method": "exit"})
    client.proc.wait(timeout=10)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
