//! The 3D Tiles export of the tenth-scale city in an independent 3D Tiles
//! client: NASA-AMMOS's `3d-tiles-renderer` on three.js
//! (`tools/tiles-client`, bundled by esbuild), in headless Chromium.
//!
//! The city is placed, baked and exported with the library calls of
//! `impostor place`, `impostor bake` and `impostor tiles`; a small static
//! server on a loopback port serves the client's page and the tileset from
//! one origin. The client must load the tileset without a load error or a
//! console error, and its parsed hierarchy must have one tile per impostor
//! plus the base scene's tiles: the root (the objects no impostor replaces)
//! and one tile per cluster group (the geometry of impostors sharing
//! objects), the groups counted here from the placement alone.
//!
//! What it then draws is checked from three viewpoints (camera positions in
//! the placement's y-up frame; the client turns the z-up tileset back):
//! from above the whole city, where every content loads; inside a CPV, where
//! its impostors are drawn instead of their group's geometry; and far
//! outside the view space, where a group's geometry is drawn and none of
//! its impostors. 3d-tiles-renderer (0.5.3) does not implement
//! `viewerRequestVolume` (NASA-AMMOS/3DTilesRendererJS#74): it refines by
//! screen-space error alone, so inside the view space it also draws the
//! impostors whose view cells do not hold the viewer. The test asserts that
//! as what this client does (see `optimizer/src/export/tiles.rs`).

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use serde_json::{Value, json};

mod common;

use common::browser::Browser;
use optimizer::api::job::Job;
use optimizer::api::placement::{PlacedCpv, Placement};

/// An empty folder for this test.
fn fresh(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "impostor-tiles-client-{name}-{}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Builds the client `tools/NAME` (its `build.mjs`) into `out`, so the
/// page served is never older than its sources; `package` is the npm
/// package it is built on.
fn build_client(name: &str, package: &str, out: &Path) {
    let tool = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../tools")
        .join(name);
    assert!(
        tool.join("node_modules").join(package).is_dir(),
        "the 3D Tiles client {name} is not installed: run `npm ci --prefix tools/{name}` \
         (tools/test.sh does)"
    );
    let o = Command::new("node")
        .arg(tool.join("build.mjs"))
        .arg(out)
        .output()
        .expect("run node");
    assert!(
        o.status.success(),
        "node tools/{name}/build.mjs: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

/// The media type of a served file.
fn content_type(name: &str) -> &'static str {
    match name.rsplit_once('.').map(|(_, e)| e) {
        Some("html") => "text/html; charset=utf-8",
        Some("js") => "text/javascript; charset=utf-8",
        Some("json") => "application/json",
        Some("glb") => "model/gltf-binary",
        _ => "application/octet-stream",
    }
}

/// Answers one request: `/` (its `index.html`) and `/NAME` from
/// `client`, `/tiles/NAME` from `tiles`; plain names only.
fn answer(mut s: TcpStream, client: &Path, tiles: &Path) {
    let mut line = String::new();
    let mut r = BufReader::new(s.try_clone().unwrap());
    if r.read_line(&mut line).is_err() {
        return;
    }
    // The rest of the head.
    loop {
        let mut h = String::new();
        match r.read_line(&mut h) {
            Ok(0) | Err(_) => break,
            Ok(_) if h == "\r\n" || h == "\n" => break,
            Ok(_) => {}
        }
    }
    let mut parts = line.split_whitespace();
    let (method, target) = (parts.next().unwrap_or(""), parts.next().unwrap_or(""));
    let path = target.split(['?', '#']).next().unwrap_or("");
    let plain = |n: &str| {
        !n.is_empty()
            && !n.starts_with('.')
            && n.chars()
                .all(|c| c.is_ascii_alphanumeric() || "._-".contains(c))
    };
    let file = match path {
        "/" => Some(client.join("index.html")),
        p => match p.strip_prefix("/tiles/") {
            Some(n) => Some(n).filter(|n| plain(n)).map(|n| tiles.join(n)),
            None => p
                .strip_prefix('/')
                .filter(|n| plain(n))
                .map(|n| client.join(n)),
        },
    };
    let body = match (method, &file) {
        ("GET", Some(f)) => std::fs::read(f).ok(),
        _ => None,
    };
    let head = match &body {
        Some(b) => format!(
            "HTTP/1.1 200 OK\r\nContent-Type: {}\r\nContent-Length: {}\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n",
            content_type(&file.as_ref().unwrap().to_string_lossy()),
            b.len()
        ),
        None => "HTTP/1.1 404 Not Found\r\nContent-Type: text/plain\r\nContent-Length: 9\r\nConnection: close\r\n\r\nnot found"
            .to_string(),
    };
    let _ = s.write_all(head.as_bytes());
    if let Some(b) = body {
        let _ = s.write_all(&b);
    }
    let _ = s.flush();
}

/// Serves `client` and `tiles` on a free loopback port (a thread per
/// connection, for as long as the test runs).
fn serve(client: PathBuf, tiles: PathBuf) -> SocketAddr {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    std::thread::spawn(move || {
        for s in listener.incoming().flatten() {
            let (c, t) = (client.clone(), tiles.clone());
            std::thread::spawn(move || answer(s, &c, &t));
        }
    });
    addr
}

/// The placement of the small city's job, its baked impostors and its
/// tileset files, made as `impostor place`, `bake` and `tiles` make them.
fn export(glb: &[u8], job: &Job) -> (Placement, Vec<(String, Vec<u8>)>) {
    use optimizer::bake::{self, BakeOptions};
    use optimizer::export::tiles::{self, TilesInput};
    use optimizer::input::{GeometryUse, Load, SceneInput, Source};
    let load = Load::new(
        Source::Bytes {
            bytes: glb,
            name: "city",
        },
        GeometryUse::WhenNeeded,
    );
    let input = SceneInput::load(&load, job, "job").unwrap();
    let placement = input
        .prepare(job, "job")
        .unwrap()
        .place(&Default::default(), &Default::default())
        .unwrap()
        .placement;
    let scene = optimizer::scene::gltf_load::load_scene_bytes(glb, "city").unwrap();
    let geom = optimizer::scene::geometry::load_geometry_bytes(glb, "city").unwrap();
    let (baked, _) = bake::bake(
        &scene,
        &geom,
        &job.memory,
        Some(&job.view_space),
        &placement,
        &BakeOptions::for_memory(&job.memory),
        "placement",
    )
    .unwrap();
    let files = tiles::export(
        &scene,
        &geom,
        &TilesInput {
            job,
            placement: &placement,
            placement_source: "placement",
            baked: &baked,
            baked_source: "impostors.glb",
        },
    )
    .unwrap();
    (placement, files)
}

/// The small city's job, placement and tileset (written to `tiles_dir`).
struct SmallCity {
    glb: Vec<u8>,
    job: Job,
    placement: Placement,
    files: Vec<(String, Vec<u8>)>,
    tileset: Value,
    tiles_dir: PathBuf,
}

/// Places, bakes and exports the small city's job into `dir/tiles`.
fn small_city(dir: &Path) -> SmallCity {
    let glb = common::city(0.1);
    let job_json = common::process::small_job();
    let job = Job::from_json(job_json.to_string().as_bytes(), "job").unwrap();
    let (placement, files) = export(&glb, &job);
    let tiles_dir = dir.join("tiles");
    std::fs::create_dir_all(&tiles_dir).unwrap();
    for (name, bytes) in &files {
        std::fs::write(tiles_dir.join(name), bytes).unwrap();
    }
    let tileset: Value = serde_json::from_slice(&files[0].1).unwrap();
    SmallCity {
        glb,
        job,
        placement,
        files,
        tileset,
        tiles_dir,
    }
}

/// The cluster groups of a placement, counted independently of the export:
/// the connected components of "two impostors share an object"; per
/// impostor its component's representative.
fn groups(p: &Placement) -> Vec<usize> {
    fn find(parent: &mut [usize], mut x: usize) -> usize {
        while parent[x] != x {
            x = parent[x];
        }
        x
    }
    let mut parent: Vec<usize> = (0..p.impostors.len()).collect();
    let mut owner: BTreeMap<u32, usize> = BTreeMap::new();
    for (i, imp) in p.impostors.iter().enumerate() {
        for &o in &imp.objects {
            let j = *owner.entry(o).or_insert(i);
            let (a, b) = (find(&mut parent, i), find(&mut parent, j));
            parent[a.max(b)] = a.min(b);
        }
    }
    (0..parent.len()).map(|i| find(&mut parent, i)).collect()
}

/// A camera position and a point it looks at, y-up.
type View = ([f64; 3], [f64; 3]);

/// A view in `cpv` seeing what its impostors stand for: its region's
/// centre, looking along a direction of its VDI whose component across is
/// its interval's middle and whose component up or down is the one of its
/// interval nearest the horizon (1 % of the interval inside it). At the
/// VDI's centre a CPV of views pitched down sees only the ground near the
/// viewer: its impostors were chosen for the views of the VDI that see the
/// city. `None` for a CPV of views up or down (a face of the y axis).
fn view_in(cpv: &PlacedCpv) -> Option<View> {
    let r = &cpv.region;
    let p: [f64; 3] = std::array::from_fn(|a| (r.min[a] + r.max[a]) / 2.0);
    let dirs = &cpv.directions;
    let axis = usize::from(dirs.face / 2);
    if axis == 1 {
        return None;
    }
    let mut d = [0.0; 3];
    d[axis] = if dirs.face.is_multiple_of(2) {
        1.0
    } else {
        -1.0
    };
    // The other two axes in order: y is u on the x faces, v on the z faces.
    let others: Vec<usize> = (0..3).filter(|&a| a != axis).collect();
    for (k, [lo, hi]) in [dirs.u, dirs.v].into_iter().enumerate() {
        let inset = 0.01 * (hi - lo);
        d[others[k]] = if others[k] == 1 {
            0.0_f64.clamp(lo + inset, hi - inset)
        } else {
            (lo + hi) / 2.0
        };
    }
    Some((p, std::array::from_fn(|a| p[a] + d[a])))
}

/// A 3D Tiles box (axis-aligned, as the export writes them) as its (min,
/// max) corners, z-up.
fn corners(volume: &Value) -> ([f64; 3], [f64; 3]) {
    let b: Vec<f64> = volume["box"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    let h = [b[3].abs(), b[7].abs(), b[11].abs()];
    (
        std::array::from_fn(|a| b[a] - h[a]),
        std::array::from_fn(|a| b[a] + h[a]),
    )
}

/// A y-up point in the tileset's z-up frame.
fn z_up(p: [f64; 3]) -> [f64; 3] {
    [p[0], -p[2], p[1]]
}

fn inside((lo, hi): ([f64; 3], [f64; 3]), p: [f64; 3]) -> bool {
    (0..3).all(|a| lo[a] <= p[a] && p[a] <= hi[a])
}

/// A tile of the client's parsed hierarchy and its state after the last
/// update.
#[derive(Debug)]
struct ClientTile {
    parent: Option<usize>,
    depth: u64,
    uri: Option<String>,
    refine: String,
    impostor: Option<usize>,
    loaded: bool,
    visited: bool,
    in_frustum: bool,
    /// The screen-space error of the last update (where it reached the tile).
    error: Option<f64>,
    active: bool,
    visible: bool,
}

fn client_tiles(state: &Value) -> Vec<ClientTile> {
    state["tiles"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| ClientTile {
            parent: t["parent"].as_u64().map(|p| p as usize),
            depth: t["depth"].as_u64().unwrap(),
            uri: t["uri"].as_str().map(str::to_string),
            refine: t["refine"].as_str().unwrap().to_string(),
            impostor: t["extras"]["impostor"].as_u64().map(|i| i as usize),
            loaded: t["loaded"] == true,
            error: t["error"].as_f64(),
            visited: t["visited"] == true,
            in_frustum: t["inFrustum"] == true,
            active: t["active"] == true,
            visible: t["visible"] == true,
        })
        .collect()
}

/// The value of the promise `expr`, awaited in turns of less than the
/// bridge's 60 s limit for one evaluation (settling a busy client may take
/// longer; its own time limit ends it).
fn settled(b: &mut Browser, expr: &str) -> Value {
    b.eval(&format!(
        "window.settled = undefined; ({expr}).then(v => window.settled = {{v}}, \
         e => window.settled = {{e: String(e && e.stack || e)}}); true"
    ));
    let r = b.wait_for("window.settled", Duration::from_secs(420), expr);
    if let Some(e) = r.get("e") {
        panic!("{expr} threw: {e}\npage problems: {:?}", b.problems());
    }
    r["v"].clone()
}

/// One browser at a time: the two clients settle within their limits on
/// two cores only when they do not share them.
static ONE_BROWSER: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Places the client's camera, lets it settle and returns its state.
fn look(b: &mut Browser, from: [f64; 3], at: [f64; 3]) -> Value {
    b.eval(&format!("tilesClient.placeCamera({from:?}, {at:?})"));
    // A busy machine (two cores shared with other work) may take minutes.
    settled(b, "tilesClient.settle(360000)");
    let state = b.eval("tilesClient.state()");
    let errors = &state["errors"];
    assert_eq!(errors, &json!([]), "load errors from {from:?}");
    state
}

#[test]
fn the_small_citys_tileset_loads_and_refines_in_3d_tiles_renderer() {
    let _one = ONE_BROWSER.lock().unwrap_or_else(|e| e.into_inner());
    let Some(mut b) = Browser::start() else {
        return;
    };
    let dir = fresh("city");
    let client = dir.join("client");
    build_client("tiles-client", "3d-tiles-renderer", &client);
    let SmallCity {
        job,
        placement,
        files,
        tileset,
        tiles_dir,
        ..
    } = small_city(&dir);
    let n = placement.impostors.len();
    assert!(n > 0, "the small city has impostors");
    let group_of = groups(&placement);
    let mut reps = group_of.clone();
    reps.sort_unstable();
    reps.dedup();
    let group_count = reps.len();

    let addr = serve(client, tiles_dir);
    b.navigate(&format!("http://{addr}/"));
    b.wait_for(
        "!!window.tilesClient",
        Duration::from_secs(30),
        "the client page",
    );
    let loaded = b.eval(&format!(
        "tilesClient.load('tiles/tileset.json', {{fovDeg: {}, resolution: {:?}}})",
        job.camera.fov_deg, job.camera.resolution
    ));
    assert_eq!(loaded["loaded"], true, "{loaded}");

    // 1. The whole city from above the view space's centre, high enough
    // to see all of it: every content loads and parses. A cluster tile
    // refines within twice the diagonal of what it reaches, which from
    // that height a small cluster whose CPVs lie near it may not be; there
    // the error target is lowered below the smallest cluster tile's
    // screen-space error, so that every tile refines (and restored after).
    let (lo, hi) = (job.view_space.min, job.view_space.max);
    let centre: [f64; 3] = std::array::from_fn(|a| (lo[a] + hi[a]) / 2.0);
    let half_fov = (job.camera.fov_deg / 2.0).to_radians();
    let extent = (hi[0] - lo[0]).max(hi[2] - lo[2]) / 2.0;
    let above = [centre[0], hi[1] + 1.1 * extent / half_fov.tan(), centre[2]];
    let at = [centre[0], 0.0, centre[2] + 1e-3];
    let mut state = look(&mut b, above, at);
    let default_target = state["camera"]["errorTarget"].as_f64().unwrap();
    let first = client_tiles(&state);
    let mut cluster_errors = Vec::new();
    for t in first.iter().filter(|t| t.depth == 1) {
        assert!(t.in_frustum, "{:?} out of view from above", t.uri);
        cluster_errors.push(t.error.expect("a cluster tile in view has an error"));
    }
    let smallest = cluster_errors.iter().copied().fold(f64::INFINITY, f64::min);
    if smallest <= default_target {
        let target = 0.9 * smallest;
        b.eval(&format!("tilesClient.setErrorTarget({target})"));
        state = look(&mut b, above, at);
    }
    let tiles = client_tiles(&state);

    // The client's hierarchy is the tileset's, tile for tile in pre-order
    // (the same contents): the root, one cluster tile per group of the
    // placement, below each its switch, and every impostor a CPV draws
    // under its own group's cluster tile.
    let json_tiles = flatten(&tileset);
    assert_eq!(tiles.len(), json_tiles.len(), "tiles parsed");
    for (k, t) in tiles.iter().enumerate() {
        assert_eq!(
            t.uri.as_deref(),
            json_tiles[k]["content"]["uri"].as_str(),
            "tile {k}"
        );
    }
    let root = &tiles[0];
    assert_eq!((root.parent, root.depth), (None, 0));
    assert_eq!(root.uri.as_deref(), Some("scene.glb"));
    assert_eq!(root.refine, "ADD");
    let cluster_tiles: Vec<usize> = (0..tiles.len()).filter(|&k| tiles[k].depth == 1).collect();
    assert_eq!(cluster_tiles.len(), group_count, "cluster tiles");
    for &k in &cluster_tiles {
        assert!(tiles[k].uri.as_deref().unwrap().starts_with("cluster-"));
        assert_eq!(tiles[k].refine, "REPLACE");
    }
    let group_tile = |k: usize| {
        let mut k = k;
        while tiles[k].depth > 1 {
            k = tiles[k].parent.unwrap();
        }
        k
    };
    let mut tiles_of = vec![Vec::new(); n];
    let mut rep_of_group_tile = BTreeMap::new();
    for (k, t) in tiles.iter().enumerate() {
        let Some(uri) = t.uri.as_deref().filter(|u| u.starts_with("impostor-")) else {
            continue;
        };
        let id = t.impostor.expect("an impostor tile names its impostor");
        assert_eq!(uri, format!("impostor-{id}.glb"));
        tiles_of[id].push(k);
        let rep = *rep_of_group_tile
            .entry(group_tile(k))
            .or_insert(group_of[id]);
        assert_eq!(
            rep, group_of[id],
            "impostor {id} under another group's tile"
        );
    }
    let drawn_somewhere: Vec<bool> = (0..n)
        .map(|i| {
            placement
                .cpvs
                .iter()
                .any(|c| c.impostors.contains(&(i as u32)))
        })
        .collect();
    // An impostor a CPV draws is left out only where, in every region
    // drawing it, a CPV of the same region draws one replacing at least as
    // many of its objects (a runtime knows the viewer's position, not its
    // direction: the export draws the larger).
    let mut left_out = 0;
    for id in 0..n {
        if !drawn_somewhere[id] {
            assert!(tiles_of[id].is_empty(), "impostor {id} drawn by no CPV");
            continue;
        }
        if !tiles_of[id].is_empty() {
            continue;
        }
        left_out += 1;
        let own = &placement.impostors[id].objects;
        for c in placement
            .cpvs
            .iter()
            .filter(|c| c.impostors.contains(&(id as u32)))
        {
            let covered = placement
                .cpvs
                .iter()
                .filter(|d| d.region == c.region)
                .any(|d| {
                    d.impostors.iter().any(|&j| {
                        let other = &placement.impostors[j as usize].objects;
                        j as usize != id
                            && other.len() >= own.len()
                            && other.iter().any(|o| own.contains(o))
                    })
                });
            assert!(covered, "impostor {id} of CPV {} is in no tile", c.id);
        }
    }
    assert!(left_out * 10 < n, "{left_out} of {n} impostors left out");
    // Everything loaded, nothing failed, and the canvas shows the city.
    // Every content file loads and parses (each by at least one of the
    // tiles naming it).
    let mut loaded_uris: BTreeMap<&str, bool> = BTreeMap::new();
    for t in &tiles {
        if let Some(u) = t.uri.as_deref() {
            *loaded_uris.entry(u).or_default() |= t.loaded;
        }
    }
    let unloaded: Vec<&&str> = loaded_uris
        .iter()
        .filter(|(_, l)| !**l)
        .map(|(u, _)| u)
        .collect();
    assert!(unloaded.is_empty(), "not loaded from above: {unloaded:?}");
    assert_eq!(loaded_uris.len(), files.len() - 1, "content files");
    let loaded_tiles = tiles.iter().filter(|t| t.uri.is_some() && t.loaded).count();
    assert_eq!(state["loadedModels"], json!(loaded_tiles));
    let pixels = b.eval("tilesClient.pixels()");
    let total = pixels["width"].as_u64().unwrap() * pixels["height"].as_u64().unwrap();
    let drawn = pixels["drawn"].as_u64().unwrap();
    assert!(drawn * 10 > total, "only {drawn} of {total} pixels drawn");

    b.eval(&format!("tilesClient.setErrorTarget({default_target})"));

    // 2. Inside the first CPV with impostors (`view_in`): the CPV's
    // impostors in view are drawn and their groups' geometry is not.
    let (cpv, (from, at)) = placement
        .cpvs
        .iter()
        .filter(|c| !c.impostors.is_empty())
        .find_map(|c| view_in(c).map(|v| (c, v)))
        .expect("a CPV with impostors");
    state = look(&mut b, from, at);
    let tiles = client_tiles(&state);
    assert!(tiles[0].visible, "the root's objects are drawn");
    // The request volume of the switch leaf above a tile.
    let leaf_volume =
        |k: usize| corners(&json_tiles[tiles[k].parent.unwrap()]["viewerRequestVolume"]);
    let mut shown = 0;
    for &id in &cpv.impostors {
        let id = id as usize;
        let g = &tiles[group_tile(tiles_of[id][0])];
        // The root refines, so every group tile's state is this update's;
        // one out of view is not drawn, nor its impostors.
        assert!(g.visited, "impostor {id}'s group tile is stale: {g:?}");
        let drawn: Vec<&ClientTile> = tiles_of[id]
            .iter()
            .map(|&k| &tiles[k])
            .filter(|t| t.visible)
            .collect();
        if !g.in_frustum {
            assert!(
                drawn.is_empty() && !g.visible,
                "impostor {id} drawn out of view"
            );
            continue;
        }
        // In view and near: the group refines, its geometry is not drawn
        // (REPLACE), and the impostor is drawn where in view.
        assert!(
            !g.visible && !g.active,
            "impostor {id}'s group geometry drawn too: {g:?}"
        );
        let holding = tiles_of[id]
            .iter()
            .find(|&&k| inside(leaf_volume(k), z_up(from)))
            .unwrap_or_else(|| panic!("no leaf drawing impostor {id} holds the viewer"));
        let t = &tiles[*holding];
        if t.in_frustum {
            shown += 1;
            assert!(
                t.loaded && t.active && t.visible,
                "impostor {id} of CPV {} in view but not drawn: {t:?}",
                cpv.id
            );
        }
    }
    assert!(shown > 0, "none of CPV {}'s impostors is in view", cpv.id);
    // Request volumes are ignored: the contents of the switch leaves that
    // do not hold the viewer are drawn as well when in view.
    let outside_drawn = (0..tiles.len())
        .filter(|&k| tiles[k].depth > 1 && tiles[k].uri.is_some() && tiles[k].visible)
        .filter(|&k| !inside(leaf_volume(k), z_up(from)))
        .count();
    assert!(
        outside_drawn > 0,
        "no content outside its request volume was drawn: the check saw nothing"
    );

    // 3. Far outside the view space, looking at the listed impostor's group
    // from a distance where its cluster tile no longer refines (its
    // screen-space error two thirds of the limit) while the root still
    // does: the group's geometry is drawn, none of its impostors.
    // Of the CPV's drawn impostors, the first whose group is small enough
    // against the root for such a distance to exist.
    let k = f64::from(job.camera.resolution[1]) / (2.0 * half_fov.tan());
    let limit = state["camera"]["errorTarget"].as_f64().unwrap();
    let root_error = tileset["root"]["geometricError"].as_f64().unwrap();
    let away = [-1.0, 0.6, -1.0];
    let len = away.iter().map(|x: &f64| x * x).sum::<f64>().sqrt();
    let (g, gc, distance, far) = cpv
        .impostors
        .iter()
        .map(|&i| i as usize)
        .filter(|&i| tiles_of[i].iter().any(|&k| tiles[k].visible))
        .find_map(|id| {
            let g = group_tile(tiles_of[id][0]);
            let group_json = json_tiles[g];
            let (glo, ghi) = corners(&group_json["boundingVolume"]);
            // z-up back to y-up: (x, y, z) ↦ (x, z, −y).
            let gc = [
                (glo[0] + ghi[0]) / 2.0,
                (glo[2] + ghi[2]) / 2.0,
                -(glo[1] + ghi[1]) / 2.0,
            ];
            let half_diag = (0..3)
                .map(|a| ((ghi[a] - glo[a]) / 2.0).powi(2))
                .sum::<f64>()
                .sqrt();
            let err = group_json["geometricError"].as_f64().unwrap();
            let distance = 1.5 * err * k / limit + half_diag;
            let far: [f64; 3] = std::array::from_fn(|a| gc[a] + away[a] / len * distance);
            let volume = corners(&group_json["children"][0]["viewerRequestVolume"]);
            (root_error * k / distance > 1.5 * limit && !inside(volume, z_up(far)))
                .then_some((g, gc, distance, far))
        })
        .unwrap_or_else(|| {
            panic!(
                "no drawn impostor of CPV {} has a group the root still refines past from \
                 where the group itself no longer does",
                cpv.id
            )
        });
    state = look(&mut b, far, gc);
    let tiles = client_tiles(&state);
    assert!(tiles[0].visible, "the root's objects are drawn from afar");
    assert!(
        tiles[g].loaded && tiles[g].visible,
        "the group's geometry is not drawn from afar: {:?}",
        tiles[g]
    );
    let drawn: Vec<usize> = (0..tiles.len())
        .filter(|&k| k != g && group_tile(k) == g && (tiles[k].visible || tiles[k].active))
        .collect();
    assert!(
        drawn.is_empty(),
        "group contents drawn from afar: {drawn:?}"
    );

    eprintln!(
        "{n} impostors in {group_count} groups, {} tiles; CPV {} from {from:?}: {shown} of its {} \
         impostors in view and drawn, {outside_drawn} contents drawn outside their request \
         volumes; group tile {g} drawn alone from {distance:.0} m",
        tiles.len(),
        cpv.id,
        cpv.impostors.len()
    );
    let problems = b.problems();
    assert!(problems.is_empty(), "the page had errors: {problems:?}");
    drop(b);
    let _ = std::fs::remove_dir_all(dir);
}

/// The tiles of a tileset JSON in pre-order.
fn flatten(tileset: &Value) -> Vec<&Value> {
    fn visit<'a>(t: &'a Value, out: &mut Vec<&'a Value>) {
        out.push(t);
        for c in t["children"].as_array().into_iter().flatten() {
            visit(c, out);
        }
    }
    let mut out = Vec::new();
    visit(&tileset["root"], &mut out);
    out
}

/// Per content URI of `tileset` (its JSON), the objects it draws: an
/// impostor's its cluster's (from the placement), geometry the objects its
/// tile lists, the root's those no impostor replaces.
fn content_objects(
    tileset: &Value,
    placement: &Placement,
    objects: usize,
) -> BTreeMap<String, Vec<u32>> {
    let mut map = BTreeMap::new();
    let mut replaced = vec![false; objects];
    for imp in &placement.impostors {
        for &o in &imp.objects {
            replaced[o as usize] = true;
        }
    }
    fn visit(t: &Value, p: &Placement, map: &mut BTreeMap<String, Vec<u32>>) {
        if let Some(uri) = t["content"]["uri"].as_str() {
            let e = &t["extras"];
            let objects: Vec<u32> = match e["impostor"].as_u64() {
                Some(i) => p.impostors[i as usize].objects.clone(),
                None => e["objects"]
                    .as_array()
                    .map(|a| a.iter().map(|o| o.as_u64().unwrap() as u32).collect())
                    .unwrap_or_default(),
            };
            if let Some(before) = map.insert(uri.to_string(), objects.clone()) {
                assert_eq!(before, objects, "{uri} stands for two object sets");
            }
        }
        for c in t["children"].as_array().into_iter().flatten() {
            visit(c, p, map);
        }
    }
    visit(tileset, placement, &mut map);
    map.insert(
        "scene.glb".into(),
        (0..objects as u32)
            .filter(|&o| !replaced[o as usize])
            .collect(),
    );
    map
}

/// Whether the y-up point `p` lies in `imp`'s view cell (within 1 mm or
/// 0.01°).
fn in_view_cell(imp: &optimizer::api::placement::PlacedImpostor, p: [f64; 3]) -> bool {
    use optimizer::api::placement::ViewCellJson;
    match imp.view_cell {
        ViewCellJson::Box { min, max } => {
            (0..3).all(|a| min[a] - 1e-3 <= p[a] && p[a] <= max[a] + 1e-3)
        }
        ViewCellJson::Shaft {
            apex,
            axis,
            half_angle_deg,
            min_distance,
        } => {
            let d: [f64; 3] = std::array::from_fn(|a| p[a] - apex[a]);
            let len = d.iter().map(|x| x * x).sum::<f64>().sqrt();
            let al = axis.iter().map(|x| x * x).sum::<f64>().sqrt();
            let cos = (0..3).map(|a| d[a] * axis[a]).sum::<f64>() / (len * al);
            len >= min_distance - 1e-3
                && cos.clamp(-1.0, 1.0).acos().to_degrees() <= half_angle_deg + 0.01
        }
    }
}

/// Has CesiumJS select tiles from `from` looking at `at` (y-up), and
/// returns the selected content URIs.
fn cesium_select(b: &mut Browser, from: [f64; 3], at: [f64; 3]) -> Vec<String> {
    let d: [f64; 3] = std::array::from_fn(|a| at[a] - from[a]);
    let r = settled(
        b,
        &format!(
            "cesiumClient.select({:?}, {:?}, [0, 0, 1], {{timeoutMs: 360000}})",
            z_up(from),
            z_up(d)
        ),
    );
    let errors = b.eval("cesiumClient.errors");
    assert_eq!(errors, json!([]), "errors from {from:?}: {r}");
    r["selected"]
        .as_array()
        .unwrap_or_else(|| panic!("no selection from {from:?}: {r}"))
        .iter()
        .map(|u| u.as_str().unwrap().to_string())
        .collect()
}

#[test]
fn cesium_switches_the_small_citys_impostors_by_the_viewers_position() {
    let _one = ONE_BROWSER.lock().unwrap_or_else(|e| e.into_inner());
    let Some(mut b) = Browser::start() else {
        return;
    };
    let dir = fresh("cesium");
    let client = dir.join("client");
    build_client("cesium-client", "@cesium/engine", &client);
    let SmallCity {
        glb,
        job,
        placement,
        tileset,
        tiles_dir,
        ..
    } = small_city(&dir);
    let scene = optimizer::scene::gltf_load::load_scene_bytes(&glb, "city").unwrap();
    let objects_of = content_objects(&tileset["root"], &placement, scene.objects.len());
    let addr = serve(client, tiles_dir);
    b.navigate(&format!("http://{addr}/"));
    b.wait_for(
        "!!window.cesiumClient",
        Duration::from_secs(30),
        "the client page",
    );
    let loaded = b.eval(&format!(
        "cesiumClient.load('tiles/tileset.json', {{fovDeg: {}, resolution: {:?}}})",
        job.camera.fov_deg, job.camera.resolution
    ));
    assert_eq!(loaded["loaded"], true, "{loaded}");

    // Views in CPVs with impostors, spread over the placement's CPVs.
    let views: Vec<(&PlacedCpv, View)> = placement
        .cpvs
        .iter()
        .filter(|c| !c.impostors.is_empty())
        .filter_map(|c| view_in(c).map(|v| (c, v)))
        .collect();
    assert!(views.len() >= 12, "{} CPVs with impostors", views.len());
    let step = views.len() / 12;
    let (mut drawn_of_cpv, mut listed_in_view, mut others) = (0, 0, 0);
    for (cpv, (from, at)) in views.iter().step_by(step).take(12) {
        let selected = cesium_select(&mut b, *from, *at);
        // Nothing twice: every object is drawn at most once, as geometry
        // or by one impostor.
        let mut drawn: BTreeMap<u32, &str> = BTreeMap::new();
        for uri in &selected {
            let objects = objects_of
                .get(uri)
                .unwrap_or_else(|| panic!("{uri} not in the tileset"));
            for &o in objects {
                if let Some(other) = drawn.insert(o, uri) {
                    panic!("CPV {}: object {o} drawn by {other} and {uri}", cpv.id);
                }
            }
        }
        // Every impostor drawn is one the placement draws from here: in a
        // CPV whose region holds the viewer, so the viewer is in its view
        // cell.
        let holding: Vec<&PlacedCpv> = placement
            .cpvs
            .iter()
            .filter(|c| (0..3).all(|a| c.region.min[a] <= from[a] && from[a] < c.region.max[a]))
            .collect();
        for uri in &selected {
            let Some(id) = uri
                .strip_prefix("impostor-")
                .and_then(|u| u.strip_suffix(".glb"))
                .map(|i| i.parse::<u32>().unwrap())
            else {
                continue;
            };
            assert!(
                holding.iter().any(|c| c.impostors.contains(&id)),
                "CPV {}: impostor {id} drawn from {from:?}, where no CPV draws it",
                cpv.id
            );
            assert!(
                in_view_cell(&placement.impostors[id as usize], *from),
                "impostor {id} drawn outside its view cell, from {from:?}"
            );
            if cpv.impostors.contains(&id) {
                drawn_of_cpv += 1;
            } else {
                others += 1;
            }
        }
        // What the CPV replaces is not drawn as geometry: each object of
        // its impostors is drawn by an impostor or, out of view, not at
        // all.
        for &id in &cpv.impostors {
            for o in &placement.impostors[id as usize].objects {
                if let Some(uri) = drawn.get(o) {
                    assert!(
                        uri.starts_with("impostor-"),
                        "CPV {}: object {o} of its impostor {id} drawn as geometry ({uri})",
                        cpv.id
                    );
                    listed_in_view += 1;
                }
            }
        }
    }
    // The checks saw something: impostors of the CPVs drawn, their objects
    // in view.
    assert!(
        drawn_of_cpv >= 12,
        "only {drawn_of_cpv} of the CPVs' impostors drawn"
    );
    assert!(listed_in_view > 0);

    // Above the view space, outside every switch's box but near enough
    // that by screen-space error alone the groups would refine into their
    // impostors: geometry only.
    let (lo, hi) = (job.view_space.min, job.view_space.max);
    let centre: [f64; 3] = std::array::from_fn(|a| (lo[a] + hi[a]) / 2.0);
    let above = [centre[0], hi[1] + 3.0, centre[2]];
    let selected = cesium_select(&mut b, above, [centre[0] + 50.0, 0.0, centre[2] + 1.0]);
    let clusters: Vec<&String> = selected
        .iter()
        .filter(|u| u.starts_with("cluster-"))
        .collect();
    assert!(
        selected.iter().all(|u| !u.starts_with("impostor-")),
        "impostors drawn from above the view space: {selected:?}"
    );
    assert!(
        !clusters.is_empty(),
        "no group drawn from above the view space: {selected:?}"
    );
    let near_groups = tileset["root"]["children"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|g| {
            clusters
                .iter()
                .any(|c| g["content"]["uri"].as_str() == Some(c.as_str()))
        })
        .filter(|g| {
            // The distance from the viewer at which its error is 16 px.
            let (glo, ghi) = corners(&g["boundingVolume"]);
            let p = z_up(above);
            let d = (0..3)
                .map(|a| (p[a] - p[a].clamp(glo[a], ghi[a])).powi(2))
                .sum::<f64>()
                .sqrt();
            let k = f64::from(job.camera.resolution[1])
                / (2.0 * (job.camera.fov_deg / 2.0).to_radians().tan());
            g["geometricError"].as_f64().unwrap() * k / d.max(1e-3) > 16.0
        })
        .count();
    assert!(
        near_groups > 0,
        "no group drawn as geometry would have refined by its error"
    );
    eprintln!(
        "CesiumJS: 12 views, {drawn_of_cpv} of their CPVs' impostors drawn ({listed_in_view} objects \
         replaced in view), {others} impostors of other CPVs of the same regions; above the view \
         space {} groups as geometry, {near_groups} of them within refining distance",
        clusters.len()
    );
    let problems = b.problems();
    assert!(problems.is_empty(), "the page had errors: {problems:?}");
    drop(b);
    let _ = std::fs::remove_dir_all(dir);
}
