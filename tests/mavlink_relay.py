"""Run MAVProxy as a relay beside a vehicle (bench tests with a ground station in the loop).

``mavproxy.py --master=URL --daemon --non-interactive --out udp:HOST:PORT`` forwards
the vehicle to each ``--out`` and everything sent there back to the vehicle.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import tempfile
from pathlib import Path


class MavProxyRelay:
    """A MAVProxy process relaying ``master`` to UDP ``outs``; ``close()`` ends it (and only it)."""

    def __init__(self, master: str, outs: list[str]) -> None:
        exe = shutil.which("mavproxy.py", path=str(Path(sys.executable).parent) + os.pathsep + os.environ["PATH"])
        if exe is None:
            raise FileNotFoundError("mavproxy.py: not installed (pip install MAVProxy)")
        self._workdir = tempfile.TemporaryDirectory(prefix="mavproxy-")
        cmd = [sys.executable, exe, f"--master={master}", "--daemon", "--non-interactive",
               "--state-basedir", self._workdir.name, "--nodtr"]
        cmd += [f"--out={out}" for out in outs]
        self.process = subprocess.Popen(cmd, cwd=self._workdir.name, stdin=subprocess.DEVNULL,
                                        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                        start_new_session=True)

    def close(self) -> None:
        if self.process.poll() is None:
            os.killpg(self.process.pid, signal.SIGTERM)
            try:
                self.process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                os.killpg(self.process.pid, signal.SIGKILL)
                self.process.wait()
        self._workdir.cleanup()

    def __enter__(self) -> MavProxyRelay:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
