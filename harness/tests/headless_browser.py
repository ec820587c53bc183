"""Headless Chromium driven over the DevTools protocol on a pipe (`--remote-debugging-pipe`): no
debugging port, no network socket. Loads a page, collects its console errors, failed loads and
uncaught exceptions, evaluates JavaScript and takes a screenshot.
"""

from __future__ import annotations

import base64
import contextlib
import fcntl
import json
import os
import shutil
import signal
import subprocess
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

# fds the browser reads commands from and writes replies to (Chromium's fixed numbers).
COMMAND_FD, REPLY_FD = 3, 4


def chromium_path() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


@dataclass
class PageProblems:
    """Everything the page complained about while it was open."""

    console_errors: list[str] = field(default_factory=list)
    exceptions: list[str] = field(default_factory=list)
    log_errors: list[str] = field(default_factory=list)

    def all(self) -> list[str]:
        return self.console_errors + self.exceptions + self.log_errors


class HeadlessChromium:
    def __init__(self, binary: str, width: int = 1280, height: int = 900) -> None:
        # Chromium's helper processes may still write the profile while it is removed.
        self.profile = tempfile.TemporaryDirectory(prefix="pfnav-chromium-", ignore_cleanup_errors=True)
        command_read, self._command_write = os.pipe()
        self._reply_read, reply_write = os.pipe()
        # The child's ends above the fds Chromium wants, so that putting them on 3 and 4 overwrites neither.
        command_read, reply_write = (self._above_reserved(fd) for fd in (command_read, reply_write))

        args = [
            binary,
            "--headless=new",
            "--remote-debugging-pipe",
            # The tests run as root in a container: Chromium's sandbox needs user namespaces it does not get.
            "--no-sandbox",
            "--disable-gpu",
            "--no-first-run",
            "--no-default-browser-check",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--mute-audio",
            f"--window-size={width},{height}",
            f"--user-data-dir={self.profile.name}",
            "about:blank",
        ]
        # bash puts the pipe ends on the fds Chromium expects (and closes the originals) before it becomes Chromium.
        redirect = f'exec "$0" "$@" {COMMAND_FD}<&{command_read} {REPLY_FD}>&{reply_write} {command_read}<&- {reply_write}>&-'
        self.process = subprocess.Popen(
            ["bash", "-c", redirect, *args],
            pass_fds=(command_read, reply_write),
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            # Its own process group: closing stops Chromium's helper processes too.
            start_new_session=True,
        )
        os.close(command_read)
        os.close(reply_write)
        self._next_id = 0
        self._buffer = b""
        self._events: list[dict[str, Any]] = []
        self.session: str | None = None

    @staticmethod
    def _above_reserved(fd: int) -> int:
        moved = fcntl.fcntl(fd, fcntl.F_DUPFD_CLOEXEC, 10)
        os.close(fd)
        return moved

    def close(self) -> None:
        try:
            os.close(self._command_write)
            os.close(self._reply_read)
        except OSError:
            pass
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        with contextlib.suppress(ProcessLookupError):
            os.killpg(self.process.pid, signal.SIGKILL)
        self.profile.cleanup()

    def __enter__(self) -> HeadlessChromium:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _read_message(self, deadline: float) -> dict[str, Any]:
        while b"\0" not in self._buffer:
            if time.monotonic() > deadline:
                raise TimeoutError("Chromium did not answer in time")
            chunk = os.read(self._reply_read, 1 << 16)
            if not chunk:
                raise RuntimeError(f"Chromium closed the DevTools pipe (exit code {self.process.poll()})")
            self._buffer += chunk
        message, self._buffer = self._buffer.split(b"\0", 1)
        return json.loads(message)

    def send(self, method: str, params: dict[str, Any] | None = None, timeout: float = 30.0) -> dict[str, Any]:
        """Sends one command (to the page's session once attached) and returns its result; events meanwhile are kept."""
        self._next_id += 1
        message: dict[str, Any] = {"id": self._next_id, "method": method, "params": params or {}}
        if self.session is not None and not method.startswith("Target."):
            message["sessionId"] = self.session
        os.write(self._command_write, json.dumps(message).encode() + b"\0")
        deadline = time.monotonic() + timeout
        while True:
            reply = self._read_message(deadline)
            if reply.get("id") == self._next_id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply.get("result", {})
            self._events.append(reply)

    def wait_for_event(self, method: str, timeout: float = 30.0) -> dict[str, Any]:
        deadline = time.monotonic() + timeout
        for event in self._events:
            if event.get("method") == method:
                return event
        while True:
            event = self._read_message(deadline)
            self._events.append(event)
            if event.get("method") == method:
                return event

    def open(self, url: str, timeout: float = 60.0) -> None:
        """A new page attached to this session, with console, log and runtime events on, navigated to `url` until it has loaded."""
        target = self.send("Target.createTarget", {"url": "about:blank"})["targetId"]
        self.session = self.send("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        for domain in ("Page", "Runtime", "Log"):
            self.send(f"{domain}.enable")
        self.send("Page.navigate", {"url": url})
        self.wait_for_event("Page.loadEventFired", timeout)

    def evaluate(self, expression: str, timeout: float = 30.0) -> Any:
        """The value of a JavaScript expression in the page (promises awaited)."""
        result = self.send("Runtime.evaluate", {"expression": expression, "returnByValue": True, "awaitPromise": True}, timeout)
        if "exceptionDetails" in result:
            raise RuntimeError(f"JavaScript failed: {result['exceptionDetails']}")
        return result["result"].get("value")

    def screenshot(self, path: Path) -> Path:
        """A PNG of the whole page (beyond the window's height)."""
        data = self.send("Page.captureScreenshot", {"format": "png", "captureBeyondViewport": True})["data"]
        path.write_bytes(base64.b64decode(data))
        return path

    def problems(self) -> PageProblems:
        found = PageProblems()
        for event in self._events:
            params = event.get("params", {})
            match event.get("method"):
                case "Runtime.consoleAPICalled" if params.get("type") in ("error", "assert"):
                    found.console_errors.append(" ".join(str(arg.get("value", arg.get("description", ""))) for arg in params.get("args", [])))
                case "Runtime.exceptionThrown":
                    details = params.get("exceptionDetails", {})
                    found.exceptions.append(str(details.get("exception", {}).get("description", details.get("text", ""))))
                case "Log.entryAdded" if params.get("entry", {}).get("level") == "error":
                    entry = params["entry"]
                    found.log_errors.append(f"{entry.get('text', '')} {entry.get('url', '')}".strip())
        return found
