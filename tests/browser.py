"""A real headless Chromium (Debian's `chromium`) driven over the DevTools protocol on a pipe.

``chromium --headless --screenshot`` shoots when the page's load event fires, before a WebAssembly
app such as Rerun's viewer has drawn anything; over the protocol the test evaluates JavaScript in
the page and takes screenshots when it wants. WebGL runs on SwiftShader (no GPU in CI).
"""

from __future__ import annotations

import base64
import json
import os
import shutil
import subprocess
import tempfile


class Chromium:
    """One headless browser with one page; ``call`` sends a DevTools command and returns its result."""

    def __init__(self, width: int = 1280, height: int = 800) -> None:
        exe = shutil.which("chromium")
        if exe is None:
            raise RuntimeError("Debian's chromium is not installed (the Makefile installs it)")
        self._profile = tempfile.mkdtemp(prefix="lp-chromium-")
        to_chrome, self._write = os.pipe()  # the browser reads commands on fd 3
        self._read, from_chrome = os.pipe()  # and writes answers on fd 4

        def fds() -> None:
            a, b = os.dup(to_chrome), os.dup(from_chrome)
            os.dup2(a, 3)
            os.dup2(b, 4)

        self.proc = subprocess.Popen(
            [exe, "--headless", "--no-sandbox", "--remote-debugging-pipe", "--use-gl=angle", "--use-angle=swiftshader",
             "--enable-unsafe-swiftshader", f"--user-data-dir={self._profile}", f"--window-size={width},{height}",
             "about:blank"], pass_fds=(3, 4), preexec_fn=fds, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        os.close(to_chrome)
        os.close(from_chrome)
        self._buffer = b""
        self._id = 0
        self.session = ""

    def call(self, method: str, params: dict | None = None, page: bool = True) -> dict:
        self._id += 1
        message = {"id": self._id, "method": method, "params": params or {}}
        if page and self.session:
            message["sessionId"] = self.session
        os.write(self._write, json.dumps(message).encode() + b"\0")
        while True:
            while b"\0" not in self._buffer:
                chunk = os.read(self._read, 1 << 20)
                if not chunk:
                    raise RuntimeError(f"chromium closed the DevTools pipe (exit code {self.proc.poll()})")
                self._buffer += chunk
            line, self._buffer = self._buffer.split(b"\0", 1)
            answer = json.loads(line)
            if answer.get("id") == self._id:
                if "error" in answer:
                    raise RuntimeError(f"{method}: {answer['error']}")
                return answer["result"]

    def open(self, url: str) -> None:
        target = self.call("Target.createTarget", {"url": url}, page=False)["targetId"]
        attached = self.call("Target.attachToTarget", {"targetId": target, "flatten": True}, page=False)
        self.session = attached["sessionId"]

    def evaluate(self, expression: str):
        return self.call("Runtime.evaluate", {"expression": expression, "returnByValue": True})["result"].get("value")

    def screenshot(self) -> bytes:
        return base64.b64decode(self.call("Page.captureScreenshot", {"format": "png"})["data"])

    def close(self) -> None:
        try:
            self.call("Browser.close", page=False)
            self.proc.wait(timeout=10)
        except (RuntimeError, OSError, subprocess.TimeoutExpired):
            self.proc.kill()
            self.proc.wait()
        for fd in (self._read, self._write):
            os.close(fd)
        shutil.rmtree(self._profile, ignore_errors=True)
