"""A small headless-Chromium driver for the viewer's browser tests (pure Python, standard library only).

It talks the DevTools protocol over ``--remote-debugging-pipe`` (NUL-terminated JSON messages on file
descriptors 3 and 4 of the browser process), so no websocket library and no downloaded browser build are
needed: only the system package (Debian: ``chromium-headless-shell``; also found: ``chromium``,
``chromium-browser``, ``google-chrome``, ``headless_shell``, or $CHROMIUM).

Also a tool: ``python tests/browser_testing.py PAGE.html OUT.png [--width W --height H --hash '#t=2']``
saves a screenshot of a page (how docs/viewer.png is made).
"""

from __future__ import annotations

import base64
import fcntl
import json
import os
import pathlib
import select
import shutil
import subprocess
import sys
import tempfile
import time

CANDIDATES = ("chromium-headless-shell", "chromium", "chromium-browser", "google-chrome", "headless_shell",
              "chrome-headless-shell")


def find_chromium():
    """Path of a Chromium binary, or None."""
    env = os.environ.get("CHROMIUM")
    if env and shutil.which(env):
        return shutil.which(env)
    for name in CANDIDATES:
        path = shutil.which(name)
        if path:
            return path
    return None


class BrowserError(RuntimeError):
    pass


class Browser:
    """One headless Chromium with one page; :meth:`send` runs a DevTools command on the page's session and
    collects the events (network requests, exceptions, console and log entries) in :attr:`events`."""

    def __init__(self, binary=None, width=1200, height=700, timeout=60.0):
        self.binary = binary or find_chromium()
        if not self.binary:
            raise BrowserError("no Chromium binary found")
        self.timeout = timeout
        self.profile = tempfile.TemporaryDirectory(prefix="jaxgest-chromium-")
        to_browser_r, self._to_browser = os.pipe()
        self._from_browser, from_browser_w = os.pipe()
        # the browser reads commands on its fd 3 and writes replies on its fd 4: a Python trampoline puts the
        # pipe ends there and execs the browser (no shell: sh cannot redirect descriptors above 9)
        r3, w4 = (fcntl.fcntl(fd, fcntl.F_DUPFD, 5) for fd in (to_browser_r, from_browser_w))  # not 3 or 4
        os.close(to_browser_r)
        os.close(from_browser_w)
        trampoline = ("import os, sys; os.dup2(int(sys.argv[1]), 3); os.dup2(int(sys.argv[2]), 4); "
                      "os.close(int(sys.argv[1])); os.close(int(sys.argv[2])); "
                      "os.execv(sys.argv[3], sys.argv[3:])")
        args = [sys.executable, "-S", "-c", trampoline, str(r3), str(w4),
                self.binary, "--headless", "--remote-debugging-pipe", "--no-sandbox", "--disable-gpu",
                "--no-first-run", "--no-default-browser-check", "--disable-extensions",
                "--disable-background-networking", "--disable-sync", "--disable-component-update",
                "--hide-scrollbars", "--mute-audio", "--force-device-scale-factor=1",
                f"--window-size={width},{height}", f"--user-data-dir={self.profile.name}", "about:blank"]
        self.proc = subprocess.Popen(args, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL, pass_fds=(r3, w4))
        os.close(r3)
        os.close(w4)
        self._buf, self._id, self.events, self.session = b"", 0, [], None
        try:
            target = self._call("Target.createTarget", {"url": "about:blank"})["targetId"]
            attached = self._call("Target.attachToTarget", {"targetId": target, "flatten": True})
            self.session = attached["sessionId"]
            for domain in ("Page", "Runtime", "Network", "Log"):
                self.send(f"{domain}.enable")
            self.send("Emulation.setDeviceMetricsOverride",
                      {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False})
        except Exception:
            self.close()
            raise

    # ------------------------------------------------------------------ protocol
    def _read_message(self, deadline):
        while b"\0" not in self._buf:
            left = deadline - time.monotonic()
            if left <= 0:
                raise BrowserError("timed out waiting for the browser")
            ready, _, _ = select.select([self._from_browser], [], [], left)
            if ready:
                chunk = os.read(self._from_browser, 1 << 20)
                if not chunk:
                    raise BrowserError(f"the browser closed its pipe (exit status {self.proc.poll()})")
                self._buf += chunk
        msg, self._buf = self._buf.split(b"\0", 1)
        return json.loads(msg)

    def _call(self, method, params=None, session=None):
        self._id += 1
        msg = {"id": self._id, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = session
        os.write(self._to_browser, json.dumps(msg).encode() + b"\0")
        deadline = time.monotonic() + self.timeout
        while True:
            reply = self._read_message(deadline)
            if reply.get("id") == self._id:
                if "error" in reply:
                    raise BrowserError(f"{method}: {reply['error']}")
                return reply.get("result", {})
            if "method" in reply:
                self.events.append(reply)

    def send(self, method, params=None):
        return self._call(method, params, self.session)

    # ------------------------------------------------------------------ helpers
    def evaluate(self, expression, await_promise=False):
        r = self.send("Runtime.evaluate", {"expression": expression, "returnByValue": True,
                                           "awaitPromise": await_promise})
        if "exceptionDetails" in r:
            raise BrowserError(f"{expression}: {r['exceptionDetails'].get('text')} "
                               f"{r['exceptionDetails'].get('exception', {}).get('description', '')}")
        return r.get("result", {}).get("value")

    def open(self, url, ready="document.documentElement.getAttribute('data-ready') === '1'"):
        self.send("Page.navigate", {"url": "about:blank"})  # so a new #hash on the same page loads it anew
        self.send("Page.navigate", {"url": url})
        deadline = time.monotonic() + self.timeout
        while time.monotonic() < deadline:
            try:
                if self.evaluate(ready):
                    return
            except BrowserError:
                pass
            time.sleep(0.05)
        raise BrowserError(f"{url}: the page did not report ready within {self.timeout:.0f} s")

    def next_frame(self):
        """Wait until the page has painted twice (so a change is on screen)."""
        self.evaluate("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(() => r(1))))",
                      await_promise=True)

    def screenshot(self):
        """The page as an (H, W, 3) uint8 array."""
        import io

        import numpy as np
        from PIL import Image

        png = base64.b64decode(self.send("Page.captureScreenshot", {"format": "png"})["data"])
        return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))

    def requests(self):
        return [e["params"]["request"]["url"] for e in self.events
                if e["method"] == "Network.requestWillBeSent"]

    def js_errors(self):
        out = []
        for e in self.events:
            m, p = e["method"], e.get("params", {})
            if m == "Runtime.exceptionThrown":
                d = p["exceptionDetails"]
                out.append(d.get("exception", {}).get("description") or d.get("text"))
            elif m == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
                args = (str(a.get("value", a.get("description"))) for a in p["args"])
                out.append("console: " + " ".join(args))
            elif m == "Log.entryAdded" and p["entry"].get("level") == "error":
                out.append("log: " + p["entry"].get("text", ""))
        return out

    def close(self):
        try:
            if self.proc.poll() is None:
                try:
                    self._call("Browser.close")
                except (BrowserError, OSError):
                    pass
                try:
                    self.proc.wait(5)
                except subprocess.TimeoutExpired:
                    self.proc.kill()
                    self.proc.wait(5)
        finally:
            for fd in (self._to_browser, self._from_browser):
                try:
                    os.close(fd)
                except OSError:
                    pass
            self.profile.cleanup()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def screenshot_page(page, out_png, width=1400, height=620, hash_=""):
    """Save a PNG screenshot of ``page`` (a local HTML file) opened in headless Chromium."""
    from PIL import Image

    url = pathlib.Path(page).resolve().as_uri() + hash_
    with Browser(width=width, height=height) as b:
        b.open(url)
        b.next_frame()
        img = b.screenshot()
        errors = b.js_errors()
    if errors:
        raise BrowserError(f"{page}: JavaScript errors: {errors}")
    Image.fromarray(img).quantize(colors=64).save(out_png, optimize=True)
    return out_png


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("page")
    ap.add_argument("out")
    ap.add_argument("--width", type=int, default=1400)
    ap.add_argument("--height", type=int, default=620)
    ap.add_argument("--hash", default="#t=2&paused=1")
    a = ap.parse_args()
    print(screenshot_page(a.page, a.out, a.width, a.height, a.hash))
