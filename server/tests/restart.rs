//! Durability: the service binary killed with SIGKILL, or stopped with
//! SIGTERM, mid-job and restarted on the same data directory finishes every
//! accepted job.

use std::net::SocketAddr;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::{Value, json};

mod common;

use common::process::request;

fn spawn(dir: &std::path::Path, addr: SocketAddr) -> Child {
    let child = Command::new(env!("CARGO_BIN_EXE_impostor-server"))
        .args(["--no-auth", "--listen", &addr.to_string(), "--data-dir"])
        .arg(dir)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start impostor-server");
    let start = Instant::now();
    while request(addr, "GET", "/healthz", b"").is_none() {
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "server did not start"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    child
}

/// An empty data folder for test `name` and a free loopback address.
fn fresh(name: &str) -> (std::path::PathBuf, SocketAddr) {
    let dir = std::env::temp_dir().join(format!("impostor-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    (dir, l.local_addr().unwrap())
}

#[test]
fn kill_9_and_restart_finishes_every_job() {
    stop_mid_job_and_restart("restart", |child| {
        child.kill().unwrap(); // SIGKILL
        child.wait().unwrap();
    });
}

/// SIGTERM mid-job (what a service manager sends): the server stops
/// admitting, exits 0, and the job it was running completes after the
/// restart with the command line's bytes.
#[test]
#[cfg(unix)]
fn sigterm_mid_job_and_restart_finishes_every_job() {
    stop_mid_job_and_restart("sigterm-mid-job", |child| {
        let status = terminate(child);
        assert_eq!(status.code(), Some(0), "{status:?}");
    });
}

#[cfg(unix)]
fn terminate(child: &mut Child) -> std::process::ExitStatus {
    common::process::terminate(child, Duration::from_secs(20))
}

/// Submits three jobs, stops the server with `stop` while the first is
/// being placed, restarts it on the same data folder and checks that every
/// job succeeds with the command line's placement bytes.
fn stop_mid_job_and_restart(name: &str, stop: impl FnOnce(&mut Child)) {
    let (dir, addr) = fresh(name);
    let glb = common::city(0.1);
    let scene = optimizer::scene::gltf_load::load_scene_bytes(&glb, "c").unwrap();
    let job_bytes = std::fs::read(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../fixtures/jobs/city-small.json"
    ))
    .unwrap();
    let expected = common::cli_placement(&glb, &job_bytes);
    let body = json!({
        "scene": serde_json::to_value(scene.summary()).unwrap(),
        "job": serde_json::from_slice::<Value>(&job_bytes).unwrap(),
    })
    .to_string();

    let mut child = spawn(&dir, addr);
    let mut ids = Vec::new();
    for _ in 0..3 {
        let (s, b) = request(addr, "POST", "/v1/jobs", body.as_bytes()).unwrap();
        assert_eq!(s, 202, "{}", String::from_utf8_lossy(&b));
        ids.push(
            serde_json::from_slice::<Value>(&b).unwrap()["id"]
                .as_str()
                .unwrap()
                .to_string(),
        );
    }
    // Kill while the first job is being placed (the city-small job takes
    // about a second to place and as long again to evaluate), so the restart
    // must re-run a job that was `running`, not only queued ones.
    let waited = Instant::now();
    loop {
        let (_, b) = request(addr, "GET", &format!("/v1/jobs/{}", ids[0]), b"").unwrap();
        let v: Value = serde_json::from_slice(&b).unwrap();
        if v["state"] == "running" && v["progress"].as_f64().unwrap_or(0.0) > 0.0 {
            break;
        }
        assert!(
            v["state"] == "queued" || v["state"] == "running",
            "job {} ended before the kill: {v}",
            ids[0]
        );
        assert!(
            waited.elapsed() < Duration::from_secs(30),
            "never running: {v}"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    stop(&mut child);

    let mut child = spawn(&dir, addr);
    let start = Instant::now();
    for id in &ids {
        loop {
            let (s, b) = request(addr, "GET", &format!("/v1/jobs/{id}"), b"").unwrap();
            assert_eq!(s, 200);
            let v: Value = serde_json::from_slice(&b).unwrap();
            match v["state"].as_str() {
                Some("succeeded") => break,
                Some("failed" | "cancelled") => panic!("job {id}: {v}"),
                _ => {}
            }
            assert!(
                start.elapsed() < Duration::from_secs(120),
                "job {id} unfinished: {v}"
            );
            std::thread::sleep(Duration::from_millis(100));
        }
        let (s, p) = request(addr, "GET", &format!("/v1/jobs/{id}/placement"), b"").unwrap();
        assert_eq!(s, 200);
        assert!(
            p == expected,
            "job {id}: placement differs after the restart"
        );
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

/// SIGTERM (what a service manager sends) stops an idle server
/// gracefully: it exits 0 instead of dying of the signal.
#[test]
#[cfg(unix)]
fn sigterm_stops_the_server_gracefully() {
    let (dir, addr) = fresh("sigterm");
    let mut child = spawn(&dir, addr);
    let status = terminate(&mut child);
    assert_eq!(status.code(), Some(0), "{status:?}");
    let _ = std::fs::remove_dir_all(&dir);
}
