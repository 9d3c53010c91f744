#!/usr/bin/env python3
"""Frame rate of the web page's 3D viewer in headless Chromium (SwiftShader,
software WebGL), on a baked job of a running impostor-server:

    tools/viewer-fps.py http://127.0.0.1:PORT JOB_ID [FRAMES [TRIANGLES]]

Opens the job's viewer through tools/chromium-cdp.py and measures, on a
960 x 600 canvas:
  - draw time per frame over FRAMES views in CPVs with impostors (spread
    over the placement's list, each from its region's centre along its
    VDI's centre; each frame drawn and waited for by reading one pixel
    back), with the placement's impostors and with the scene alone (the
    viewer's "without impostors" toggle);
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
# The viewer's display budget (#/jobs/ID/view?triangles=N; 0: the scene as
# uploaded); the viewer's default when not given.
budget = "?triangles=%d" % int(sys.argv[4]) if len(sys.argv) > 4 else ""
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
send("Page.navigate", {"url": "%s/#/jobs/%s/view%s" % (base, job, budget)})
js(r"""new Promise((ok, no) => { const t = setInterval(() => {
  const v = document.getElementById('viewer');
  if (v && v.dataset.error) { clearInterval(t); no(new Error(v.dataset.error)); }
  if (v && v.dataset.ready === 'true') { clearInterval(t); ok(true); } }, 200); })""")

DRAW = """(() => { const v = impostorViewer, gl = v.renderer.getContext(), px = new Uint8Array(4);
  const n = %d, plain = %s;
  // Views in CPVs with impostors, spread over the placement's list: each
  // from its region's centre along its VDI's centre.
  const cpvs = v.placement.cpvs.filter((c) => c.impostors.length > 0);
  const views = [];
  for (let i = 0; i < Math.min(n, cpvs.length); i++) {
    const c = cpvs[Math.floor((i * cpvs.length) / Math.min(n, cpvs.length))], r = c.region, d = c.directions;
    const axis = d.face >> 1, dir = [0, 0, 0], rest = [0, 1, 2].filter((a) => a !== axis);
    dir[axis] = d.face %% 2 === 0 ? 1 : -1;
    dir[rest[0]] = (d.u[0] + d.u[1]) / 2;
    dir[rest[1]] = (d.v[0] + d.v[1]) / 2;
    views.push([[0, 1, 2].map((a) => (r.min[a] + r.max[a]) / 2), dir]);
  }
  v.setPlain(plain);
  v.lookFrom(...views[0]); gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
  const t0 = performance.now(); let shown = 0;
  for (const [p, d] of views) {
    v.lookFrom(p, d); gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
    shown += Number(v.root.dataset.visibleImpostorNodes || 0);
  }
  return { views: views.length, ms_per_frame: (performance.now() - t0) / views.length,
           impostors_per_frame: shown / views.length }; })()"""
WALK = """new Promise((ok) => { const v = impostorViewer; v.setPlain(%s);
  if (!v.walk) v.toggleWalk();
  let n = 0; const t0 = performance.now();
  const count = () => { n++; if (performance.now() - t0 < 10000) requestAnimationFrame(count);
    else { if (v.walk) v.toggleWalk(); ok({ fps: n / ((performance.now() - t0) / 1000) }); } };
  requestAnimationFrame(count); })"""
out = {"frames": frames, "canvas": [960, 600],
       "triangles": js("Number(impostorViewer.root.dataset.sceneTriangles)"),
       "drawn_triangles": js("Number(impostorViewer.root.dataset.drawnTriangles)"),
       "objects": js("impostorViewer.objectMeshes.length"),
       "impostors": js("impostorViewer.impostorNodes.size")}
print("viewer-fps: the viewer is open (%d objects, %d triangles, %d drawn)"
      % (out["objects"], out["triangles"], out["drawn_triangles"]),
      file=sys.stderr)
for name, plain in (("with_impostors", "false"), ("without_impostors", "true")):
    out[name] = js(DRAW % (frames, plain), timeout=3600)
    print("viewer-fps: %s: %s" % (name, out[name]), file=sys.stderr)
    out[name].update(js(WALK % plain, timeout=900))
out["problems"] = send("bridge.problems")
bridge.stdin.close()
bridge.wait()
print(json.dumps(out, indent=2))
