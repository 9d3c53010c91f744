// A second independent 3D Tiles client for the tests: CesiumJS
// (`@cesium/engine`, no widgets), which implements `viewerRequestVolume`,
// loading a tileset from this page's origin and exposing
// `window.cesiumClient` for a test to drive over the DevTools protocol:
//
//   await cesiumClient.load(url, { resolution, fovDeg, tileset })
//       (re)loads the tileset at `url` (a previous one is removed with its
//       cache, so every load starts cold); all options are optional:
//       resolution [w, h] of the canvas (default [640, 360]; Cesium's
//       screen-space error uses its height), fovDeg the vertical field of
//       view (default 60), tileset extra Cesium3DTileset options (they
//       override the defaults below). Resolves to { loaded: true, tiles: n }
//   await cesiumClient.select(position, direction, up, { timeoutMs })
//       all [x, y, z] in the tileset's own (z-up) frame; places the camera
//       there and renders until the tileset has settled (no request
//       pending or processing, and the same selection three frames in a
//       row); resolves to
//         { selected: ["imp1.glb", ...], requested, loaded, failed,
//           frames, ms }
//       selected: the content URIs (relative to the tileset JSON's folder,
//       sorted) of the tiles Cesium selected in the last frame, every inner
//       content of a tile with a `contents` array; requested / loaded /
//       failed: content requests made, contents loaded, contents failed
//       since `load`; frames / ms: what settling took
//   cesiumClient.tiles()
//       every tile in pre-order (a parent before its children) with its
//       state in the last frame (see listTiles), for diagnosis
//   cesiumClient.errors
//       console errors, uncaught exceptions, render errors and tile load
//       failures, as strings
//
// Frames. The tileset has no root transform: its coordinates are a small
// local z-up frame (metres; x east, y north, z up) near (0, 0, 0), which in
// Cesium's Earth-fixed frame would be the Earth's centre, a bad place for
// its camera (and its near/far and precision logic). The tileset is
// therefore placed on the ellipsoid by `modelMatrix` (east-north-up at
// ORIGIN), and every camera position / direction / up the test gives is
// mapped by the same matrix, so the test speaks in the tileset's frame.
// Cesium applies `modelMatrix` to every tile's bounding volume, content
// bounding volume and viewerRequestVolume (Cesium3DTile's computedTransform,
// `createBoundingVolume` / `updateTransform`), so request volumes keep
// their meaning. glTF content is y-up; Cesium turns it to z-up itself
// (asset.gltfUpAxis, default "Y").
//
// Cesium's refinement as this client sees it (checked on a hand-made
// tileset): a tile outside its viewerRequestVolume is neither drawn nor
// traversed; a REPLACE parent with content refines as soon as an empty
// child is in its request volume (it does not wait for that child's
// descendants to load) and is drawn when no child is. But with the default
// `cullWithChildrenBounds: true`, a REPLACE parent whose children's boxes
// lie within its own box (Cesium3DTileOptimizations: the same centre counts
// as within) is culled when none of its children is "visible", and a child
// outside its request volume counts as not visible: the parent is then not
// drawn either. Pass `{ tileset: { cullWithChildrenBounds: false } }` to
// `load` to see the tileset without that optimization.
//
// Nothing here fetches from the network but the tileset: the Scene is made
// without a Viewer or widgets, so it has no globe, imagery, terrain, sky
// box, atmosphere, sun or moon.

import {
  Cartesian3,
  Cesium3DTileRefine,
  Cesium3DTileset,
  Color,
  Credit,
  CreditDisplay,
  Math as CesiumMath,
  Matrix4,
  PerspectiveFrustum,
  Scene,
  Transforms,
} from "@cesium/engine";

// Where the tileset's local frame is put on the ellipsoid (any place will
// do; height 0).
const ORIGIN = Cartesian3.fromDegrees(8.5, 47.0, 0.0);
const FRAME = Transforms.eastNorthUpToFixedFrame(ORIGIN);

const errors = [];

function text(x) {
  if (x instanceof Error) return x.stack ?? String(x);
  if (typeof x === "string") return x;
  try {
    return JSON.stringify(x);
  } catch {
    return String(x);
  }
}

const consoleError = console.error.bind(console);
console.error = (...args) => {
  errors.push(`console.error: ${args.map(text).join(" ")}`);
  consoleError(...args);
};
window.addEventListener("error", (e) => {
  errors.push(`uncaught: ${e.error ? text(e.error) : e.message}`);
});
window.addEventListener("unhandledrejection", (e) => {
  errors.push(`unhandled rejection: ${text(e.reason)}`);
});

// Every URL the page requests by XMLHttpRequest (Cesium's Resource loads
// tileset JSON and contents that way), to count content requests.
const requests = [];
const xhrOpen = XMLHttpRequest.prototype.open;
XMLHttpRequest.prototype.open = function (method, url, ...rest) {
  requests.push(new URL(String(url), document.baseURI).href);
  return xhrOpen.call(this, method, url, ...rest);
};

// Cesium computes the sun's direction every frame (lighting only) from the
// Earth's orientation, whose IAU 2006 XYS data it would fetch in chunks
// from CESIUM_BASE_URL/Assets/IAU2006_XYS. Without the data it uses the
// TEME approximation, as it does while a chunk loads: nothing to do with
// which tiles are drawn.
Transforms.iau2006XysData.computeXysRadians = () => undefined;

// The default credit shows Cesium ion's logo, an image Cesium would fetch
// from CESIUM_BASE_URL/Assets/Images; the page does not display credits.
CreditDisplay.cesiumCredit = new Credit("CesiumJS", false);

let scene = null;
let tileset = null;
let baseUrl = "";
let tilesetUrl = "";
let requestsAtLoad = 0;
let loaded = 0;
let failed = 0;

function makeScene([width, height], fovDeg) {
  const canvas = document.getElementById("view");
  canvas.width = width;
  canvas.height = height;
  canvas.style.width = `${width}px`;
  canvas.style.height = `${height}px`;
  scene = new Scene({
    canvas,
    creditContainer: document.getElementById("credits"),
    contextOptions: { webgl: { antialias: false } },
    msaaSamples: 1,
    scene3DOnly: true,
  });
  // Explicitly nothing that fetches or draws the Earth (a Scene made
  // without a Viewer has none of these; this says so).
  scene.globe = undefined;
  scene.skyBox = undefined;
  scene.skyAtmosphere = undefined;
  scene.sun = undefined;
  scene.moon = undefined;
  scene.fog.enabled = false;
  scene.backgroundColor = Color.fromBytes(0x20, 0x24, 0x28, 0xff);
  scene.rethrowRenderErrors = true;
  scene.renderError.addEventListener((_, e) => {
    errors.push(`render error: ${text(e)}`);
  });
  // The camera is only moved by `select`: no input, and no collision
  // detection (there is no terrain to keep it above).
  const control = scene.screenSpaceCameraController;
  control.enableInputs = false;
  control.enableCollisionDetection = false;
  // The views' camera: vertical field of view `fovDeg`, the canvas's
  // aspect, near plane 0.1 m. Cesium's `fov` is the wider angle: the
  // horizontal one when the aspect ratio is above 1.
  const aspect = width / height;
  const fovy = CesiumMath.toRadians(fovDeg);
  const fov = aspect > 1 ? 2 * Math.atan(Math.tan(fovy / 2) * aspect) : fovy;
  scene.camera.frustum = new PerspectiveFrustum({
    fov,
    aspectRatio: aspect,
    near: 0.1,
    far: 1.0e7,
  });
}

// The content URIs a tile draws: each inner content of a `contents` array
// (3D Tiles 1.1, or 3DTILES_multiple_contents), else its one content;
// resolved as Cesium resolves them and made relative to the tileset JSON's
// folder. Reads Cesium3DTile's private `_header` / `_contentResource`
// (fine for a test client: there is no public accessor for an unloaded
// tile's URIs).
function contentUris(tile) {
  const header = tile._header ?? {};
  const base = tile._contentResource?.url ?? tilesetUrl;
  let uris = [];
  const multi = header.contents ?? header.extensions?.["3DTILES_multiple_contents"]?.contents;
  if (Array.isArray(multi) && multi.length > 1) {
    uris = multi.map((c) => new URL(c.uri ?? c.url, base).href);
  } else if (tile._contentResource) {
    uris = [tile._contentResource.url];
  }
  return uris.map((u) => {
    const plain = u.split(/[?#]/)[0];
    return plain.startsWith(baseUrl) ? plain.slice(baseUrl.length) : plain;
  });
}

// The content URIs drawn in the last frame: Cesium3DTileset's private
// `_selectedTiles` (the traversal's selection; no public accessor).
function selection() {
  const out = [];
  for (const tile of tileset._selectedTiles) out.push(...contentUris(tile));
  return out.sort();
}

// Every tile, pre-order; `parent` is the parent's index in this list. The
// per-frame fields are Cesium3DTile's private traversal state: `updated`
// says whether the last frame's traversal evaluated the tile (when not,
// the other per-frame fields are stale).
function listTiles() {
  const out = [];
  if (!tileset) return out;
  const frame = scene.frameState.frameNumber;
  const visit = (tile, parent) => {
    const index = out.length;
    out.push({
      index,
      parent,
      depth: tile._depth,
      uris: contentUris(tile),
      refine: tile.refine === Cesium3DTileRefine.ADD ? "ADD" : "REPLACE",
      geometricError: tile.geometricError,
      hasRequestVolume: tile._viewerRequestVolume !== undefined,
      updated: tile._updatedVisibilityFrame === tileset._updatedVisibilityFrame,
      // In the frustum (and not culled by its children's bounds).
      visible: Boolean(tile._visible),
      inRequestVolume: Boolean(tile._inRequestVolume),
      screenSpaceError: tile._screenSpaceError,
      refines: Boolean(tile._refines),
      visited: tile._visitedFrame === frame,
      selected: tile._selectedFrame === frame,
      contentReady: tile.contentReady,
      contentFailed: tile.contentFailed,
    });
    for (const child of tile.children) visit(child, index);
  };
  visit(tileset.root, null);
  return out;
}

function counts() {
  const content = requests
    .slice(requestsAtLoad)
    .filter((u) => u.startsWith(baseUrl) && !u.split(/[?#]/)[0].endsWith(".json"));
  return { requested: content.length, loaded, failed };
}

const nextTask = () => new Promise((r) => setTimeout(r, 0));

function local(v, point) {
  const c = new Cartesian3(v[0], v[1], v[2]);
  return point
    ? Matrix4.multiplyByPoint(FRAME, c, new Cartesian3())
    : Matrix4.multiplyByPointAsVector(FRAME, c, new Cartesian3());
}

window.cesiumClient = {
  errors,

  async load(url, { resolution = [640, 360], fovDeg = 60, tileset: options = {} } = {}) {
    if (!scene) makeScene(resolution, fovDeg);
    if (tileset) {
      scene.primitives.remove(tileset); // destroys it and its contents
      tileset = null;
    }
    tilesetUrl = new URL(url, document.baseURI).href;
    baseUrl = new URL("./", tilesetUrl).href;
    requestsAtLoad = requests.length;
    loaded = 0;
    failed = 0;
    try {
      tileset = await Cesium3DTileset.fromUrl(tilesetUrl, {
        maximumScreenSpaceError: 16,
        modelMatrix: FRAME,
        // Deterministic refinement by screen-space error alone: no lower
        // detail far off near the horizon or in the periphery (both on by
        // default), no image-based lighting pass (nothing to do with which
        // tiles are drawn).
        dynamicScreenSpaceError: false,
        foveatedScreenSpaceError: false,
        environmentMapOptions: { enabled: false },
        ...options,
      });
    } catch (e) {
      errors.push(`tileset ${url}: ${text(e)}`);
      throw e;
    }
    tileset.tileLoad.addEventListener(() => {
      loaded += 1;
    });
    tileset.tileFailed.addEventListener((e) => {
      failed += 1;
      errors.push(`tile failed: ${e.url}: ${e.message}`);
    });
    scene.primitives.add(tileset);
    return { loaded: true, tiles: listTiles().length };
  },

  async select(position, direction, up = [0, 0, 1], { timeoutMs = 60000 } = {}) {
    if (!tileset) throw new Error("cesiumClient.select: no tileset loaded");
    const d = Cartesian3.normalize(local(direction, false), new Cartesian3());
    const across = Cartesian3.cross(d, local(up, false), new Cartesian3());
    if (!(Cartesian3.magnitude(across) > 1e-9)) {
      throw new Error(`cesiumClient.select: direction ${direction} is along up ${up}`);
    }
    const right = Cartesian3.normalize(across, new Cartesian3());
    const u = Cartesian3.cross(right, d, new Cartesian3());
    scene.camera.setView({
      destination: local(position, true),
      orientation: { direction: d, up: u },
    });
    const start = performance.now();
    let last = null;
    let same = 0;
    let frames = 0;
    for (;;) {
      scene.render();
      frames += 1;
      const now = selection().join("\n");
      same = tileset.tilesLoaded && now === last ? same + 1 : 0;
      last = now;
      if (same >= 2) break; // three frames in a row
      if (performance.now() - start > timeoutMs) {
        const s = tileset.statistics;
        throw new Error(
          `cesiumClient.select: not settled within ${timeoutMs} ms (pending ${s.numberOfPendingRequests}, ` +
            `processing ${s.numberOfTilesProcessing}; selected ${JSON.stringify(selection())})`,
        );
      }
      await nextTask();
    }
    return {
      selected: selection(),
      ...counts(),
      frames,
      ms: Math.round(performance.now() - start),
    };
  },

  tiles: listTiles,
};
