"""The test side of ``tests/fork_server.py``: start it in a subprocess, ask it to fork ``ccjax``
commands, and read back each child's pid, exit code and peak memory."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path


class ForkServer:
    """``tests/fork_server.py`` in a subprocess: start a ``ccjax`` command, learn its pid, wait for it.

    Arguments:
        logs: a folder for the children's stdout and stderr (``NNNN.out``, ``NNNN.err``).
        env: extra environment variables for the server and its children.
    """

    def __init__(self, logs: Path, **env: str):
        self.logs = logs
        self.count = 0
        server = Path(__file__).with_name("fork_server.py")
        self.process = subprocess.Popen(
            [sys.executable, str(server)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            env=dict(os.environ, **env),
        )
        assert json.loads(self._read()) == {"ready": True}

    def _read(self) -> str:
        assert self.process.stdout is not None
        line = self.process.stdout.readline()
        assert line, "the fork server stopped"
        return line

    def start(self, argv: list[str], cwd: Path) -> tuple[int, Path]:
        """Fork a child running ``ccjax argv``; returns its pid and the stem of its log files."""
        assert self.process.stdin is not None
        self.count += 1
        log = self.logs / f"{self.count:04d}"
        request = {"argv": argv, "cwd": str(cwd), "stdout": f"{log}.out", "stderr": f"{log}.err"}
        self.process.stdin.write(json.dumps(request) + "\n")
        self.process.stdin.flush()
        return json.loads(self._read())["pid"], log

    def finish(self) -> dict:
        """The last child's end: ``{"pid", "status" (exit code, minus a killing signal), "maxrss_kb"}``."""
        return json.loads(self._read())

    def wait(self) -> int:
        """The exit code of the last child (minus the signal that killed it)."""
        return self.finish()["status"]

    def run(self, argv: list[str]) -> tuple[int, str, int]:
        """``(exit code, stderr, peak resident kB)`` of ``ccjax argv`` run in the log folder."""
        _, log = self.start(argv, self.logs)
        done = self.finish()
        return done["status"], Path(f"{log}.err").read_text(errors="replace"), done["maxrss_kb"]

    def close(self) -> None:
        assert self.process.stdin is not None and self.process.stdout is not None
        self.process.stdin.close()
        self.process.wait(60)
        self.process.stdout.close()
