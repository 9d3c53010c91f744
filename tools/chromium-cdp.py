#!/usr/bin/env python3
"""A line bridge to headless Chromium's DevTools protocol, for the tests.

Starts Debian's chromium headless (the same flags and pipe transport as
tools/check-report.sh: --remote-debugging-pipe, no port), opens one page and
attaches to it, then reads commands from stdin, one JSON object a line:

    {"method": "Runtime.evaluate", "params": {...}}

and answers each with one line on stdout: {"result": ...} or
{"error": ...}. Commands go to the page. One command of the
bridge's own: {"method": "bridge.problems"} answers with the console errors
and uncaught exceptions the page has had so far. At the end of stdin the
browser is closed.

WebGL runs on SwiftShader (software), so the page can render without a GPU.
Exit codes: 0 done, 2 setup error (no chromium, chromium exited).
"""
import json, os, select, shutil, subprocess, sys, tempfile, time

chromium = os.environ.get("CHROMIUM") or shutil.which("chromium")
if not chromium:
    print("chromium-cdp: chromium is not installed (tools/install-test-deps.sh installs "
          "Debian's chromium package)", file=sys.stderr)
    sys.exit(2)

profile = tempfile.mkdtemp(prefix="impostor-chromium-")
flags = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
    "--disable-extensions", "--disable-default-apps", "--mute-audio", "--hide-scrollbars",
    "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist",
    "--user-data-dir=" + profile, "--remote-debugging-pipe",
]
to_chrome_r, to_chrome_w = os.pipe()
from_chrome_r, from_chrome_w = os.pipe()

def child_fds():
    # Chromium reads protocol messages from fd 3 and writes them to fd 4.
    r, w = os.dup(to_chrome_r), os.dup(from_chrome_w)
    os.dup2(r, 3)
    os.dup2(w, 4)

log = open(os.path.join(profile, "chromium.log"), "wb")
proc = subprocess.Popen([chromium, *flags, "about:blank"], stdin=subprocess.DEVNULL,
                        stdout=log, stderr=log, preexec_fn=child_fds, close_fds=False)
os.close(to_chrome_r)
os.close(from_chrome_w)

buf = b""
next_id = 0
problems = []

def fail_setup(msg):
    proc.kill()
    try:
        tail = open(os.path.join(profile, "chromium.log"), errors="replace").read()[-2000:]
    except OSError:
        tail = ""
    print("chromium-cdp: " + msg + "\n" + tail, file=sys.stderr)
    shutil.rmtree(profile, ignore_errors=True)
    sys.exit(2)

def note(m):
    """Keeps the page's console errors and uncaught exceptions."""
    method, p = m.get("method"), m.get("params", {})
    if method == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
        problems.append("console %s: %s" % (p["type"], " ".join(
            str(a.get("value", a.get("description", ""))) for a in p.get("args", []))))
    elif method == "Runtime.exceptionThrown":
        d = p.get("exceptionDetails", {})
        problems.append("uncaught exception: " +
                        d.get("exception", {}).get("description", d.get("text", "")))
    elif method == "Log.entryAdded" and p.get("entry", {}).get("level") == "error":
        e = p["entry"]
        problems.append("console error (%s): %s %s" % (e.get("source"), e.get("text"), e.get("url", "")))

def read_message(deadline):
    global buf
    while b"\0" not in buf:
        left = deadline - time.monotonic()
        if left <= 0:
            return None
        ready, _, _ = select.select([from_chrome_r], [], [], left)
        if not ready:
            return None
        chunk = os.read(from_chrome_r, 1 << 20)
        if not chunk:
            fail_setup("chromium exited; its log ends with:")
        buf += chunk
    msg, buf = buf.split(b"\0", 1)
    return json.loads(msg)

def call(method, params=None, session=None, timeout=60):
    """The answer to one command: ("result", value) or ("error", value)."""
    global next_id
    next_id += 1
    msg = {"id": next_id, "method": method, "params": params or {}}
    if session:
        msg["sessionId"] = session
    os.write(to_chrome_w, json.dumps(msg).encode() + b"\0")
    deadline = time.monotonic() + timeout
    while True:
        m = read_message(deadline)
        if m is None:
            return ("error", {"message": "no answer to %s within %d s" % (method, timeout)})
        if m.get("id") == next_id:
            if "error" in m:
                return ("error", m["error"])
            return ("result", m.get("result", {}))
        note(m)

def must(method, params=None, session=None):
    kind, value = call(method, params, session)
    if kind == "error":
        fail_setup("%s failed: %s" % (method, json.dumps(value)))
    return value

target = must("Target.createTarget", {"url": "about:blank"})["targetId"]
session = must("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
for domain in ("Page", "Runtime", "Log", "DOM"):
    must(domain + ".enable", session=session)
must("Emulation.setDeviceMetricsOverride",
     {"width": 1280, "height": 900, "deviceScaleFactor": 1, "mobile": False}, session=session)
print(json.dumps({"result": {"ready": True}}), flush=True)

for line in sys.stdin:
    line = line.strip()
    if not line:
        continue
    cmd = json.loads(line)
    if cmd.get("method") == "bridge.problems":
        # Collect what arrived meanwhile.
        deadline = time.monotonic() + 0.2
        while (m := read_message(deadline)) is not None:
            note(m)
        print(json.dumps({"result": problems}), flush=True)
        continue
    kind, value = call(cmd["method"], cmd.get("params"), session, cmd.get("timeout", 60))
    print(json.dumps({kind: value}), flush=True)

os.write(to_chrome_w, json.dumps({"id": next_id + 1, "method": "Browser.close"}).encode() + b"\0")
try:
    proc.wait(timeout=20)
except subprocess.TimeoutExpired:
    proc.kill()
shutil.rmtree(profile, ignore_errors=True)
