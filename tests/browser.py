"""Open a page in headless Chromium and report what it did: console errors, requests, figure sizes.

Chromium is driven through its DevTools protocol over a pipe (``--remote-debugging-pipe``: commands
on file descriptor 3, replies and events on 4, NUL-terminated JSON), so no library and no network
port are needed, only Debian's ``chromium`` package (``.ci/run`` installs it).

Used by tests/test_report.py; run as a script it saves a screenshot of a page::

    python tests/browser.py out/diag/report.html docs/images/report_diagnosis.png [HEIGHT]

(the page's top ``HEIGHT`` CSS pixels, 1200 wide; the whole page without it).
"""

from __future__ import annotations

import base64
import fcntl
import json
import os
import select
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

#: The flags that run Chromium here: no sandbox (root in a container), no GPU, nothing fetched behind the
#: page's back (no QUIC, background networking, component updates or sync), a fresh profile each time,
#: no scroll bar in a screenshot.
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync", "--hide-scrollbars")
#: Seconds a page may take to load (a 1 MB report loads in well under one here).
TIMEOUT = 60.0
#: What a figure is, on a report page.
FIGURES = "figure svg, figure img"


def chromium() -> str | None:
    """The Chromium executable on PATH, or None."""
    return shutil.which("chromium") or shutil.which("chromium-browser")


@dataclass
class Load:
    """What opening a page did.

    Attributes
    ----------
    errors : list of str
        Console errors, uncaught exceptions and browser log errors (a blocked request among them).
    requests : list of str
        Every URL the page requested (the page itself first).
    figures : list of (float, float)
        Width and height (CSS pixels) of each figure on the page.
    screenshot : bytes
        A PNG of the whole page (when asked for).
    """

    errors: list = field(default_factory=list)
    requests: list = field(default_factory=list)
    figures: list = field(default_factory=list)
    screenshot: bytes = b""


class _Pipe:
    """The DevTools protocol over Chromium's pipe."""

    def __init__(self, write_fd: int, read_fd: int):
        self.write_fd, self.read_fd = write_fd, read_fd
        self.buffer = b""
        self.next_id = 0
        self.events: list = []

    def send(self, method: str, params: dict | None = None, session: str | None = None) -> dict:
        self.next_id += 1
        message = {"id": self.next_id, "method": method, "params": params or {}}
        if session:
            message["sessionId"] = session
        os.write(self.write_fd, json.dumps(message).encode() + b"\0")
        reply = self.wait(lambda m: m.get("id") == self.next_id)
        if "error" in reply:
            raise RuntimeError(f"{method}: {reply['error']}")
        return reply.get("result", {})

    def wait(self, wanted, timeout: float = TIMEOUT) -> dict:
        end = time.monotonic() + timeout
        while True:
            while b"\0" in self.buffer:
                raw, self.buffer = self.buffer.split(b"\0", 1)
                message = json.loads(raw)
                if "method" in message:
                    self.events.append(message)
                if wanted(message):
                    return message
            ready, _, _ = select.select([self.read_fd], [], [], max(0.0, end - time.monotonic()))
            if not ready:
                raise TimeoutError(f"Chromium did not answer within {timeout:g} s")
            chunk = os.read(self.read_fd, 1 << 20)
            if not chunk:
                raise EOFError("Chromium closed its pipe")
            self.buffer += chunk


def open_page(path, *, width: int = 1200, screenshot: bool = False, height: int | None = None) -> Load:
    """Load the file ``path`` in headless Chromium, ``width`` CSS pixels wide, and return what it did
    (``screenshot``: with a PNG of the whole page, or of its top ``height`` pixels)."""
    exe = chromium()
    if exe is None:
        raise FileNotFoundError("chromium is not installed (apt-get install -y chromium)")
    commands_r, commands_w = os.pipe()
    replies_r, replies_w = os.pipe()
    # above 2 so that putting them at 3 and 4 in the child never overwrites one before it is copied
    child_in, child_out = fcntl.fcntl(commands_r, fcntl.F_DUPFD, 10), fcntl.fcntl(replies_w, fcntl.F_DUPFD, 10)

    def at_3_and_4():
        os.dup2(child_in, 3)
        os.dup2(child_out, 4)

    profile = tempfile.mkdtemp(prefix="momentid-chromium-")
    proc = subprocess.Popen([exe, *FLAGS, f"--user-data-dir={profile}", "--remote-debugging-pipe", "about:blank"],
                            preexec_fn=at_3_and_4, pass_fds=(3, 4), stdin=subprocess.DEVNULL,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    for fd in (commands_r, replies_w, child_in, child_out):
        os.close(fd)
    pipe = _Pipe(commands_w, replies_r)
    load = Load()
    try:
        page = next(t for t in pipe.send("Target.getTargets")["targetInfos"] if t["type"] == "page")
        session = pipe.send("Target.attachToTarget", {"targetId": page["targetId"], "flatten": True})["sessionId"]
        for domain in ("Page", "Runtime", "Log", "Network"):
            pipe.send(f"{domain}.enable", session=session)
        pipe.send("Emulation.setDeviceMetricsOverride", {"width": width, "height": height or 900,
                                                         "deviceScaleFactor": 1, "mobile": False}, session=session)
        pipe.send("Page.navigate", {"url": Path(path).resolve().as_uri()}, session=session)
        pipe.wait(lambda m: m.get("method") == "Page.loadEventFired")
        sizes = pipe.send("Runtime.evaluate", {
            "expression": f"JSON.stringify([...document.querySelectorAll({json.dumps(FIGURES)})].map("
                          f"e => {{ const r = e.getBoundingClientRect(); return [r.width, r.height]; }}))",
            "returnByValue": True}, session=session)
        load.figures = [tuple(x) for x in json.loads(sizes["result"]["value"])]
        if screenshot:
            shot = pipe.send("Page.captureScreenshot", {"format": "png", "captureBeyondViewport": height is None},
                             session=session)
            load.screenshot = base64.b64decode(shot["data"])
        pipe.send("Runtime.evaluate", {"expression": "1"}, session=session)   # events so far are in
    finally:
        try:
            pipe.send("Browser.close")
        except (EOFError, OSError, RuntimeError, TimeoutError):
            pass
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        os.close(commands_w)
        os.close(replies_r)
        shutil.rmtree(profile, ignore_errors=True)
    for event in pipe.events:
        method, params = event["method"], event.get("params", {})
        if method == "Runtime.consoleAPICalled" and params.get("type") in ("error", "assert"):
            load.errors.append("console: " + " ".join(str(a.get("value", a.get("description", "")))
                                                      for a in params.get("args", [])))
        elif method == "Runtime.exceptionThrown":
            load.errors.append("exception: " + params["exceptionDetails"].get("text", ""))
        elif method == "Log.entryAdded" and params["entry"].get("level") == "error":
            load.errors.append(f"{params['entry'].get('source')}: {params['entry'].get('text')}")
        elif method == "Network.requestWillBeSent":
            load.requests.append(params["request"]["url"])
    return load


if __name__ == "__main__":
    if len(sys.argv) not in (3, 4):
        sys.exit("usage: python tests/browser.py PAGE.html SCREENSHOT.png [HEIGHT]")
    result = open_page(sys.argv[1], screenshot=True, height=int(sys.argv[3]) if len(sys.argv) == 4 else None)
    Path(sys.argv[2]).write_bytes(result.screenshot)
    print(f"{sys.argv[1]}: {len(result.figures)} figures, {len(result.errors)} errors, "
          f"{len(result.requests)} requests -> {sys.argv[2]}")
