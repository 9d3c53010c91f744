//! Helpers for the tests that run the real `impostor-server` binary as
//! child processes: a blocking HTTP request and a graceful stop.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::process::{Child, Command};
use std::time::{Duration, Instant};

/// One blocking HTTP/1.1 request (`Connection: close`, a JSON body when
/// `body` is not empty); `None` when the server does not answer.
pub fn request(addr: SocketAddr, method: &str, path: &str, body: &[u8]) -> Option<(u16, Vec<u8>)> {
    let mut s = TcpStream::connect_timeout(&addr, Duration::from_secs(2)).ok()?;
    let ctype = if body.is_empty() {
        ""
    } else {
        "Content-Type: application/json\r\n"
    };
    let head = format!(
        "{method} {path} HTTP/1.1\r\nHost: t\r\nConnection: close\r\n{ctype}Content-Length: {}\r\n\r\n",
        body.len()
    );
    s.write_all(head.as_bytes()).ok()?;
    s.write_all(body).ok()?;
    let mut raw = Vec::new();
    s.read_to_end(&mut raw).ok()?;
    let split = raw.windows(4).position(|w| w == b"\r\n\r\n")?;
    let status = std::str::from_utf8(&raw[9..12]).ok()?.parse().ok()?;
    Some((status, raw[split + 4..].to_vec()))
}

/// Sends SIGTERM to `child` and waits (at most `limit`) for it to exit;
/// kills it and fails past that.
pub fn terminate(child: &mut Child, limit: Duration) -> std::process::ExitStatus {
    let sent = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .expect("run kill");
    assert!(sent.success());
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            return status;
        }
        if start.elapsed() > limit {
            child.kill().unwrap();
            panic!("the process did not stop within {limit:?} of SIGTERM");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The small city job (`fixtures/jobs/city-small.json`) as JSON.
pub fn small_job() -> serde_json::Value {
    serde_json::from_slice(
        &std::fs::read(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../fixtures/jobs/city-small.json"
        ))
        .expect("the small city job"),
    )
    .expect("the small city job is JSON")
}

/// Submits the summary of the GLB scene `glb` with `job` as one JSON body
/// and returns the new job's id (the submission must be accepted).
pub fn submit_summary(addr: SocketAddr, glb: &[u8], job: &serde_json::Value) -> String {
    let scene = optimizer::scene::gltf_load::load_scene_bytes(glb, "scene").expect("a GLB");
    let body = serde_json::json!({
        "scene": serde_json::to_value(scene.summary()).expect("a summary"),
        "job": job,
    });
    let (s, b) = request(addr, "POST", "/v1/jobs", body.to_string().as_bytes()).expect("request");
    assert_eq!(s, 202, "{}", String::from_utf8_lossy(&b));
    serde_json::from_slice::<serde_json::Value>(&b).expect("JSON")["id"]
        .as_str()
        .expect("an id")
        .to_string()
}
