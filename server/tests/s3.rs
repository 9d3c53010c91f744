//! The artifact store on an S3-compatible server: the real binary with
//! `--artifacts s3://bucket/prefix`, against moto's S3 server on a loopback
//! port (`tools/install-test-deps.sh` installs it in `target/test-venv`).
//! The job files are objects in the bucket, a result is served from there
//! with the command line's bytes, a deletion removes them, and a store
//! that stops answering makes `/healthz` answer 503.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

mod common;

use common::process::{request, small_job, submit_summary};

const BIN: &str = env!("CARGO_BIN_EXE_impostor-server");

fn free_addr() -> SocketAddr {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
}

fn wait_until(what: &str, mut ready: impl FnMut() -> bool) {
    let start = Instant::now();
    while !ready() {
        assert!(start.elapsed() < Duration::from_secs(60), "{what}");
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// The command that starts moto's S3 server: the project's virtual
/// environment's Python (`target/test-venv`, still valid when the folder
/// moves, unlike its scripts' first lines), or `moto_server` on the `PATH`.
fn moto_server() -> Command {
    let python = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../target/test-venv/bin/python"
    ));
    if python.exists() {
        let mut c = Command::new(python);
        c.args(["-m", "moto.server"]);
        return c;
    }
    let on_path = Command::new("sh")
        .args(["-c", "command -v moto_server"])
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .unwrap_or_default();
    assert!(
        !on_path.is_empty(),
        "moto's S3 server is not installed: run tools/install-test-deps.sh"
    );
    Command::new(on_path)
}

/// The keys of the bucket's objects (a ListObjectsV2 answer's `<Key>`s).
fn keys(s3: SocketAddr, bucket: &str) -> Vec<String> {
    let (status, body) = request(s3, "GET", &format!("/{bucket}?list-type=2"), b"").unwrap();
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    let text = String::from_utf8_lossy(&body);
    let mut keys: Vec<String> = text
        .split("<Key>")
        .skip(1)
        .filter_map(|k| Some(k.split_once("</Key>")?.0.to_string()))
        .collect();
    keys.sort();
    keys
}

struct Killed(Child);

impl Drop for Killed {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[test]
fn job_files_live_in_an_s3_bucket() {
    let s3 = free_addr();
    let moto = Killed(
        moto_server()
            .args(["-H", "127.0.0.1", "-p", &s3.port().to_string()])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("start moto's S3 server"),
    );
    wait_until("the S3 server did not start", || {
        request(s3, "GET", "/", b"").is_some()
    });
    let (status, _) = request(s3, "PUT", "/jobs", b"").unwrap();
    assert_eq!(status, 200, "bucket created");

    let dir = std::env::temp_dir().join(format!("impostor-s3-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let addr = free_addr();
    let server = Killed(
        Command::new(BIN)
            .args(["--no-auth", "--listen", &addr.to_string()])
            .args(["--artifacts", "s3://jobs/deployment-a", "--data-dir"])
            .arg(&dir)
            .env("AWS_ENDPOINT", format!("http://{s3}"))
            .env("AWS_ALLOW_HTTP", "true")
            .env("AWS_REGION", "us-east-1")
            .env("AWS_ACCESS_KEY_ID", "test")
            .env("AWS_SECRET_ACCESS_KEY", "test")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("start the server"),
    );
    wait_until("the server did not start", || {
        request(addr, "GET", "/healthz", b"").is_some_and(|(s, _)| s == 200)
    });
    let (_, health) = request(addr, "GET", "/healthz", b"").unwrap();
    let health: Value = serde_json::from_slice(&health).unwrap();
    assert_eq!(health["artifacts"], "s3", "{health}");

    let glb = common::city(0.1);
    let job = small_job();
    let expected = common::cli_placement(&glb, &serde_json::to_vec(&job).unwrap());
    let id = submit_summary(addr, &glb, &job);
    wait_until("the job did not succeed", || {
        let (_, v) = request(addr, "GET", &format!("/v1/jobs/{id}"), b"").unwrap();
        let v: Value = serde_json::from_slice(&v).unwrap();
        assert!(v["state"] != "failed", "{v}");
        v["state"] == "succeeded"
    });
    let (s, placement) = request(addr, "GET", &format!("/v1/jobs/{id}/placement"), b"").unwrap();
    assert_eq!(s, 200);
    assert!(placement == expected, "not the command line's placement");
    // The inputs and results are the bucket's objects, under the prefix;
    // the server's own folder holds none of them.
    let stored = keys(s3, "jobs");
    for name in [
        "job.json",
        "scene",
        "placement.json",
        "evaluation.json",
        "report.html",
    ] {
        assert!(
            stored
                .iter()
                .any(|k| k.starts_with("deployment-a/") && k.ends_with(name)),
            "{name} not in {stored:?}"
        );
    }
    assert!(!dir.join("jobs").exists());

    let (s, _) = request(addr, "DELETE", &format!("/v1/jobs/{id}"), b"").unwrap();
    assert_eq!(s, 200);
    assert_eq!(
        keys(s3, "jobs"),
        Vec::<String>::new(),
        "deleted with the job"
    );

    // The control: with the store gone, the health check says so.
    drop(moto);
    let (s, b) = request(addr, "GET", "/healthz", b"").unwrap();
    assert_eq!(s, 503, "{}", String::from_utf8_lossy(&b));
    assert!(String::from_utf8_lossy(&b).contains("artifact store"));
    drop(server);
    let _ = std::fs::remove_dir_all(&dir);
}
