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

/// Builds the client (`tools/tiles-client/build.mjs`) into `out`, so the
/// page served is never older than its sources.
fn build_client(out: &Path) {
    let tool = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tools/tiles-client");
    assert!(
        tool.join("node_modules/3d-tiles-renderer").is_dir(),
        "the 3D Tiles client is not installed: run `npm ci --prefix tools/tiles-client` \
         (tools/test.sh does)"
    );
    let o = Command::new("node")
        .arg(tool.join("build.mjs"))
        .arg(out)
        .output()
        .expect("run node");
    assert!(
        o.status.success(),
        "node tools/tiles-client/build.mjs: {}",
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

/// Answers one request: `/` and `/tiles-client.js` from `client`,
/// `/tiles/NAME` from `tiles`; plain names only.
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
        "/tiles-client.js" => Some(client.join("tiles-client.js")),
        p => p
            .strip_prefix("/tiles/")
            .filter(|n| plain(n))
            .map(|n| tiles.join(n)),
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

/// A view in `cpv` seeing what its impostors stand for: its region's
/// centre, looking along a direction of its VDI whose component across is
/// its interval's middle and whose component up or down is the one of its
/// interval nearest the horizon (1 % of the interval inside it). At the
/// VDI's centre a CPV of views pitched down sees only the ground near the
/// viewer: its impostors were chosen for the views of the VDI that see the
/// city. `None` for a CPV of views up or down (a face of the y axis).
fn view_in(cpv: &PlacedCpv) -> Option<([f64; 3], [f64; 3])> {
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
            visited: t["visited"] == true,
            in_frustum: t["inFrustum"] == true,
            active: t["active"] == true,
            visible: t["visible"] == true,
        })
        .collect()
}

/// Places the client's camera, lets it settle and returns its state.
fn look(b: &mut Browser, from: [f64; 3], at: [f64; 3]) -> Value {
    b.eval(&format!("tilesClient.placeCamera({from:?}, {at:?})"));
    b.eval("tilesClient.settle(120000)");
    let state = b.eval("tilesClient.state()");
    let errors = &state["errors"];
    assert_eq!(errors, &json!([]), "load errors from {from:?}");
    state
}

#[test]
fn the_small_citys_tileset_loads_and_refines_in_3d_tiles_renderer() {
    let Some(mut b) = Browser::start() else {
        return;
    };
    let dir = fresh("city");
    let client = dir.join("client");
    build_client(&client);
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
    // to see all of it, near enough that every cluster tile refines
    // (closer than twice the diagonal of what it reaches): every content
    // loads and parses.
    let (lo, hi) = (job.view_space.min, job.view_space.max);
    let centre: [f64; 3] = std::array::from_fn(|a| (lo[a] + hi[a]) / 2.0);
    let half_fov = (job.camera.fov_deg / 2.0).to_radians();
    let extent = (hi[0] - lo[0]).max(hi[2] - lo[2]) / 2.0;
    let above = [centre[0], hi[1] + 1.1 * extent / half_fov.tan(), centre[2]];
    let mut state = look(&mut b, above, [centre[0], 0.0, centre[2] + 1e-3]);
    let tiles = client_tiles(&state);

    // The hierarchy: impostors plus the base scene (the root and one tile
    // per cluster group).
    assert_eq!(
        tiles.len(),
        n + 1 + group_count,
        "{n} impostors, {group_count} cluster groups"
    );
    let root = &tiles[0];
    assert_eq!((root.parent, root.depth), (None, 0));
    assert_eq!(root.uri.as_deref(), Some("scene.glb"));
    assert_eq!(root.refine, "ADD");
    let impostor_tiles: Vec<usize> = (0..tiles.len())
        .filter(|&k| {
            tiles[k]
                .uri
                .as_deref()
                .is_some_and(|u| u.starts_with("impostor-"))
        })
        .collect();
    assert_eq!(impostor_tiles.len(), n, "tiles with impostor content");
    let mut tile_of = vec![usize::MAX; n];
    for &k in &impostor_tiles {
        let t = &tiles[k];
        let id = t.impostor.expect("an impostor tile names its impostor");
        assert_eq!(
            t.uri.as_deref(),
            Some(format!("impostor-{id}.glb").as_str())
        );
        assert_eq!(tile_of[id], usize::MAX, "impostor {id} twice");
        tile_of[id] = k;
        let p = &tiles[t.parent.unwrap()];
        assert_eq!((t.depth, p.depth, p.parent), (2, 1, Some(0)));
        assert!(p.uri.as_deref().unwrap().starts_with("cluster-"));
        assert_eq!(
            (t.refine.as_str(), p.refine.as_str()),
            ("REPLACE", "REPLACE")
        );
    }
    // The client's cluster tiles are the placement's groups: two impostors
    // share a parent exactly when they share a group.
    let parent_of = |id: usize| tiles[tile_of[id]].parent.unwrap();
    let mut rep_of_parent = BTreeMap::new();
    for (id, &group) in group_of.iter().enumerate() {
        let rep = *rep_of_parent.entry(parent_of(id)).or_insert(group);
        assert_eq!(rep, group, "impostor {id} under another group's tile");
    }
    assert_eq!(rep_of_parent.len(), group_count);
    // Everything loaded, nothing failed, and the canvas shows the city.
    let unloaded: Vec<&Option<String>> =
        tiles.iter().filter(|t| !t.loaded).map(|t| &t.uri).collect();
    assert!(unloaded.is_empty(), "not loaded from above: {unloaded:?}");
    assert_eq!(state["loadedModels"], json!(tiles.len()));
    let pixels = b.eval("tilesClient.pixels()");
    let total = pixels["width"].as_u64().unwrap() * pixels["height"].as_u64().unwrap();
    let drawn = pixels["drawn"].as_u64().unwrap();
    assert!(drawn * 10 > total, "only {drawn} of {total} pixels drawn");

    // Request volumes of the export, per impostor (z-up boxes).
    let mut request = vec![None; n];
    for c in tileset["root"]["children"].as_array().unwrap() {
        for t in c["children"].as_array().unwrap() {
            let id = t["extras"]["impostor"].as_u64().unwrap() as usize;
            request[id] = Some(corners(&t["viewerRequestVolume"]));
        }
    }
    let request: Vec<_> = request.into_iter().map(Option::unwrap).collect();

    // 2. Inside the first CPV with impostors (`view_in`):
    // the CPV's impostors in view are drawn and their groups' geometry is
    // not (REPLACE).
    let (cpv, (from, at)) = placement
        .cpvs
        .iter()
        .filter(|c| !c.impostors.is_empty())
        .find_map(|c| view_in(c).map(|v| (c, v)))
        .expect("a CPV with impostors");
    state = look(&mut b, from, at);
    let tiles = client_tiles(&state);
    assert!(tiles[0].visible, "the root's objects are drawn");
    let listed: Vec<usize> = cpv.impostors.iter().map(|&i| i as usize).collect();
    let mut shown = 0;
    for &id in &listed {
        let t = &tiles[tile_of[id]];
        let g = &tiles[t.parent.unwrap()];
        // The viewer is in the impostor's view cell, so in its request
        // volume.
        assert!(inside(request[id], z_up(from)), "impostor {id}");
        // The root refines, so every group tile's state is this update's;
        // one out of view (no child's box in the frustum) is not drawn,
        // nor its impostors.
        assert!(g.visited, "impostor {id}'s group tile is stale: {g:?}");
        if !g.in_frustum {
            assert!(!t.visible && !g.visible, "impostor {id}: {t:?} {g:?}");
            continue;
        }
        // In view and near: the group refines into its impostors, and its
        // geometry is not drawn (REPLACE).
        assert!(
            !g.visible && !g.active,
            "impostor {id}'s group geometry drawn too: {g:?}"
        );
        if t.in_frustum {
            shown += 1;
            assert!(
                t.loaded && t.active && t.visible,
                "impostor {id} of CPV {} in view but not drawn: {t:?}",
                cpv.id
            );
        } else {
            assert!(!t.visible, "impostor {id} drawn out of view: {t:?}");
        }
    }
    assert!(shown > 0, "none of CPV {}'s impostors is in view", cpv.id);
    // Request volumes are ignored: the same groups' impostors for view
    // cells that do not hold the viewer are drawn as well when in view.
    let mut outside_drawn = 0;
    for id in 0..n {
        let t = &tiles[tile_of[id]];
        let sibling = listed.iter().any(|&l| parent_of(l) == parent_of(id));
        if !sibling || listed.contains(&id) || inside(request[id], z_up(from)) || !t.in_frustum {
            continue;
        }
        assert!(
            t.visible,
            "impostor {id}, outside its request volume but in view: {t:?}"
        );
        outside_drawn += 1;
    }
    assert!(
        outside_drawn > 0,
        "no impostor outside its request volume was in view: the check saw nothing"
    );

    // 3. Far outside the view space, looking at the listed impostor's group
    // from a distance where its cluster tile no longer refines (its
    // screen-space error two thirds of the limit) while the root still
    // does: the group's geometry is drawn, none of its impostors.
    let id = listed
        .iter()
        .copied()
        .find(|&id| tiles[tile_of[id]].visible)
        .unwrap();
    let g = parent_of(id);
    let group_tile = tileset["root"]["children"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["content"]["uri"].as_str() == tiles[g].uri.as_deref())
        .expect("the group's tile in tileset.json");
    let (glo, ghi) = corners(&group_tile["boundingVolume"]);
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
    let k = f64::from(job.camera.resolution[1]) / (2.0 * half_fov.tan());
    let err = group_tile["geometricError"].as_f64().unwrap();
    let limit = state["camera"]["errorTarget"].as_f64().unwrap();
    let distance = 1.5 * err * k / limit + half_diag;
    let away = [-1.0, 0.6, -1.0];
    let len = away.iter().map(|x: &f64| x * x).sum::<f64>().sqrt();
    let far: [f64; 3] = std::array::from_fn(|a| gc[a] + away[a] / len * distance);
    let root_error = tileset["root"]["geometricError"].as_f64().unwrap();
    assert!(
        root_error * k / distance > 1.5 * limit,
        "the root would not refine from {far:?}"
    );
    for c in group_tile["children"].as_array().unwrap() {
        assert!(!inside(corners(&c["viewerRequestVolume"]), z_up(far)));
    }
    state = look(&mut b, far, gc);
    let tiles = client_tiles(&state);
    assert!(tiles[0].visible, "the root's objects are drawn from afar");
    assert!(
        tiles[g].loaded && tiles[g].visible,
        "the group's geometry is not drawn from afar: {:?}",
        tiles[g]
    );
    let drawn: Vec<usize> = (0..n)
        .filter(|&i| parent_of(i) == g && (tiles[tile_of[i]].visible || tiles[tile_of[i]].active))
        .collect();
    assert!(drawn.is_empty(), "impostors drawn from afar: {drawn:?}");

    eprintln!(
        "{n} impostors in {group_count} groups; CPV {} from {from:?}: {shown} of its {} \
         impostors in view and drawn, {outside_drawn} drawn outside their request volumes; \
         group tile {g} drawn alone from {distance:.0} m",
        cpv.id,
        listed.len()
    );
    let problems = b.problems();
    assert!(problems.is_empty(), "the page had errors: {problems:?}");
    drop(b);
    let _ = std::fs::remove_dir_all(dir);
}
