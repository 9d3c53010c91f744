#!/usr/bin/env bash
# Loads a report page in headless Chromium and fails (exit 1, with a
# message) when it does not load, logs an error to the console (console
# errors and assertions, uncaught exceptions, failed loads, blocked content)
# or requests anything but the file itself (a report is self-contained).
# With a second argument, also writes a PNG screenshot of the top of the
# page (1200 × 1600), or with a third, of the element that CSS selector
# picks (e.g. '#walkthrough figure', the first match, whole).
#
#   tools/check-report.sh REPORT.html [SCREENSHOT.png [SELECTOR]]
#
# Chromium is driven over the DevTools protocol on a pipe
# (--remote-debugging-pipe, no port), by the Python 3 below. When chromium
# is missing and we are root, it is installed with apt-get (Debian's
# package, /usr/bin/chromium). Exit codes: 0 page fine, 1 page failed the
# check, 2 usage or setup error.
set -euo pipefail

die() { echo "check-report: $*" >&2; exit 2; }

[ $# -ge 1 ] && [ $# -le 3 ] || die "usage: $0 REPORT.html [SCREENSHOT.png [SELECTOR]]"
page=$1
shot=${2:-}
selector=${3:-}
[ -f "$page" ] || die "no such file: $page"

if ! command -v chromium >/dev/null 2>&1; then
    [ "$(id -u)" = 0 ] || die "chromium is not installed (as root: apt-get install -y chromium)"
    echo "check-report: installing chromium" >&2
    apt-get update -qq >&2
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >&2
fi
command -v python3 >/dev/null 2>&1 || die "python3 is needed to drive chromium"

profile=$(mktemp -d)
trap 'rm -rf "$profile"' EXIT

url="file://$(realpath "$page")"
shot_abs=""
if [ -n "$shot" ]; then
    mkdir -p "$(dirname "$shot")"
    shot_abs=$(realpath -m "$shot")
fi

CHROMIUM=$(command -v chromium) PROFILE="$profile" URL="$url" SHOT="$shot_abs" SELECTOR="$selector" \
    timeout 180 python3 - <<'PY'
import base64, json, os, select, subprocess, sys, time

url, shot, profile = os.environ["URL"], os.environ["SHOT"], os.environ["PROFILE"]
flags = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
    "--disable-extensions", "--disable-default-apps", "--mute-audio",
    "--hide-scrollbars", "--user-data-dir=" + profile, "--remote-debugging-pipe",
]
# Chromium reads protocol messages from fd 3 and writes them to fd 4,
# each ended by a NUL byte.
to_chrome_r, to_chrome_w = os.pipe()
from_chrome_r, from_chrome_w = os.pipe()

def child_fds():
    # Copy first: the pipe ends may themselves be fds 3 and 4.
    r, w = os.dup(to_chrome_r), os.dup(from_chrome_w)
    os.dup2(r, 3)
    os.dup2(w, 4)

log = open(os.path.join(profile, "chromium.log"), "wb")
proc = subprocess.Popen([os.environ["CHROMIUM"], *flags, "about:blank"],
                        stdin=subprocess.DEVNULL, stdout=log, stderr=log,
                        preexec_fn=child_fds, close_fds=False)
os.close(to_chrome_r)
os.close(from_chrome_w)

buf = b""
events = []
next_id = 0

def fail_setup(msg):
    proc.kill()
    print("check-report: " + msg, file=sys.stderr)
    sys.exit(2)

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
            fail_setup("chromium exited (see its log: rerun with a kept profile)")
        buf += chunk
    msg, buf = buf.split(b"\0", 1)
    return json.loads(msg)

def call(method, params=None, session=None, timeout=30):
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
            fail_setup("no answer to " + method)
        if m.get("id") == next_id:
            if "error" in m:
                fail_setup(method + " failed: " + json.dumps(m["error"]))
            return m.get("result", {})
        events.append(m)

def wait_for(method, timeout):
    deadline = time.monotonic() + timeout
    if any(e.get("method") == method for e in events):
        return True
    while True:
        m = read_message(deadline)
        if m is None:
            return False
        events.append(m)
        if m.get("method") == method:
            return True

target = call("Target.createTarget", {"url": "about:blank"})["targetId"]
s = call("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
for domain in ("Page", "Runtime", "Log", "Network"):
    call(domain + ".enable", session=s)
call("Emulation.setDeviceMetricsOverride",
     {"width": 1200, "height": 1600, "deviceScaleFactor": 1, "mobile": False}, session=s)
events.clear()
nav = call("Page.navigate", {"url": url}, session=s)
problems = []
if nav.get("errorText"):
    problems.append("navigation failed: " + nav["errorText"])
elif not wait_for("Page.loadEventFired", 60):
    problems.append("the page did not finish loading within 60 s")
# Let late console messages arrive.
deadline = time.monotonic() + 1.0
while (m := read_message(deadline)) is not None:
    events.append(m)

state = call("Runtime.evaluate", {
    "expression": "JSON.stringify({ready: document.readyState, title: document.title,"
                  " svgs: document.querySelectorAll('svg').length,"
                  " tables: document.querySelectorAll('table').length,"
                  " text: document.body ? document.body.innerText.length : 0})",
    "returnByValue": True}, session=s)
info = json.loads(state.get("result", {}).get("value") or "{}")
if info.get("ready") != "complete" or not info.get("text"):
    problems.append("the page did not load and render: " + json.dumps(info))

for e in events:
    m, p = e.get("method"), e.get("params", {})
    if m == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
        text = " ".join(str(a.get("value", a.get("description", ""))) for a in p.get("args", []))
        problems.append("console %s: %s" % (p["type"], text))
    elif m == "Runtime.exceptionThrown":
        d = p.get("exceptionDetails", {})
        problems.append("uncaught exception: " + d.get("exception", {}).get("description", d.get("text", "")))
    elif m == "Log.entryAdded" and p.get("entry", {}).get("level") == "error":
        entry = p["entry"]
        problems.append("console error (%s): %s %s" % (entry.get("source"), entry.get("text"), entry.get("url", "")))
    elif m == "Network.requestWillBeSent":
        req = p.get("request", {}).get("url", "")
        if not (req == url or req.startswith("data:") or req.startswith("about:")):
            problems.append("the page requested an external resource: " + req)

selector = os.environ.get("SELECTOR", "")
clip = {"x": 0, "y": 0, "width": 1200, "height": 1600, "scale": 1}
if shot and selector:
    box = call("Runtime.evaluate", {
        "expression": "(() => { const e = document.querySelector(%s); if (!e) return null;"
                      " const r = e.getBoundingClientRect();"
                      " return JSON.stringify({x: r.left + scrollX, y: r.top + scrollY,"
                      " width: r.width, height: r.height}); })()" % json.dumps(selector),
        "returnByValue": True}, session=s).get("result", {}).get("value")
    if not box:
        problems.append("no element matches the selector " + selector)
    else:
        clip = dict(json.loads(box), scale=1)
if shot:
    png = call("Page.captureScreenshot", {"format": "png", "clip": clip,
        "captureBeyondViewport": True}, session=s)
    with open(shot, "wb") as f:
        f.write(base64.b64decode(png["data"]))

os.write(to_chrome_w, json.dumps({"id": next_id + 1, "method": "Browser.close"}).encode() + b"\0")
try:
    proc.wait(timeout=20)
except subprocess.TimeoutExpired:
    proc.kill()

print("check-report: %s: title %r, %d SVG charts, %d tables" % (
    url, info.get("title"), info.get("svgs", 0), info.get("tables", 0)))
if shot:
    print("check-report: screenshot written to " + shot)
if problems:
    for p in problems:
        print("check-report: FAIL: " + p, file=sys.stderr)
    sys.exit(1)
print("check-report: OK: loaded, no console errors, no external requests")
PY
