//! The web page at `/`: the real `impostor-server` binary serves it and its
//! assets (types, cache headers, the bundled three.js), and headless
//! Chromium submits a job through its form, follows the job to success and
//! opens the 3D viewer, which must find the camera's CPV, show that CPV's
//! impostors in place of their clusters' objects (the object order of the
//! optimizer) and draw the scene.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::{Value, json};

mod common;

use common::browser::Browser;
use common::process::{request, terminate};

/// An empty folder for test `name`.
fn fresh(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("impostor-web-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Starts the binary with `--no-auth` (the default local setup) on a free
/// loopback port over an empty data folder.
fn spawn(name: &str) -> (Child, SocketAddr, std::path::PathBuf) {
    let dir = fresh(name);
    let (child, addr) = spawn_in(&dir, &["--no-auth"]);
    (child, addr, dir)
}

/// Starts the binary with `auth` (`--no-auth` or `--tokens FILE`) on a free
/// loopback port, its data in `dir/data`.
fn spawn_in(dir: &std::path::Path, auth: &[&str]) -> (Child, SocketAddr) {
    let addr = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap();
    let child = Command::new(env!("CARGO_BIN_EXE_impostor-server"))
        .args(auth)
        .args(["--listen", &addr.to_string(), "--data-dir"])
        .arg(dir.join("data"))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start impostor-server");
    let start = Instant::now();
    while request(addr, "GET", "/healthz", b"").is_none() {
        assert!(start.elapsed() < Duration::from_secs(20), "no server");
        std::thread::sleep(Duration::from_millis(50));
    }
    (child, addr)
}

/// `GET path`: status, the head's lines (lower case) and the body.
fn get(addr: SocketAddr, path: &str) -> (u16, String, Vec<u8>) {
    let mut s = TcpStream::connect(addr).unwrap();
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: t\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut raw = Vec::new();
    s.read_to_end(&mut raw).unwrap();
    let split = raw.windows(4).position(|w| w == b"\r\n\r\n").unwrap();
    let head = String::from_utf8_lossy(&raw[..split]).to_lowercase();
    let status = head[9..12].parse().unwrap();
    (status, head, raw[split + 4..].to_vec())
}

/// The value of header `name` in `head` (lower case).
fn header<'a>(head: &'a str, name: &str) -> Option<&'a str> {
    head.lines()
        .find_map(|l| l.strip_prefix(&format!("{name}: ")))
        .map(str::trim)
}

#[test]
fn the_page_and_its_assets_are_served_with_their_types_and_cache_headers() {
    let (mut child, addr, dir) = spawn("assets");
    let (s, head, body) = get(addr, "/");
    assert_eq!(s, 200);
    assert_eq!(
        header(&head, "content-type"),
        Some("text/html; charset=utf-8")
    );
    assert_eq!(header(&head, "cache-control"), Some("no-cache"));
    let html = String::from_utf8(body).unwrap();
    // The index names its hashed assets; nothing comes from elsewhere.
    let assets: Vec<&str> = html
        .split('"')
        .filter(|p| p.starts_with("assets/"))
        .collect();
    assert_eq!(assets.len(), 2, "{html}");
    assert!(
        !html.contains("http://") && !html.contains("https://"),
        "{html}"
    );
    for asset in assets {
        let (s, head, body) = get(addr, &format!("/{asset}"));
        assert_eq!(s, 200, "{asset}");
        let (kind, needle) = if asset.ends_with(".js") {
            // three.js's renderer and the embedded job schema.
            ("text/javascript; charset=utf-8", "WebGLRenderer")
        } else {
            ("text/css; charset=utf-8", "canvas")
        };
        assert_eq!(header(&head, "content-type"), Some(kind), "{asset}");
        assert_eq!(
            header(&head, "cache-control"),
            Some("public, max-age=31536000, immutable"),
            "{asset}"
        );
        // Named by their content (so cached for good): the first 16 hex
        // digits of its SHA-256.
        use sha2::Digest;
        let hash: String = sha2::Sha256::digest(&body)
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect();
        let ext = asset.rsplit_once('.').unwrap().1;
        assert_eq!(asset, format!("assets/app-{}.{ext}", &hash[..16]));
        let text = String::from_utf8(body).unwrap();
        assert!(text.contains(needle), "{asset} lacks {needle}");
        if asset.ends_with(".js") {
            assert!(text.contains("target_frame_time_ms"), "the job schema");
            // The Basis Universal transcoder's folder, for KTX2 atlases,
            // and Draco's decoder's, for Draco-compressed scenes.
            for (prefix, files) in [
                (
                    "assets/basis-",
                    ["basis_transcoder.js", "basis_transcoder.wasm"],
                ),
                (
                    "assets/draco-",
                    ["draco_wasm_wrapper.js", "draco_decoder.wasm"],
                ),
            ] {
                let at = text.find(prefix).expect("the decoder's folder");
                let folder = &text[at..at + prefix.len() + 16];
                for file in files {
                    let kind = match file.rsplit_once('.').unwrap().1 {
                        "js" => "text/javascript; charset=utf-8",
                        _ => "application/wasm",
                    };
                    let (s, head, body) = get(addr, &format!("/{folder}/{file}"));
                    assert_eq!(s, 200, "{folder}/{file}");
                    assert_eq!(header(&head, "content-type"), Some(kind));
                    assert!(body.len() > 10_000, "{file}: {} bytes", body.len());
                }
            }
            let at = text.find("assets/basis-").unwrap();
            let folder = &text[at..at + "assets/basis-".len() + 16];
            assert_eq!(get(addr, &format!("/{folder}/../index.html")).0, 404);
            assert_eq!(
                get(addr, &format!("/{folder}/x/basis_transcoder.js")).0,
                404
            );
        }
    }
    // Control: an unknown asset is a 404, not the page; the API is as it was.
    let (s, head, _) = get(addr, "/assets/app-NOSUCH.js");
    assert_eq!(s, 404);
    assert!(
        header(&head, "content-type")
            .unwrap()
            .starts_with("text/plain")
    );
    assert_eq!(get(addr, "/assets/../index.html").0, 404);
    let (s, _, body) = get(addr, "/v1/jobs");
    assert_eq!(s, 200);
    assert_eq!(
        serde_json::from_slice::<Value>(&body).unwrap()["jobs"],
        json!([])
    );
    terminate(&mut child, Duration::from_secs(30));
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn the_page_sends_the_token_the_user_enters() {
    let Some(mut b) = Browser::start() else {
        return;
    };
    let dir = fresh("token");
    let tokens = dir.join("tokens.json");
    let out = Command::new(env!("CARGO_BIN_EXE_impostor-server"))
        .args(["token", "add", "--tenant", "studio", "--tokens"])
        .arg(&tokens)
        .output()
        .unwrap();
    assert!(out.status.success(), "{out:?}");
    let token = String::from_utf8(out.stdout).unwrap().trim().to_string();
    let (mut child, addr) = spawn_in(&dir, &["--tokens", tokens.to_str().unwrap()]);
    // The page itself needs no token.
    assert_eq!(get(addr, "/").0, 200);
    b.navigate(&format!("http://{addr}/#/"));
    let refused = b.wait_for(
        "document.querySelector('#main .error')?.innerText",
        Duration::from_secs(30),
        "the job list refused without a token",
    );
    assert!(refused.as_str().unwrap().contains("401"), "{refused}");
    // The user enters the token: the list loads with it.
    b.eval(&format!(
        "const t = document.getElementById('token'); t.value = {}; \
         t.dispatchEvent(new Event('change')); true",
        serde_json::to_string(&token).unwrap()
    ));
    let listed = b.wait_for(
        "document.getElementById('main').innerText.includes('No jobs yet')",
        Duration::from_secs(30),
        "the job list with the token",
    );
    assert_eq!(listed, true);
    assert_eq!(
        b.eval("document.querySelector('#main .error')"),
        Value::Null
    );
    drop(b);
    terminate(&mut child, Duration::from_secs(30));
    let _ = std::fs::remove_dir_all(dir);
}

/// Submits `scene` with the job `job_text` through the page's form (bake
/// checked, as by default), waits for the job page to show it succeeded
/// and returns its id. The page must be on `#/submit`.
fn submit_through_form(b: &mut Browser, scene: &std::path::Path, job_text: &str) -> String {
    let root = b.call("DOM.getDocument", json!({})).unwrap()["root"]["nodeId"].clone();
    let input = b
        .call(
            "DOM.querySelector",
            json!({"nodeId": root, "selector": "#scene"}),
        )
        .unwrap()["nodeId"]
        .clone();
    b.call(
        "DOM.setFileInputFiles",
        json!({"nodeId": input, "files": [scene.to_str().unwrap()]}),
    )
    .unwrap();
    b.eval(&format!(
        "document.getElementById('job').value = {}; document.getElementById('submit').click(); true",
        serde_json::to_string(job_text).unwrap()
    ));
    let state = b.wait_for(
        "(() => { const p = document.getElementById('job-page');
                  return p && p.dataset.ready === 'true' && p.dataset.state; })()",
        Duration::from_secs(600),
        "the job page showing a finished job",
    );
    assert_eq!(state, "succeeded");
    let id = b.eval("document.getElementById('job-page').dataset.job");
    id.as_str().unwrap().to_string()
}

/// Opens the viewer of the job on the page (`open-viewer`) and waits for it.
fn open_viewer(b: &mut Browser) {
    b.eval("document.getElementById('open-viewer').click(); true");
    b.wait_for(
        "(() => { const v = document.getElementById('viewer');
                  if (v && v.dataset.error) throw new Error(v.dataset.error);
                  return v && v.dataset.ready === 'true'; })()",
        Duration::from_secs(120),
        "the viewer loading the job",
    );
}

/// A placement file as JSON with every CPV's impostor list whole (a file may
/// write a list as its change from the one before it), rebuilt by the
/// library's reader.
fn whole_lists(file: &[u8]) -> Value {
    let mut v: Value = serde_json::from_slice(file).unwrap();
    optimizer::api::placement::whole_lists(&mut v).unwrap();
    v
}

/// The CPV of `placement` holding the view at `p` looking along `d`, by the
/// convention of DESIGN.md: the eye in the CPV's region (min inclusive, max
/// exclusive except at the view space's maximum `vs_max`) and the direction
/// in its VDI (cube face 2·axis + (0 if positive else 1), a direction on an
/// edge on the lower face; (u, v) the other two coordinates over the major
/// one's magnitude, bounds inclusive). The first such CPV.
fn cpv_at(placement: &Value, vs_max: [f64; 3], p: [f64; 3], d: [f64; 3]) -> Option<&Value> {
    let mut axis = 0;
    for a in 1..3 {
        if d[a].abs() > d[axis].abs() {
            axis = a;
        }
    }
    let m = d[axis].abs();
    let face = 2 * axis + usize::from(d[axis] < 0.0);
    let rest: Vec<f64> = (0..3).filter(|&a| a != axis).map(|a| d[a] / m).collect();
    let f = |v: &Value| v.as_f64().unwrap();
    placement["cpvs"].as_array().unwrap().iter().find(|c| {
        let dirs = &c["directions"];
        let in_vdi = dirs["face"].as_u64().unwrap() as usize == face
            && (f(&dirs["u"][0])..=f(&dirs["u"][1])).contains(&rest[0])
            && (f(&dirs["v"][0])..=f(&dirs["v"][1])).contains(&rest[1]);
        let r = &c["region"];
        let in_region = (0..3).all(|a| {
            let (lo, hi) = (f(&r["min"][a]), f(&r["max"][a]));
            p[a] >= lo && p[a] <= hi && (p[a] < hi || hi == vs_max[a])
        });
        in_vdi && in_region
    })
}

/// The impostors' footprint in views of `placement`'s CPVs with impostors
/// (each from its region's centre along its VDI's centre), tried in order
/// of their impostors' apparent size from there (sum of (radius /
/// distance)²), at most 8: the view in which impostors or their objects
/// cover the most pixels (at least 200), as (CPV id, pixels, footprint,
/// mismatch) (`impostorViewer.footprint()`). At eye level in the tenth-scale
/// city the impostors are far away and small (~0.1 % of the canvas), so
/// their outlines weigh much: about a fifth of the footprint mismatches.
/// An atlas that failed to decode would mismatch all of it (transparent:
/// no impostor pixel) or far more than its objects (opaque: whole quads).
fn footprint_view(b: &mut Browser, placement: &Value) -> (u64, u64, u64, u64) {
    let f = |v: &Value| v.as_f64().unwrap();
    let apparent = |cpv: &Value| -> f64 {
        let (p, _) = view_in(cpv);
        cpv["impostors"]
            .as_array()
            .unwrap()
            .iter()
            .map(|i| {
                let sphere = &placement["impostors"][i.as_u64().unwrap() as usize]["sphere"];
                let d2: f64 = (0..3)
                    .map(|a| (f(&sphere["center"][a]) - p[a]).powi(2))
                    .sum();
                f(&sphere["radius"]).powi(2) / d2.max(1e-6)
            })
            .sum()
    };
    let mut cpvs: Vec<(f64, &Value)> = placement["cpvs"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|c| !c["impostors"].as_array().unwrap().is_empty())
        .map(|c| (apparent(c), c))
        .collect();
    cpvs.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut best = None;
    for (_, cpv) in cpvs.into_iter().take(8) {
        let (p, d) = view_in(cpv);
        b.eval(&format!("impostorViewer.lookFrom({p:?}, {d:?})"));
        let f = b.eval("impostorViewer.footprint()");
        let n = |k: &str| f[k].as_u64().unwrap();
        let view = (
            cpv["id"].as_u64().unwrap(),
            n("pixels"),
            n("footprint"),
            n("mismatch"),
        );
        if best.is_none_or(|b: (u64, u64, u64, u64)| view.2 > b.2) {
            best = Some(view);
        }
    }
    let best = best.expect("CPVs with impostors");
    assert!(best.2 >= 200, "the impostors cover only {} pixels", best.2);
    best
}

/// The viewer's object ids name the optimizer's objects: every object's
/// drawn box is the box the optimizer loaded for that id from `glb`, within
/// `step` of an object's largest side (the quantization step of a
/// Draco-compressed scene: three.js bounds a primitive by its accessors'
/// `min` and `max`, the values before quantization; the optimizer by the
/// decoded vertices).
fn assert_object_boxes(b: &mut Browser, glb: &[u8], step: f64) {
    let scene = optimizer::scene::gltf_load::load_scene_bytes(glb, "scene").unwrap();
    let boxes = b.eval("impostorViewer.objectMeshes.map((_, i) => impostorViewer.objectBox(i))");
    let boxes = boxes.as_array().unwrap();
    assert_eq!(boxes.len(), scene.objects.len());
    for (i, (b, o)) in boxes.iter().zip(&scene.objects).enumerate() {
        for (k, want) in [("min", o.min), ("max", o.max)] {
            for a in 0..3 {
                let got = b[k][a]
                    .as_f64()
                    .unwrap_or_else(|| panic!("object {i}: the viewer has no mesh for it ({b})"));
                let side = (o.max - o.min).max_element();
                assert!(
                    (got - want[a]).abs() < 1e-3 * (1.0 + want[a].abs()) + step * side,
                    "object {i} ({}) {k}[{a}]: the viewer's {got}, the optimizer's {}",
                    o.name,
                    want[a]
                );
            }
        }
    }
}

/// The tenth-scale city with its repeated meshes drawn as GPU instances
/// (`gltfpack -noq -mi`: `EXT_mesh_gpu_instancing`), as game maps ship
/// forests and props, then compressed with Draco (glTF Transform with
/// Google's encoder: `KHR_draco_mesh_compression`), as the web ships scenes.
fn instanced_draco_city(dir: &std::path::Path) -> Vec<u8> {
    let city = dir.join("city-plain.glb");
    std::fs::write(&city, common::city(0.1)).unwrap();
    let out = dir.join("city-instanced.glb");
    let tools = concat!(env!("CARGO_MANIFEST_DIR"), "/../tools");
    node(
        "gltfpack (npm ci --prefix tools/gltfpack)",
        &format!("{tools}/gltfpack/node_modules/gltfpack/cli.js"),
        &[
            "-noq".as_ref(),
            "-mi".as_ref(),
            "-i".as_ref(),
            city.as_os_str(),
            "-o".as_ref(),
            out.as_os_str(),
        ],
    );
    let compressed = dir.join("city-instanced-draco.glb");
    node(
        "the Draco encoder (npm ci --prefix tools/gltf-draco)",
        &format!("{tools}/gltf-draco/draco.mjs"),
        &[out.as_os_str(), compressed.as_os_str()],
    );
    std::fs::read(compressed).unwrap()
}

/// Runs `node SCRIPT ARGS`, failing the test with its error output.
fn node(what: &str, script: &str, args: &[&std::ffi::OsStr]) {
    let o = Command::new("node")
        .arg(script)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("run node for {what}: {e}"));
    assert!(
        o.status.success(),
        "{what}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

/// A view in `cpv`: its region's centre looking along its VDI's centre.
fn view_in(cpv: &Value) -> ([f64; 3], [f64; 3]) {
    let r = &cpv["region"];
    let p =
        [0, 1, 2].map(|a| (r["min"][a].as_f64().unwrap() + r["max"][a].as_f64().unwrap()) / 2.0);
    let dirs = &cpv["directions"];
    let face = dirs["face"].as_u64().unwrap() as usize;
    let mid = |k: &str| (dirs[k][0].as_f64().unwrap() + dirs[k][1].as_f64().unwrap()) / 2.0;
    let axis = face / 2;
    let mut d = [0.0; 3];
    d[axis] = if face.is_multiple_of(2) { 1.0 } else { -1.0 };
    let others: Vec<usize> = (0..3).filter(|&a| a != axis).collect();
    d[others[0]] = mid("u");
    d[others[1]] = mid("v");
    (p, d)
}

/// Ids as the viewer lists them: ascending, comma-separated.
fn id_list(ids: impl IntoIterator<Item = u64>) -> String {
    let mut v: Vec<u64> = ids.into_iter().collect();
    v.sort();
    v.dedup();
    v.iter().map(u64::to_string).collect::<Vec<_>>().join(",")
}

#[test]
fn the_page_submits_a_job_follows_it_and_views_its_impostors() {
    let Some(mut b) = Browser::start() else {
        return;
    };
    let (mut child, addr, dir) = spawn("browser");
    let glb = common::city(0.1);
    let scene_path = dir.join("city.glb");
    std::fs::write(&scene_path, &glb).unwrap();
    // The small city's job, with a walkthrough for the viewer's walk: three
    // turns, through several cells and view directions.
    let mut job = common::process::small_job();
    let path = [
        [20.0, 1.8, 20.0],
        [60.0, 1.8, 30.0],
        [60.0, 1.8, 80.0],
        [20.0, 1.8, 60.0],
    ];
    job["walkthrough"] = json!({ "points": path });
    let job_text = job.to_string();

    b.navigate(&format!("http://{addr}/#/submit"));
    b.wait_for(
        "!!document.getElementById('scene')",
        Duration::from_secs(30),
        "the submit form",
    );
    // Control: a job the schema refuses is not sent.
    b.eval(
        "document.getElementById('job').value = '{\"target_frame_time_ms\": \"fast\"}';
         document.getElementById('submit').click(); true",
    );
    let refused = b.wait_for(
        "document.getElementById('submit-result').innerText",
        Duration::from_secs(10),
        "the schema's errors",
    );
    let refused = refused.as_str().unwrap();
    assert!(
        refused.contains("does not match the job schema"),
        "{refused}"
    );
    assert!(refused.contains("view_space"), "{refused}");
    assert!(refused.contains("/target_frame_time_ms"), "{refused}");
    let (_, _, list) = get(addr, "/v1/jobs");
    assert_eq!(
        serde_json::from_slice::<Value>(&list).unwrap()["jobs"],
        json!([])
    );

    let id = submit_through_form(&mut b, &scene_path, &job_text);
    let (s, _, status) = get(addr, &format!("/v1/jobs/{id}"));
    assert_eq!(s, 200);
    let status: Value = serde_json::from_slice(&status).unwrap();
    assert_eq!(status["state"], "succeeded");
    assert_eq!(status["bake"], true);
    // The page shows the summary, the report and the downloads.
    let cpvs = b.eval(
        "[...document.querySelectorAll('#job-summary tr')].find(r => r.cells[0].innerText === 'cpvs')?.cells[1].innerText",
    );
    assert_eq!(cpvs, json!(status["summary"]["cpvs"].to_string()));
    let files = b.eval("[...document.querySelectorAll('[data-file]')].map(a => a.dataset.file)");
    assert!(
        files.as_array().unwrap().contains(&json!("impostors.glb")),
        "{files}"
    );
    // The scene input is served as it was uploaded.
    let (s, head, scene) = get(addr, &format!("/v1/jobs/{id}/scene"));
    assert_eq!(s, 200);
    assert_eq!(header(&head, "content-type"), Some("model/gltf-binary"));
    assert!(scene == glb, "the scene differs from the upload");

    // The viewer.
    open_viewer(&mut b);
    let (_, _, placement) = get(addr, &format!("/v1/jobs/{id}/placement"));
    let placement = whole_lists(&placement);
    let cpvs = placement["cpvs"].as_array().unwrap();
    let with = cpvs
        .iter()
        .find(|c| !c["impostors"].as_array().unwrap().is_empty())
        .expect("the small city has a CPV with impostors");
    let other = cpvs
        .iter()
        .find(|c| c["impostors"] != with["impostors"])
        .expect("a CPV with other impostors");
    for cpv in [with, other, with] {
        let (p, d) = view_in(cpv);
        let state = b.eval(&format!("impostorViewer.lookFrom({p:?}, {d:?})"));
        let active = cpv["impostors"].as_array().unwrap();
        let hidden = active.iter().flat_map(|i| {
            placement["impostors"][i.as_u64().unwrap() as usize]["objects"]
                .as_array()
                .unwrap()
                .iter()
                .map(|o| o.as_u64().unwrap())
        });
        assert_eq!(state["cpv"], cpv["id"].to_string(), "{state}");
        assert_eq!(
            state["activeImpostors"],
            id_list(active.iter().map(|i| i.as_u64().unwrap())),
            "{state}"
        );
        assert_eq!(state["hiddenObjects"], id_list(hidden), "{state}");
        assert_eq!(state["visibleImpostorNodes"], active.len().to_string());
        let ms: f64 = state["frameMs"].as_str().unwrap().parse().unwrap();
        assert_eq!(ms, cpv["time_ms_final"].as_f64().unwrap());
    }

    // The impostors cover what their objects covered.
    let (cpv, pixels, footprint, mismatch) = footprint_view(&mut b, &placement);
    eprintln!("PNG: CPV {cpv}: footprint {footprint} of {pixels} pixels, mismatch {mismatch}");
    assert!(
        mismatch * 3 <= footprint,
        "CPV {cpv}: {mismatch} of {footprint} pixels mismatch"
    );
    let (p, d) = view_in(with);
    b.eval(&format!("impostorViewer.lookFrom({p:?}, {d:?})"));

    // The view cells of the shown impostors (the camera is in `with`):
    // shafts as cones (meshes), boxes as boxes (lines).
    b.eval("document.querySelector('aside input[type=checkbox]').click(); true");
    let cells = b.eval(
        "new Promise(r => requestAnimationFrame(() => requestAnimationFrame(() => r(
           impostorViewer.cells.children.map(c => c.isMesh ? 'shaft' : 'box')))))",
    );
    let mut want: Vec<&str> = with["impostors"]
        .as_array()
        .unwrap()
        .iter()
        .map(|i| {
            let cell = &placement["impostors"][i.as_u64().unwrap() as usize]["view_cell"];
            if cell.get("shaft").is_some() {
                "shaft"
            } else {
                "box"
            }
        })
        .collect();
    let mut got: Vec<&str> = cells
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_str().unwrap())
        .collect();
    want.sort();
    got.sort();
    assert_eq!(got, want);

    assert_object_boxes(&mut b, &glb, 0.0);

    // A walk of 100 frames along the path: at every frame the CPV shown is
    // the placement's CPV of the camera's view (found here from the
    // placement alone), with its impostors and only those drawn; the canvas
    // is drawn at frames along the way.
    let vs_max = [474.0, 2.0, 316.0];
    let mut seen = std::collections::BTreeSet::new();
    let mut first_cpv = Value::Null;
    for i in 0..100 {
        let state = b.eval(&format!("impostorViewer.walkFrame({i}, 100)"));
        let xyz = |k: &str| [0, 1, 2].map(|a| state[k][a].as_f64().unwrap());
        let cpv = cpv_at(&placement, vs_max, xyz("position"), xyz("direction"));
        let (id, active) = match cpv {
            Some(c) => (
                c["id"].to_string(),
                c["impostors"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|i| i.as_u64().unwrap())
                    .collect(),
            ),
            None => (String::new(), Vec::new()),
        };
        assert_eq!(state["cpv"], id, "frame {i}: {state}");
        assert_eq!(
            state["activeImpostors"],
            id_list(active.clone()),
            "frame {i}"
        );
        assert_eq!(
            state["visibleImpostorNodes"],
            active.len().to_string(),
            "frame {i}"
        );
        if i == 0 {
            first_cpv = state["cpv"].clone();
        }
        if !active.is_empty() {
            seen.insert(id);
        }
        if i % 33 == 0 {
            let pixels = b.eval("impostorViewer.pixels()");
            let total = pixels["width"].as_u64().unwrap() * pixels["height"].as_u64().unwrap();
            let drawn = pixels["drawn"].as_u64().unwrap();
            assert!(
                drawn * 20 > total,
                "frame {i}: only {drawn} of {total} pixels drawn"
            );
        }
    }
    // The check could fail: the walk passes through several CPVs that
    // have impostors.
    assert!(
        seen.len() >= 3,
        "the walk met only CPVs {seen:?} with impostors"
    );
    // "Walk the path" follows the job's walkthrough to its end.
    b.eval("document.getElementById('walk').click(); true");
    assert_eq!(
        b.eval("document.getElementById('viewer').dataset.walking"),
        "true"
    );
    b.wait_for(
        "document.getElementById('viewer').dataset.walking === 'false'",
        Duration::from_secs(300),
        "the walk reaching the path's end",
    );
    let end = b.eval("impostorViewer.state().position");
    for (a, want) in path[3].iter().enumerate() {
        let got = end[a].as_f64().unwrap();
        assert!((got - want).abs() < 1e-6, "walk ended at {end}");
    }

    // With a display budget below the scene's triangles the viewer draws
    // the scene simplified, says so, and still switches impostors.
    let scene_triangles: u64 = b
        .eval("impostorViewer.state().sceneTriangles")
        .as_str()
        .unwrap()
        .parse()
        .unwrap();
    assert_eq!(
        b.eval("impostorViewer.state().drawnTriangles"),
        scene_triangles.to_string(),
        "under the default budget the scene is drawn as uploaded"
    );
    assert_eq!(b.eval("!!document.getElementById('decimated')"), false);
    let budget = scene_triangles / 4;
    // (The old viewer renamed, so the wait below cannot see it before the
    // hash change reaches the page's router.)
    b.eval("document.getElementById('viewer').id = 'old-viewer'; true");
    b.navigate(&format!(
        "http://{addr}/#/jobs/{id}/view?triangles={budget}"
    ));
    b.wait_for(
        "(() => { const v = document.getElementById('viewer'); \
                  return v && v.dataset.ready === 'true' && v.dataset.drawnTriangles; })()",
        Duration::from_secs(120),
        "the decimated viewer",
    );
    let state = b.eval("impostorViewer.walkFrame(0, 100)");
    let drawn: u64 = state["drawnTriangles"].as_str().unwrap().parse().unwrap();
    assert_eq!(state["sceneTriangles"], scene_triangles.to_string());
    assert!(
        drawn * 2 < scene_triangles,
        "{drawn} of {scene_triangles} triangles drawn under a budget of {budget}"
    );
    assert_eq!(b.eval("!!document.getElementById('decimated')"), true);
    assert_eq!(state["cpv"], first_cpv, "the first frame's CPV, decimated");
    let pixels = b.eval("impostorViewer.pixels()");
    let total = pixels["width"].as_u64().unwrap() * pixels["height"].as_u64().unwrap();
    assert!(
        pixels["drawn"].as_u64().unwrap() * 20 > total,
        "the decimated scene is not drawn: {pixels}"
    );
    eprintln!("decimated for display: {scene_triangles} -> {drawn} triangles (budget {budget})");

    // The job list shows the job.
    b.navigate(&format!("http://{addr}/#/"));
    let row = b.wait_for(
        &format!(
            "[...document.querySelectorAll('#jobs tr')].find(r => r.innerText.includes('{id}'))?.innerText"
        ),
        Duration::from_secs(30),
        "the job in the list",
    );
    assert!(row.as_str().unwrap().contains("succeeded"), "{row}");
    let problems = b.problems();
    assert!(problems.is_empty(), "the page had errors: {problems:?}");
    drop(b);
    terminate(&mut child, Duration::from_secs(30));
    let _ = std::fs::remove_dir_all(dir);
}

/// Impostors baked as KTX2 (`memory.texture_format`, Basis Universal
/// UASTC with mip levels) load in the viewer through three.js's KTX2Loader
/// and the transcoder the server serves, and cover what their objects did.
/// The scene draws its repeated meshes as GPU instances and is
/// Draco-compressed: the viewer (three.js with Google's Draco decoder)
/// numbers each instance as the optimizer (its own Draco decoder) does,
/// with the same boxes, and hides instances one by one.
#[test]
fn the_viewer_shows_impostors_baked_as_ktx2() {
    let Some(mut b) = Browser::start() else {
        return;
    };
    let (mut child, addr, dir) = spawn("ktx2");
    let scene_path = dir.join("city.glb");
    let scene_glb = instanced_draco_city(&dir);
    std::fs::write(&scene_path, &scene_glb).unwrap();
    let mut job = common::process::small_job();
    job["memory"] = json!({"texture_format": "ktx2"});
    b.navigate(&format!("http://{addr}/#/submit"));
    b.wait_for(
        "!!document.getElementById('scene')",
        Duration::from_secs(30),
        "the submit form",
    );
    let id = submit_through_form(&mut b, &scene_path, &job.to_string());
    let (s, _, glb) = get(addr, &format!("/v1/jobs/{id}/impostors.glb"));
    assert_eq!(s, 200);
    let n = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    let gltf: Value = serde_json::from_slice(&glb[20..20 + n]).unwrap();
    assert_eq!(gltf["extensionsRequired"], json!(["KHR_texture_basisu"]));
    let images = gltf["images"].as_array().unwrap();
    assert!(!images.is_empty());
    assert!(
        images.iter().all(|i| i["mimeType"] == "image/ktx2"),
        "{images:?}"
    );
    let (_, _, placement) = get(addr, &format!("/v1/jobs/{id}/placement"));
    let placement = whole_lists(&placement);

    open_viewer(&mut b);
    // Every atlas arrived as a compressed texture with its mip chain.
    let textures = b.eval("impostorViewer.textures()");
    let textures = textures.as_array().unwrap();
    assert_eq!(textures.len(), images.len(), "{textures:?}");
    for t in textures {
        assert_eq!(t["compressed"], true, "{t}");
        assert!(t["width"].as_u64().unwrap() > 0, "{t}");
        assert!(t["mipmaps"].as_u64().unwrap() > 1, "{t}");
    }
    let instances = b.eval("impostorViewer.objectInstance.filter((k) => k !== null).length");
    assert!(
        instances.as_u64().unwrap() > 100,
        "{instances} GPU instances"
    );
    // Positions quantized to 14 bits over each mesh's bounds.
    assert_object_boxes(&mut b, &scene_glb, 1.0 / f64::from(1 << 14));
    let (cpv, pixels, footprint, mismatch) = footprint_view(&mut b, &placement);
    eprintln!("KTX2: CPV {cpv}: footprint {footprint} of {pixels} pixels, mismatch {mismatch}");
    assert!(
        mismatch * 3 <= footprint,
        "CPV {cpv}: {mismatch} of {footprint} pixels mismatch"
    );
    // Control: the same view with the atlases dropped (the layers drawn as
    // opaque quads) mismatches far more.
    let control = b.eval(
        "impostorViewer.impostorNodes.forEach((nodes) => nodes.forEach((n) => n.traverse((o) => {
           if (o.material) { o.material.map = null; o.material.alphaTest = 0;
                             o.material.transparent = false; o.material.needsUpdate = true; }
         })));
         impostorViewer.footprint()",
    );
    let n = |k: &str| control[k].as_u64().unwrap();
    eprintln!("KTX2 control: {control}");
    assert!(n("mismatch") * 3 > n("footprint"), "{control}");
    let problems = b.problems();
    assert!(problems.is_empty(), "the page had errors: {problems:?}");
    drop(b);
    terminate(&mut child, Duration::from_secs(30));
    let _ = std::fs::remove_dir_all(dir);
}
