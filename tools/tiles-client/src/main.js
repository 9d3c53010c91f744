// An independent 3D Tiles client for the tests: NASA-AMMOS's
// 3d-tiles-renderer (`TilesRenderer`) on a three.js WebGLRenderer, loading a
// tileset from this page's origin and exposing `window.tilesClient` for the
// test to drive over the DevTools protocol (server/tests/tiles_client.rs):
//
//   await tilesClient.load(url, { fovDeg, resolution: [w, h] })
//       the tileset at `url`, seen by a camera with that vertical field of
//       view, its screen-space errors computed for that resolution (the
//       job's camera, which the export chose its geometric errors for);
//       resolves once the root tileset is parsed (or failed to load)
//   tilesClient.placeCamera(position, lookAt)
//   tilesClient.setErrorTarget(px)
//       the screen-space error above which a tile refines (the
//       renderer's `errorTarget`, 16 px by default, as CesiumJS's)
//   await tilesClient.settle()
//       updates and renders until no tile is queued, downloading or parsing
//       and three updates in a row leave every tile's state unchanged
//   tilesClient.state()
//       { tiles: [...], errors: [...], stats, camera } (below)
//   tilesClient.pixels()
//       { width, height, drawn }: pixels of a fresh render that are not
//       the clear colour
//
// Frames. 3D Tiles is z-up and glTF content y-up: TilesRenderer turns each
// glTF content by +90° about x into the tileset's z-up frame, `(x, y, z) ↦
// (x, −z, y)` (its `_upRotationMatrix`, from `asset.gltfUpAxis`, default
// "y"), where the tileset's bounding volumes live. The group holding the
// tiles is turned back by −90° about x, so three.js's world frame is the
// glTF frame again: the frame of the scene file, the job and the placement.
// Camera positions and targets are given in that frame, y up, exactly as
// the placement's CPV regions and view cells are written.
//
// Nothing here knows about impostors: the test reads a tile's role from its
// content URI and `extras`, which the client reports as the tileset has them.

import {
  AmbientLight,
  Color,
  DirectionalLight,
  PerspectiveCamera,
  Scene,
  WebGLRenderer,
} from "three";
import { FAILED, LOADED, TilesRenderer } from "3d-tiles-renderer";

const canvas = document.getElementById("view");
const renderer = new WebGLRenderer({ canvas, antialias: false });
renderer.setPixelRatio(1);
const scene = new Scene();
const CLEAR = [0x20, 0x24, 0x28];
scene.background = new Color(`rgb(${CLEAR.join(",")})`);
scene.add(new AmbientLight(0xffffff, 1.5));
const sun = new DirectionalLight(0xffffff, 2.0);
sun.position.set(0.3, 1, 0.5);
scene.add(sun);
const camera = new PerspectiveCamera(45, 1, 0.1, 100000);

let tiles = null;
const errors = [];
let loadedModels = 0;

// One update of the tiles for the current camera. Rendering is left to
// `settle`'s end and `pixels`: the traversal does not depend on it, and
// software WebGL (SwiftShader) would slow every update down.
function step() {
  scene.updateMatrixWorld();
  camera.updateMatrixWorld();
  tiles.update();
}

function rootDone() {
  return tiles.rootLoadingState === LOADED || tiles.rootLoadingState === FAILED;
}

function busy() {
  const s = tiles.stats;
  return (
    !rootDone() ||
    s.queued + s.downloading + s.parsing > 0 ||
    tiles.downloadQueue.running ||
    tiles.parseQueue.running ||
    tiles.processNodeQueue.running
  );
}

// Every tile of the parsed hierarchy, in pre-order (a parent before its
// children); `parent` is the parent's index in this list.
function listTiles() {
  const out = [];
  const index = new Map();
  if (!tiles || !tiles.root) return out;
  tiles.traverse((tile) => {
    index.set(tile, out.length);
    const t = tile.traversal;
    const content = tile.engineData.scene;
    let meshes = 0;
    if (content && tiles.visibleTiles.has(tile)) {
      content.traverse((o) => {
        if (o.isMesh) meshes += 1;
      });
    }
    out.push({
      index: out.length,
      parent: tile.parent ? index.get(tile.parent) : null,
      depth: tile.internal.depth,
      uri: tile.content?.uri ?? null,
      refine: tile.refine,
      geometricError: tile.geometricError,
      hasRequestVolume: "viewerRequestVolume" in tile,
      extras: tile.extras ?? null,
      // The content is parsed and held (it may still be undrawn).
      loaded: tile.internal.loadingState === LOADED,
      failed: tile.internal.loadingState === FAILED,
      // The last update's traversal: whether it reset the tile's state
      // (it does for the tiles it reaches and the children of the tiles
      // it uses; the other fields of a tile it did not reset are stale),
      // its bounding volume in the frustum (false where the traversal did
      // not test it, e.g. below a tile that did not refine), its
      // screen-space error, in the set the renderer displays (`active`)
      // and drawn (`visible`: active, in the frustum and loaded, its scene
      // added to the tiles' group).
      visited: t.lastFrameVisited === tiles.frameCount,
      inFrustum: t.lastFrameVisited === tiles.frameCount && Boolean(t.inFrustum),
      error: t.lastFrameVisited === tiles.frameCount && Number.isFinite(t.error) ? t.error : null,
      active: tiles.activeTiles.has(tile),
      visible: tiles.visibleTiles.has(tile),
      drawnMeshes: meshes,
    });
    return false;
  });
  return out;
}

function signature() {
  return listTiles()
    .map((t) => `${t.loaded ? 1 : 0}${t.active ? 1 : 0}${t.visible ? 1 : 0}`)
    .join("");
}

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

window.tilesClient = {
  async load(url, { fovDeg = 45, resolution = [512, 512] } = {}) {
    if (tiles) throw new Error("tilesClient.load: a tileset is loaded already");
    const [w, h] = resolution;
    // The canvas keeps the camera's aspect at a modest size; the error
    // computation uses the job's resolution.
    const scale = Math.min(1, 512 / Math.max(w, h));
    renderer.setSize(Math.round(w * scale), Math.round(h * scale));
    camera.fov = fovDeg;
    camera.aspect = w / h;
    camera.updateProjectionMatrix();
    tiles = new TilesRenderer(url);
    // No cache limit: a tileset whose switch leaves name the same contents
    // many times holds more tiles than the default cache (8,000 tiles,
    // 0.4 GB), and the tests look at every tile at once.
    const cache = tiles.lruCache;
    cache.minSize = cache.maxSize = Infinity;
    cache.minBytesSize = cache.maxBytesSize = Infinity;
    tiles.addEventListener("load-error", (e) => {
      errors.push({ url: e.url ?? null, message: String(e.error?.message ?? e.error) });
    });
    tiles.addEventListener("load-model", () => {
      loadedModels += 1;
    });
    tiles.group.rotation.x = -Math.PI / 2;
    scene.add(tiles.group);
    tiles.setCamera(camera);
    tiles.setResolution(camera, w, h);
    const start = performance.now();
    while (!rootDone()) {
      step();
      if (performance.now() - start > 30000) {
        throw new Error(`tilesClient.load: ${url} not loaded within 30 s`);
      }
      await sleep(10);
    }
    return { loaded: tiles.rootLoadingState === LOADED, errors: [...errors] };
  },

  setErrorTarget(px) {
    if (!tiles) throw new Error("tilesClient.setErrorTarget: no tileset is loaded");
    tiles.errorTarget = px;
    return tiles.errorTarget;
  },

  placeCamera(position, lookAt) {
    camera.position.set(...position);
    camera.up.set(0, 1, 0);
    camera.lookAt(...lookAt);
    camera.updateMatrixWorld();
    return true;
  },

  async settle(timeoutMs = 60000) {
    const start = performance.now();
    let last = "";
    let quiet = 0;
    let updates = 0;
    for (;;) {
      step();
      updates += 1;
      const sig = signature();
      quiet = !busy() && sig === last ? quiet + 1 : 0;
      last = sig;
      if (quiet >= 3) {
        // Drawn once: textures are uploaded and shaders compiled, so their
        // errors reach the console.
        renderer.render(scene, camera);
        return { updates, ms: Math.round(performance.now() - start) };
      }
      if (performance.now() - start > timeoutMs) {
        throw new Error(
          `tilesClient.settle: still busy after ${timeoutMs} ms (${JSON.stringify(tiles.stats)})`,
        );
      }
      await sleep(10);
    }
  },

  state() {
    const s = tiles ? tiles.stats : {};
    return {
      tiles: listTiles(),
      errors: [...errors],
      loadedModels,
      stats: {
        queued: s.queued,
        downloading: s.downloading,
        parsing: s.parsing,
        loaded: s.loaded,
        failed: s.failed,
        inFrustum: s.inFrustum,
        used: s.used,
        active: s.active,
        visible: s.visible,
      },
      camera: {
        position: camera.position.toArray(),
        fovDeg: camera.fov,
        errorTarget: tiles ? tiles.errorTarget : null,
      },
    };
  },

  pixels() {
    renderer.render(scene, camera);
    const gl = renderer.getContext();
    const w = gl.drawingBufferWidth;
    const h = gl.drawingBufferHeight;
    const px = new Uint8Array(w * h * 4);
    gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, px);
    const clear = CLEAR;
    let drawn = 0;
    for (let i = 0; i < px.length; i += 4) {
      const d =
        Math.abs(px[i] - clear[0]) + Math.abs(px[i + 1] - clear[1]) + Math.abs(px[i + 2] - clear[2]);
      if (d > 6) drawn += 1;
    }
    return { width: w, height: h, drawn };
  },
};
