// The 3D viewer of a finished, baked job: the scene as submitted and the
// baked impostors, flown through with WASD + mouse (or along the job's
// walkthrough path). Each frame it finds the camera's CPV in the placement,
// shows that CPV's impostors in place of their clusters' objects and plots
// the CPV's estimated frame time with and without impostors.
//
// Atlases may be PNG or KTX2 (Basis Universal, transcoded by three.js's
// KTX2Loader with the transcoder the server serves); scenes may be
// Draco-compressed (three.js's DRACOLoader with the decoder the server
// serves).
//
// State for tests and scripts: the #viewer element's data-* attributes
// (ready, cpv, active-impostors, hidden-objects, frame-ms,
// frame-ms-original, visible-impostor-nodes, walking) and window.impostorViewer
// (lookFrom, walkFrame, state, textures, pixels, footprint, objectBox).
import * as THREE from "three";
import { GLTFLoader } from "three/examples/jsm/loaders/GLTFLoader.js";
import { DRACOLoader } from "three/examples/jsm/loaders/DRACOLoader.js";
import { KTX2Loader } from "three/examples/jsm/loaders/KTX2Loader.js";
import { DISPLAY_TRIANGLES, decimate } from "./decimate.js";
import { bytes, json } from "./api.js";
import { FrameChart } from "./chart.js";
import { expandCpvLists, findCpv } from "./cpv.js";
import { errorBox, h } from "./dom.js";
import { glbJson, objectNodes } from "./objects.js";
import { regionLines, viewCell, boxLines } from "./overlays.js";

/// Meshes on this layer are not drawn (the camera sees layer 0 only);
/// layers are not inherited, so hiding a node's meshes leaves its children.
const HIDDEN = 1;
/// The Basis Universal transcoder's folder (set by build.mjs), for KTX2
/// atlases (`KHR_texture_basisu`).
const TRANSCODER = BASIS_PATH;
/// Draco's decoder folder (set by build.mjs), for Draco-compressed scenes
/// (`KHR_draco_mesh_compression`).
const DRACO_DECODER = DRACO_PATH;

/// The viewer of job `id`; scenes over `triangles` triangles (default
/// DISPLAY_TRIANGLES; 0: never) are drawn decimated.
export async function viewerPage(main, id, signal, triangles = DISPLAY_TRIANGLES) {
  const root = h("section", { id: "viewer", class: "viewer-page" });
  main.append(h("h1", {}, "Viewer of job ", h("a", { href: `#/jobs/${id}` }, h("code", {}, id))), root);
  const status = h("p", {}, "Loading the scene, the impostors and the placement…");
  root.append(status);
  const canvas = h("canvas", { class: "scene", width: 960, height: 600, tabindex: 0 });
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
  let data;
  try {
    data = await load(id, renderer);
  } catch (e) {
    renderer.dispose();
    status.replaceWith(errorBox(e));
    root.dataset.error = String(e.message || e);
    return;
  }
  if (signal.aborted) return;
  status.remove();
  const viewer = new Viewer(root, renderer, data, signal);
  window.impostorViewer = viewer;
  await viewer.fitForDisplay(triangles);
  if (signal.aborted) return;
  root.dataset.ready = "true";
}

/// The job, its placement, its scene and its baked impostors (PNG or KTX2
/// atlases), parsed by three.js's GLTFLoader for `renderer`.
async function load(id, renderer) {
  const job = await json(`/v1/jobs/${id}`);
  if (job.state !== "succeeded") throw new Error(`job ${id} is ${job.state}: the viewer needs a finished job`);
  if (!job.bake) throw new Error(`job ${id} was not baked: submit it with “bake” to view its impostors`);
  const [params, placement, sceneBytes, impostorBytes] = await Promise.all([
    json(`/v1/jobs/${id}/job`),
    json(`/v1/jobs/${id}/placement`),
    bytes(`/v1/jobs/${id}/scene`),
    bytes(`/v1/jobs/${id}/impostors.glb`),
  ]);
  const ktx2 = new KTX2Loader().setTranscoderPath(TRANSCODER).detectSupport(renderer);
  const draco = new DRACOLoader().setDecoderPath(DRACO_DECODER).setDecoderConfig({ type: "wasm" });
  const loader = new GLTFLoader().setKTX2Loader(ktx2).setDRACOLoader(draco);
  let scene, impostors;
  try {
    [scene, impostors] = await Promise.all([
      loader.parseAsync(sceneBytes, ""),
      loader.parseAsync(impostorBytes, ""),
    ]);
  } finally {
    ktx2.dispose();
    draco.dispose();
  }
  expandCpvLists(placement.cpvs);
  const sceneJson = glbJson(sceneBytes);
  const nodeObjects = await Promise.all(
    (sceneJson.nodes || []).map((_, i) => scene.parser.getDependency("node", i)));
  return { params, placement, scene, sceneJson, nodeObjects, impostors };
}

/// The instance matrices `mesh` was loaded with (kept before any instance
/// is hidden).
function instanceMatrices(mesh) {
  if (!mesh.userData.loadedMatrices) mesh.userData.loadedMatrices = mesh.instanceMatrix.array.slice();
  return mesh.userData.loadedMatrices;
}

/// Shows instance `k` of an instanced mesh with its loaded matrix, or hides
/// it (a zero matrix: it draws nothing); layers hide whole meshes only.
function showInstance(mesh, k, on) {
  const loaded = instanceMatrices(mesh);
  const a = mesh.instanceMatrix.array;
  for (let i = 16 * k; i < 16 * k + 16; i++) a[i] = on ? loaded[i] : 0;
  mesh.instanceMatrix.needsUpdate = true;
}

class Viewer {
  constructor(root, renderer, { params, placement, scene, sceneJson, nodeObjects, impostors }, signal) {
    this.root = root;
    this.placement = placement;
    this.vs = params.view_space;
    this.target = placement.summary.target_frame_time_ms;
    this.walkPoints = params.walkthrough ? params.walkthrough.points : null;

    this.renderer = renderer;
    this.canvas = renderer.domElement;
    const chartCanvas = h("canvas", { width: 380, height: 200, id: "frame-chart" });
    this.info = h("div", { id: "viewer-info" });
    const toggle = (label, fn) => h("label", {}, h("input", { type: "checkbox", onchange: (e) => fn(e.target.checked) }), ` ${label}`, h("br"));
    this.walkButton = h("button", { id: "walk", disabled: !this.walkPoints, onclick: () => this.toggleWalk() },
      this.walkPoints ? "Walk the path" : "no walkthrough path in the job");
    const aside = h("aside", {},
      h("p", {}, "Fly: W A S D, R/F up and down, drag the mouse to look; shift: faster."),
      h("p", {}, this.walkButton),
      toggle("view cells of the shown impostors", (on) => { this.showCells = on; this.cellsFor = null; }),
      toggle("CPV regions", (on) => { this.regions.visible = on; this.cpvBox.visible = on; }),
      toggle("the scene without impostors", (on) => this.setPlain(on)),
      h("h3", {}, "Estimated frame time of the camera's CPV"), chartCanvas, this.info);
    const layout = h("div", { class: "viewer" }, this.canvas, aside);
    root.append(layout);
    this.chart = new FrameChart(chartCanvas);

    this.renderer.setClearColor(0xb0bec5);
    this.three = new THREE.Scene();
    this.three.add(new THREE.HemisphereLight(0xffffff, 0x555555, 2.5));
    const sun = new THREE.DirectionalLight(0xffffff, 1.5);
    sun.position.set(1, 2, 1.5);
    this.three.add(sun);
    this.three.add(scene.scene, impostors.scene);

    this.mapScene(scene, sceneJson, nodeObjects);
    this.mapImpostors(impostors);
    this.cells = new THREE.Group();
    this.three.add(this.cells);
    this.regions = regionLines(placement.cpvs.map((c) => c.region), 0x6a1b9a);
    this.regions.visible = false;
    this.three.add(this.regions);
    this.cpvBox = new THREE.Group();
    this.cpvBox.visible = false;
    this.three.add(this.cpvBox);

    const fov = params.camera && params.camera.fov_deg ? params.camera.fov_deg : 45;
    this.camera = new THREE.PerspectiveCamera(fov, 960 / 600, 0.1, 20000);
    this.camera.layers.set(0);
    const [min, max] = [this.vs.min, this.vs.max];
    this.size = Math.hypot(max[0] - min[0], max[1] - min[1], max[2] - min[2]);
    this.pos = new THREE.Vector3((min[0] + max[0]) / 2, (min[1] + max[1]) / 2, (min[2] + max[2]) / 2);
    this.yaw = 0;
    this.pitch = 0;
    this.keys = new Set();
    this.walk = null;
    this.cpv = undefined;
    this.plain = false;
    this.bindInput(signal);
    this.last = performance.now();
    const frame = (t) => {
      if (signal.aborted) { this.renderer.dispose(); return; }
      this.tick(Math.min(0.25, (t - this.last) / 1000));
      this.last = t;
      requestAnimationFrame(frame);
    };
    requestAnimationFrame(frame);
  }

  /// The meshes of each object id (own meshes of its node: not those of
  /// child nodes, which are objects of their own). `nodeObjects`: the
  /// three.js object of each glTF node (the loader's node cache; its
  /// associations are shared between the instances of a mesh).
  mapScene(gltf, sceneJson, nodeObjects) {
    const { objects, instances, levels } = objectNodes(sceneJson);
    const isNode = new Set(nodeObjects);
    const own = (o) => {
      const out = o.isMesh ? [o] : [];
      for (const c of o.children) if (c.isMesh && !isNode.has(c)) out.push(c);
      return out;
    };
    this.objectMeshes = objects.map((n) => own(nodeObjects[n]));
    // A GPU instance is one instance of its node's instanced meshes.
    this.objectInstance = instances;
    // Coarser levels of detail are not drawn: objects show their own level.
    this.hiddenLevels = new Set([...levels].map((n) => nodeObjects[n]));
    for (const o of this.hiddenLevels) o.visible = false;
    this.sceneRoot = gltf.scene;
  }

  /// Decimates the scene for display when it has more than `budget`
  /// triangles (`decimate.js`), says so on the page and in `state()`
  /// (`sceneTriangles`, `drawnTriangles`).
  async fitForDisplay(budget) {
    const { before, after } = await decimate(this.sceneRoot, budget, this.hiddenLevels);
    this.root.dataset.sceneTriangles = String(before);
    this.root.dataset.drawnTriangles = String(after);
    if (after < before) {
      this.root.prepend(h("p", { class: "note", id: "decimated" },
        `The scene has ${before.toLocaleString()} triangles: drawn simplified to ${after.toLocaleString()} ` +
        "for display (the placement and the impostors were made from the scene as uploaded)."));
    } else if (budget > 0 && before > budget) {
      this.root.prepend(h("p", { class: "note" }, `The scene has ${before.toLocaleString()} triangles ` +
        "and could not be simplified: the browser may draw it slowly."));
    }
  }

  /// The nodes of each impostor id: `extras.impostor` of the baked GLB,
  /// an object whose `id` is the placement id (`schemas/baked-node.schema.json`),
  /// or the bare id in files baked before it carried more.
  mapImpostors(gltf) {
    this.impostorNodes = new Map();
    gltf.scene.traverse((o) => {
      const extras = o.userData && o.userData.impostor;
      if (extras === undefined || extras === null) return;
      const id = typeof extras === "object" ? extras.id : extras;
      if (id === undefined) return;
      if (!this.impostorNodes.has(id)) this.impostorNodes.set(id, []);
      this.impostorNodes.get(id).push(o);
      o.visible = false;
    });
  }

  bindInput(signal) {
    const opts = { signal };
    this.canvas.addEventListener("keydown", (e) => { this.keys.add(e.key.toLowerCase()); e.preventDefault(); }, opts);
    this.canvas.addEventListener("keyup", (e) => this.keys.delete(e.key.toLowerCase()), opts);
    this.canvas.addEventListener("blur", () => this.keys.clear(), opts);
    let drag = null;
    this.canvas.addEventListener("mousedown", (e) => { drag = [e.clientX, e.clientY]; this.canvas.focus(); }, opts);
    window.addEventListener("mouseup", () => { drag = null; }, opts);
    window.addEventListener("mousemove", (e) => {
      if (!drag) return;
      this.yaw -= (e.clientX - drag[0]) * 0.005;
      this.pitch = Math.max(-1.55, Math.min(1.55, this.pitch - (e.clientY - drag[1]) * 0.005));
      drag = [e.clientX, e.clientY];
      if (this.walk) this.toggleWalk();
    }, opts);
  }

  /// Places the camera at `p` looking along `d` (stops a walk).
  lookFrom(p, d) {
    if (this.walk) this.toggleWalk();
    this.pos.set(...p);
    const len = Math.hypot(...d);
    this.yaw = Math.atan2(-d[0], -d[2]);
    this.pitch = Math.asin(Math.max(-1, Math.min(1, d[1] / len)));
    this.tick(0);
    return this.state();
  }

  toggleWalk() {
    if (this.walk) {
      this.walk = null;
      this.walkButton.textContent = "Walk the path";
      this.root.dataset.walking = "false";
      return;
    }
    this.walk = { ...this.path(), s: 0 };
    this.walkButton.textContent = "Stop walking";
    this.root.dataset.walking = "true";
  }

  move(dt) {
    if (this.walk) {
      const w = this.walk;
      w.s = Math.min(w.total, w.s + dt * Math.max(5, w.total / 30));
      this.poseOnPath(w, w.s);
      if (w.s >= w.total) this.toggleWalk();
      return;
    }
    const speed = (this.keys.has("shift") ? 0.25 : 0.06) * this.size * dt;
    const fwd = new THREE.Vector3(-Math.sin(this.yaw), 0, -Math.cos(this.yaw));
    const right = new THREE.Vector3(-fwd.z, 0, fwd.x);
    const k = (c) => (this.keys.has(c) ? 1 : 0);
    this.pos.addScaledVector(fwd, (k("w") - k("s")) * speed);
    this.pos.addScaledVector(right, (k("d") - k("a")) * speed);
    this.pos.y += (k("r") - k("f")) * speed;
    // The camera stays in the job's view space.
    for (const [a, c] of ["x", "y", "z"].entries()) {
      this.pos[c] = Math.max(this.vs.min[a], Math.min(this.vs.max[a], this.pos[c]));
    }
  }

  tick(dt) {
    this.move(dt);
    this.camera.position.copy(this.pos);
    this.camera.rotation.set(this.pitch, this.yaw, 0, "YXZ");
    this.camera.updateMatrixWorld();
    const d = new THREE.Vector3();
    this.camera.getWorldDirection(d);
    const cpv = findCpv(this.placement.cpvs, this.vs.max, this.pos.toArray(), d.toArray());
    if (cpv !== this.cpv) this.switchCpv(cpv);
    if (this.showCells && this.cellsFor !== this.cpv) this.drawCells();
    if (!this.showCells && this.cells.children.length) this.cells.clear();
    this.chart.push(cpv ? cpv.time_ms_original : null, cpv ? cpv.time_ms_final : null, this.target);
    this.renderer.render(this.three, this.camera);
  }

  /// Draws every object and no impostor (`on`), or the placement again.
  setPlain(on) {
    this.plain = on;
    this.switchCpv(this.cpv);
    this.root.dataset.plain = String(on);
  }

  /// Shows `cpv`'s impostors and hides the objects of their clusters
  /// (unless the scene is shown without impostors).
  switchCpv(cpv) {
    this.cpv = cpv;
    const active = cpv && !this.plain ? [...cpv.impostors].sort((a, b) => a - b) : [];
    const hidden = new Set();
    for (const i of active) for (const o of this.placement.impostors[i].objects) hidden.add(o);
    this.objectMeshes.forEach((meshes, id) => {
      const k = this.objectInstance[id];
      for (const m of meshes) {
        if (k !== null && m.isInstancedMesh) showInstance(m, k, !hidden.has(id));
        else m.layers.set(hidden.has(id) ? HIDDEN : 0);
      }
    });
    let shown = 0;
    const on = new Set(active);
    for (const [id, nodes] of this.impostorNodes) {
      for (const n of nodes) {
        n.visible = on.has(id);
        if (n.visible) shown++;
      }
    }
    this.cpvBox.clear();
    if (cpv) this.cpvBox.add(boxLines(cpv.region.min, cpv.region.max, 0xff6f00));
    const ds = this.root.dataset;
    ds.cpv = cpv ? String(cpv.id) : "";
    ds.activeImpostors = active.join(",");
    ds.hiddenObjects = [...hidden].sort((a, b) => a - b).join(",");
    ds.visibleImpostorNodes = String(shown);
    ds.frameMs = cpv ? String(cpv.time_ms_final) : "";
    ds.frameMsOriginal = cpv ? String(cpv.time_ms_original) : "";
    this.info.replaceChildren(cpv
      ? h("p", {}, `CPV ${cpv.id}: ${cpv.time_ms_original.toFixed(2)} ms without impostors, ` +
        `${cpv.time_ms_final.toFixed(2)} ms with ${active.length} impostor(s) ` +
        `(${hidden.size} objects replaced)${cpv.solved ? "" : `; unsolved: ${cpv.unsolved_reason}`}.`)
      : h("p", {}, "No CPV here: the view was proven within the target without impostors."));
  }

  drawCells() {
    this.cells.clear();
    for (const i of this.cpv ? this.cpv.impostors : []) {
      this.cells.add(viewCell(this.placement.impostors[i].view_cell, this.size, 0x00897b));
    }
    this.cellsFor = this.cpv;
  }

  /// The job's walkthrough path: its points, segment lengths and length.
  path() {
    const pts = this.walkPoints.map((p) => new THREE.Vector3(...p));
    const lengths = pts.slice(1).map((p, i) => p.distanceTo(pts[i]));
    return { pts, lengths, total: lengths.reduce((a, b) => a + b, 0) };
  }

  /// Puts the camera at arc length `s` of `path`, looking along its segment.
  poseOnPath(path, s) {
    let i = 0;
    while (i < path.lengths.length - 1 && s > path.lengths[i]) { s -= path.lengths[i]; i++; }
    const seg = path.pts[i + 1].clone().sub(path.pts[i]);
    this.pos.copy(path.pts[i]).addScaledVector(seg, path.lengths[i] > 0 ? s / path.lengths[i] : 0);
    if (path.lengths[i] > 0) {
      seg.normalize();
      this.yaw = Math.atan2(-seg.x, -seg.z);
      this.pitch = Math.asin(seg.y);
    }
  }

  /// Frame `i` of a walk of `n` frames along the job's path (frame 0 at its
  /// start, frame n − 1 at its end), drawn: its state (stops a walk).
  walkFrame(i, n) {
    if (!this.walkPoints) throw new Error("the job has no walkthrough path");
    if (this.walk) this.toggleWalk();
    const path = this.path();
    this.poseOnPath(path, n > 1 ? (path.total * i) / (n - 1) : 0);
    this.tick(0);
    return this.state();
  }

  /// The camera and the CPV shown: the #viewer element's data attributes,
  /// the position and the view direction.
  state() {
    const d = new THREE.Vector3();
    this.camera.getWorldDirection(d);
    return { ...this.root.dataset, position: this.pos.toArray(), direction: d.toArray() };
  }

  /// The world box of object `id`'s meshes: their local boxes' transformed
  /// corners, as the optimizer bounds an object (for checking the object
  /// order against the optimizer's).
  objectBox(id) {
    const box = new THREE.Box3();
    const k = this.objectInstance[id];
    for (const m of this.objectMeshes[id] || []) {
      if (k !== null && m.isInstancedMesh) {
        // The instance's own box: the geometry's, by its shown matrix.
        if (!m.geometry.boundingBox) m.geometry.computeBoundingBox();
        const matrix = new THREE.Matrix4().fromArray(instanceMatrices(m), 16 * k);
        m.updateWorldMatrix(true, false);
        box.union(m.geometry.boundingBox.clone().applyMatrix4(matrix.premultiply(m.matrixWorld)));
      } else {
        box.expandByObject(m, false);
      }
    }
    return { min: box.min.toArray(), max: box.max.toArray() };
  }

  /// The atlas textures of the baked impostors, one entry per texture:
  /// whether three.js holds it GPU-compressed (transcoded from KTX2), its
  /// size and its number of mip levels in the file (0 when the GPU makes
  /// them, as for PNG).
  textures() {
    const seen = new Map();
    for (const nodes of this.impostorNodes.values()) {
      for (const n of nodes) {
        n.traverse((o) => {
          const map = o.material && o.material.map;
          if (!map || seen.has(map.uuid)) return;
          const img = map.image || {};
          seen.set(map.uuid, {
            compressed: !!map.isCompressedTexture,
            width: img.width || 0,
            height: img.height || 0,
            mipmaps: (map.mipmaps || []).length,
          });
        });
      }
    }
    return [...seen.values()];
  }

  /// How many of the canvas's pixels are not the clear colour.
  pixels() {
    const { width, height, px } = this.readPixels();
    const clear = new THREE.Color(0xb0bec5);
    const [r, g, b] = [clear.r, clear.g, clear.b].map((c) => Math.round(c * 255));
    let drawn = 0;
    for (let i = 0; i < px.length; i += 4) {
      if (Math.abs(px[i] - r) > 2 || Math.abs(px[i + 1] - g) > 2 || Math.abs(px[i + 2] - b) > 2) drawn++;
    }
    return { width, height, drawn };
  }

  /// The impostors' coverage in the current view against their objects':
  /// the view is drawn as shown, with the CPV's replaced objects and
  /// impostors both hidden ("behind"), and as the plain scene. A pixel is
  /// covered by the impostors where the view as shown differs from behind,
  /// by the objects where the plain scene does; the footprint is the pixels
  /// covered by either and the mismatch those covered by one only (colours
  /// are not compared: the viewer's lights are not the bake's).
  footprint() {
    const cpv = this.cpv;
    const draw = () => { this.renderer.render(this.three, this.camera); return this.readPixels().px; };
    const shown = draw();
    const nodes = [...this.impostorNodes.values()].flat().filter((n) => n.visible);
    for (const n of nodes) n.visible = false;
    const behind = draw();
    for (const n of nodes) n.visible = true;
    this.switchCpv(null);
    const plain = draw();
    this.switchCpv(cpv);
    draw();
    const differs = (a, b, i) => Math.abs(a[i] - b[i]) + Math.abs(a[i + 1] - b[i + 1]) + Math.abs(a[i + 2] - b[i + 2]) > 6;
    let footprint = 0, mismatch = 0;
    for (let i = 0; i < shown.length; i += 4) {
      const imp = differs(shown, behind, i), obj = differs(plain, behind, i);
      if (imp || obj) footprint++;
      if (imp !== obj) mismatch++;
    }
    return { pixels: shown.length / 4, footprint, mismatch };
  }

  readPixels() {
    const gl = this.renderer.getContext();
    const width = gl.drawingBufferWidth, height = gl.drawingBufferHeight;
    const px = new Uint8Array(width * height * 4);
    gl.readPixels(0, 0, width, height, gl.RGBA, gl.UNSIGNED_BYTE, px);
    return { width, height, px };
  }
}
