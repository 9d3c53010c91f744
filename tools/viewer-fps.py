#!/usr/bin/env python3
"""Frame rate of the web page's 3D viewer in headless Chromium (SwiftShader,
software WebGL), on a baked job of a running impostor-server:

    tools/viewer-fps.py http://127.0.0.1:PORT JOB_ID [FRAMES]

Opens the job's viewer through tools/chromium-cdp.py and measures, on a
960 x 600 canvas:
  - draw time per frame over FRAMES frames of the job's walkthrough path
    (`impostorViewer.walkFrame`; each frame drawn and waited for by reading
    one pixel back), with the placement's impostors and with the scene
    alone (the viewer's "without impostors" toggle);
  - the page's frame rate while walking the path in real time (animation
    frames counted over 10 s), both ways.
Prints one JSON object. `tools/viewer-fps.sh` starts a server and submits
the job for it.
"""
import json, os, subprocess, sys

if len(sys.argv) < 3:
    print(__doc__, file=sys.stderr)
    sys.exit(2)
base, job = sys.argv[1].rstrip("/"), sys.argv[2]
frames = int(sys.argv[3]) if len(sys.argv) > 3 else 100
bridge = subprocess.Popen(
    [sys.executable, os.path.join(os.path.dirname(os.path.abspath(__file__)), "chromium-cdp.py")],
    stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)

def send(method, params=None, timeout=60):
    bridge.stdin.write(json.dumps({"method": method, "params": params or {}, "timeout": timeout}) + "\n")
    bridge.stdin.flush()
    answer = json.loads(bridge.stdout.readline())
    if "error" in answer:
        sys.exit("viewer-fps: %s failed: %s" % (method, answer["error"]))
    return answer["result"]

def js(expr, timeout=600):
    r = send("Runtime.evaluate", {"expression": expr, "awaitPromise": True, "returnByValue": True},
             timeout)
    if "exceptionDetails" in r:
        sys.exit("viewer-fps: %s: %s" % (expr[:60], r["exceptionDetails"]))
    return r["result"].get("value")

assert json.loads(bridge.stdout.readline())["result"]["ready"]
send("Page.navigate", {"url": "%s/#/jobs/%s/view" % (base, job)})
js(r"""new Promise((ok, no) => { const t = setInterval(() => {
  const v = document.getElementById('viewer');
  if (v && v.dataset.error) { clearInterval(t); no(new Error(v.dataset.error)); }
  if (v && v.dataset.ready === 'true') { clearInterval(t); ok(true); } }, 200); })""")

DRAW = """(() => { const v = impostorViewer, gl = v.renderer.getContext(), px = new Uint8Array(4);
  v.setPlain(%s); v.walkFrame(0, %d); gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
  const t0 = performance.now(); let shown = 0;
  for (let i = 0; i < %d; i++) {
    v.walkFrame(i, %d); gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
    shown += Number(v.root.dataset.visibleImpostorNodes || 0);
  }
  return { ms_per_frame: (performance.now() - t0) / %d, impostors_per_frame: shown / %d }; })()"""
WALK = """new Promise((ok) => { const v = impostorViewer; v.setPlain(%s);
  if (!v.walk) v.toggleWalk();
  let n = 0; const t0 = performance.now();
  const count = () => { n++; if (performance.now() - t0 < 10000) requestAnimationFrame(count);
    else { if (v.walk) v.toggleWalk(); ok({ fps: n / ((performance.now() - t0) / 1000) }); } };
  requestAnimationFrame(count); })"""
out = {"frames": frames, "canvas": [960, 600],
       "triangles": js("impostorViewer.triangles"),
       "objects": js("impostorViewer.objectMeshes.length"),
       "impostors": js("impostorViewer.impostorNodes.size")}
print("viewer-fps: the viewer is open (%d objects, %d triangles)" % (out["objects"], out["triangles"]),
      file=sys.stderr)
for name, plain in (("with_impostors", "false"), ("without_impostors", "true")):
    out[name] = js(DRAW % (plain, frames, frames, frames, frames, frames), timeout=3600)
    print("viewer-fps: %s: %s" % (name, out[name]), file=sys.stderr)
    out[name].update(js(WALK % plain, timeout=900))
out["problems"] = send("bridge.problems")
bridge.stdin.close()
bridge.wait()
print(json.dumps(out, indent=2))
