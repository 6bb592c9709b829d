"""Starting `swarmdsl studio` as a user does, for the studio tests: a real process on a
free port of 127.0.0.1 with a known token, stopped by its own pid."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PROGRAM = ROOT / "tests" / "data" / "studio" / "walkers.swarm"
TOKEN = "test-token-studio"


def program_copy(folder: Path) -> Path:
    """A copy of the test program in `folder`: the page may save it."""
    import shutil

    path = folder / "walkers.swarm"
    shutil.copy(PROGRAM, path)
    return path


class StudioProcess:
    """`swarmdsl studio FILE --no-browser`; `url` is the page's address with the token."""

    def __init__(self, program: Path, port: int = 0, token: str = TOKEN, *extra: str):
        env = dict(os.environ, SWARMDSL_STUDIO_TOKEN=token, PYTHONPATH=str(ROOT))
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "swarmdsl", "studio", str(program), "--no-browser",
             "--port", str(port), *extra],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=ROOT)
        line = self.proc.stdout.readline()
        if " at http" not in line:
            self.stop()
            raise RuntimeError(f"studio did not start: {line!r} {self.proc.stderr.read()}")
        self.url = line.rsplit(" at ", 1)[1].strip()
        self.base = self.url.split("/?", 1)[0]
        self.port = int(self.base.rsplit(":", 1)[1])
        self.token = token
        _wait_listening(self.port)

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        for stream in (self.proc.stdout, self.proc.stderr):
            if stream:
                stream.close()


def _wait_listening(port: int, timeout: float = 20.0) -> None:
    import socket

    end = time.monotonic() + timeout
    while time.monotonic() < end:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.05)
    raise RuntimeError(f"nothing listens on port {port}")
