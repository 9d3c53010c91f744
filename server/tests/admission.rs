//! What the service decides before the work, over a real TCP listener:
//! 401 without a valid token, each tenant sees only its own jobs,
//! per-tenant quotas and rate limits decided from the headers, uploads
//! streamed to disk and removed when refused; and the `token` commands and
//! the `--no-auth` rule of the real binary.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use common::start;
use serde_json::{Value, json};
use server::Config;

mod common;

fn temp_dir(name: &str) -> PathBuf {
    // Under Cargo's directory for tests' temporary data: the next run
    // replaces it, so runs do not pile up.
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("admission-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The files under `dir`, recursively, with their sizes.
fn files(dir: &Path) -> Vec<(PathBuf, u64)> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let m = e.metadata().unwrap();
        if m.is_dir() {
            out.extend(files(&e.path()));
        } else {
            out.push((e.path(), m.len()));
        }
    }
    out
}

/// An upload is written to disk as it arrives, not held in memory: 8 MiB
/// of a scene part are on disk, in the upload's staging folder, while the
/// rest of the body has not been sent. When the submission is refused
/// (its scene is not one), the staging folder is removed and no job is
/// stored.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn uploads_stream_to_disk_and_refused_ones_leave_nothing() {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let dir = temp_dir("stream");
    let addr = start(Config::new(&dir)).await;
    let boundary = "XuploadX";
    let head_part = format!(
        "--{boundary}\r\nContent-Disposition: form-data; name=\"scene\"; filename=\"s.glb\"\r\n\
         Content-Type: application/octet-stream\r\n\r\n"
    );
    let scene = vec![b'x'; 8 << 20];
    let tail = format!(
        "\r\n--{boundary}\r\nContent-Disposition: form-data; name=\"job\"\r\n\r\n{{}}\r\n\
         --{boundary}--\r\n"
    );
    let length = head_part.len() + scene.len() + tail.len();
    let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
    let head = format!(
        "POST /v1/jobs HTTP/1.1\r\nHost: test\r\nConnection: close\r\n\
         Content-Type: multipart/form-data; boundary={boundary}\r\nContent-Length: {length}\r\n\r\n"
    );
    s.write_all(head.as_bytes()).await.unwrap();
    s.write_all(head_part.as_bytes()).await.unwrap();
    s.write_all(&scene).await.unwrap();
    s.flush().await.unwrap();
    let uploads = dir.join("uploads");
    let begin = std::time::Instant::now();
    loop {
        let on_disk: u64 = files(&uploads).iter().map(|f| f.1).sum();
        if on_disk >= (8 << 20) - 65536 {
            break;
        }
        assert!(
            begin.elapsed() < Duration::from_secs(10),
            "{on_disk} bytes of the upload on disk: {:?}",
            files(&uploads)
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    s.write_all(tail.as_bytes()).await.unwrap();
    let mut raw = Vec::new();
    s.read_to_end(&mut raw).await.unwrap();
    let text = String::from_utf8_lossy(&raw);
    assert!(text.starts_with("HTTP/1.1 422"), "{text}");
    // The refused upload is removed (off the request, within moments).
    let begin = std::time::Instant::now();
    while !files(&uploads).is_empty() {
        assert!(
            begin.elapsed() < Duration::from_secs(5),
            "{:?}",
            files(&uploads)
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert!(files(&dir.join("jobs")).is_empty());
}

/// A request with `token` (when given); status, JSON body (or null) and
/// the answer's headers.
async fn call(
    addr: SocketAddr,
    method: &str,
    path: &str,
    token: Option<&str>,
    body: Option<&Value>,
) -> (u16, Value, String) {
    let auth = token.map(|t| format!("Bearer {t}"));
    let headers: Vec<(&str, &str)> = auth
        .as_deref()
        .map(|a| vec![("Authorization", a)])
        .unwrap_or_default();
    let bytes = body.map(|b| b.to_string().into_bytes()).unwrap_or_default();
    let ctype = body.map(|_| "application/json");
    let ((s, b), h) = common::client::request_with(addr, method, path, &headers, ctype, &bytes)
        .await
        .unwrap();
    (s, serde_json::from_slice(&b).unwrap_or(Value::Null), h)
}

/// A small job over the generated city's summary.
fn small_submission() -> Value {
    let summary = common::city_summary(0.1);
    let job: Value = serde_json::from_slice(
        &std::fs::read(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../fixtures/jobs/city-small.json"
        ))
        .unwrap(),
    )
    .unwrap();
    json!({"scene": summary, "job": job})
}

/// A server with a tokens file of two tenants, `a` and `b`; their tokens.
fn two_tenants(name: &str) -> (Config, PathBuf, String, String) {
    let dir = temp_dir(name);
    let tokens = dir.join("tokens.json");
    let a = server::auth::add(&tokens, "a").unwrap();
    let b = server::auth::add(&tokens, "b").unwrap();
    let mut cfg = Config::new(dir.join("data"));
    cfg.tokens = Some(tokens.clone());
    (cfg, tokens, a, b)
}

/// Without a valid token every `/v1` route is 401 (health and the API
/// document stay open); a tenant sees, fetches, follows and deletes only
/// its own jobs (another's is 404, as if it did not exist); ids are
/// random UUIDs; a revoked token is refused within a second or so.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tenants_see_only_their_own_jobs() {
    let (mut cfg, tokens, a, b) = two_tenants("isolation");
    cfg.workers = 0; // jobs stay queued: nothing here needs them to run
    let addr = start(cfg).await;
    let sub = small_submission();

    for (token, what) in [
        (None, "no token"),
        (Some("imp_0000"), "an unknown token"),
        (Some(&a[..a.len() - 1]), "a truncated token"),
    ] {
        for (method, path) in [("GET", "/v1/jobs"), ("POST", "/v1/jobs")] {
            let body = (method == "POST").then_some(&sub);
            let (s, v, h) = call(addr, method, path, token, body).await;
            assert_eq!(s, 401, "{what}, {method} {path}: {v}");
            assert!(h.contains("www-authenticate: bearer"), "{h}");
            assert!(v["error"].as_str().unwrap().contains("token"), "{v}");
        }
    }
    // The wrong scheme is refused too.
    let ((s, _), _) = common::client::request_with(
        addr,
        "GET",
        "/v1/jobs",
        &[("Authorization", &format!("Basic {a}"))],
        None,
        b"",
    )
    .await
    .unwrap();
    assert_eq!(s, 401);
    assert_eq!(call(addr, "GET", "/healthz", None, None).await.0, 200);
    assert_eq!(call(addr, "GET", "/openapi.json", None, None).await.0, 200);

    // Tenant a submits two jobs: random UUIDs, not sequential.
    let mut ids = Vec::new();
    for _ in 0..2 {
        let (s, v, _) = call(addr, "POST", "/v1/jobs", Some(&a), Some(&sub)).await;
        assert_eq!(s, 202, "{v}");
        let id = v["id"].as_str().unwrap().to_string();
        assert!(id.parse::<u64>().is_err(), "{id}");
        assert_eq!(id.len(), 36, "{id}");
        assert_eq!(&id[14..15], "4", "a version 4 UUID: {id}");
        ids.push(id);
    }
    assert_ne!(ids[0], ids[1]);
    let (s, v, _) = call(addr, "POST", "/v1/jobs", Some(&b), Some(&sub)).await;
    assert_eq!(s, 202, "{v}");
    let b_job = v["id"].as_str().unwrap().to_string();

    // Each tenant lists its own jobs only.
    let listed = |v: &Value| -> Vec<String> {
        v["jobs"]
            .as_array()
            .unwrap()
            .iter()
            .map(|j| j["id"].as_str().unwrap().to_string())
            .collect()
    };
    let (_, v, _) = call(addr, "GET", "/v1/jobs", Some(&a), None).await;
    assert_eq!(listed(&v), ids);
    let (_, v, _) = call(addr, "GET", "/v1/jobs", Some(&b), None).await;
    assert_eq!(listed(&v), vec![b_job.clone()]);
    // Nor may b page from a's job.
    let (s, _, _) = call(
        addr,
        "GET",
        &format!("/v1/jobs?after={}", ids[0]),
        Some(&b),
        None,
    )
    .await;
    assert_eq!(s, 400);

    // b cannot see, fetch, follow or delete a's job: 404 everywhere, the
    // same answer as for a job that does not exist.
    let id = &ids[0];
    for (method, path) in [
        ("GET", format!("/v1/jobs/{id}")),
        ("GET", format!("/v1/jobs/{id}/events")),
        ("GET", format!("/v1/jobs/{id}/placement")),
        ("GET", format!("/v1/jobs/{id}/evaluation")),
        ("GET", format!("/v1/jobs/{id}/impostors.glb")),
        ("GET", format!("/v1/jobs/{id}/report")),
        ("GET", format!("/v1/jobs/{id}/scene")),
        ("GET", format!("/v1/jobs/{id}/job")),
        ("DELETE", format!("/v1/jobs/{id}")),
    ] {
        let (s, v, _) = call(addr, method, &path, Some(&b), None).await;
        assert_eq!(s, 404, "{method} {path}: {v}");
        assert_eq!(v["error"], format!("no job {id}"), "{v}");
    }
    // The job is untouched, and its tenant sees it.
    let (s, v, _) = call(addr, "GET", &format!("/v1/jobs/{id}"), Some(&a), None).await;
    assert_eq!((s, v["state"].as_str()), (200, Some("queued")), "{v}");
    let (s, v, _) = call(addr, "GET", &format!("/v1/jobs/{id}/job"), Some(&a), None).await;
    assert_eq!(s, 200, "{v}");
    assert!(v["view_space"].is_object(), "the job as submitted: {v}");
    let (s, v, _) = call(addr, "DELETE", &format!("/v1/jobs/{id}"), Some(&a), None).await;
    assert_eq!((s, v["state"].as_str()), (200, Some("cancelled")), "{v}");

    // A revoked token is refused once the server has looked at the file.
    let entry = server::auth::list(&tokens).unwrap().remove(0);
    assert_eq!(entry.tenant, "a");
    server::auth::revoke(&tokens, &entry.id).unwrap();
    tokio::time::sleep(Duration::from_millis(1100)).await;
    assert_eq!(call(addr, "GET", "/v1/jobs", Some(&a), None).await.0, 401);
    assert_eq!(call(addr, "GET", "/v1/jobs", Some(&b), None).await.0, 200);
}

/// Sends the headers of a submission of `length` bytes with `token` and
/// reads the answer given before any of the body: its status, or `None`
/// when the server waits for the body (nothing within 1 s).
async fn answer_to_headers(addr: SocketAddr, token: &str, length: u64) -> Option<u16> {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
    let head = format!(
        "POST /v1/jobs HTTP/1.1\r\nHost: test\r\nAuthorization: Bearer {token}\r\n\
         Content-Type: application/json\r\nContent-Length: {length}\r\n\r\n"
    );
    s.write_all(head.as_bytes()).await.unwrap();
    let mut raw = vec![0u8; 4096];
    let n = tokio::time::timeout(Duration::from_secs(1), s.read(&mut raw))
        .await
        .ok()?
        .unwrap();
    let text = String::from_utf8_lossy(&raw[..n]).to_string();
    Some(
        text.get(9..12)
            .and_then(|c| c.parse().ok())
            .unwrap_or_else(|| panic!("{text}")),
    )
}

/// `--tenant-max-jobs`: a tenant with its most jobs queued is refused
/// (429, with `Retry-After`) from the headers of a 1 GB upload, before a
/// byte of its body; another tenant's same upload is read (the control),
/// and the tenant may submit again once its job is cancelled.
/// `--rate-limit`: a tenant's requests over the rate are 429 with a
/// `Retry-After`, while another tenant's go through.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tenant_quotas_and_rate_limits() {
    let (mut cfg, _, a, b) = two_tenants("quota");
    cfg.workers = 0;
    cfg.tenant_max_jobs = Some(1);
    cfg.max_upload_mb = 2048;
    let addr = start(cfg).await;
    let sub = small_submission();
    let (s, v, _) = call(addr, "POST", "/v1/jobs", Some(&a), Some(&sub)).await;
    assert_eq!(s, 202, "{v}");
    let id = v["id"].as_str().unwrap().to_string();
    assert_eq!(answer_to_headers(addr, &a, 1 << 30).await, Some(429));
    assert_eq!(answer_to_headers(addr, &b, 1 << 30).await, None);
    let (s, v, h) = call(addr, "POST", "/v1/jobs", Some(&a), Some(&sub)).await;
    assert_eq!(s, 429, "{v}");
    assert!(
        v["error"].as_str().unwrap().contains("--tenant-max-jobs"),
        "{v}"
    );
    assert!(h.contains("retry-after: "), "{h}");
    call(addr, "DELETE", &format!("/v1/jobs/{id}"), Some(&a), None).await;
    let (s, v, _) = call(addr, "POST", "/v1/jobs", Some(&a), Some(&sub)).await;
    assert_eq!(s, 202, "{v}");

    let (mut cfg, _, a, b) = two_tenants("rate");
    cfg.rate_limit = Some(2);
    let addr = start(cfg).await;
    let mut refused = None;
    for i in 0..20 {
        let (s, v, h) = call(addr, "GET", "/v1/jobs", Some(&a), None).await;
        if s == 429 {
            refused = Some((i, v, h));
            break;
        }
        assert_eq!(s, 200, "{v}");
    }
    let (i, v, h) = refused.expect("20 requests at once were never limited");
    assert!(i >= 2, "refused after {i} requests, the burst is 2");
    assert!(v["error"].as_str().unwrap().contains("--rate-limit"), "{v}");
    let wait: u64 = h
        .lines()
        .find_map(|l| l.strip_prefix("retry-after: "))
        .and_then(|w| w.trim().parse().ok())
        .unwrap_or_else(|| panic!("{h}"));
    assert!((1..=2).contains(&wait), "{wait}");
    assert_eq!(call(addr, "GET", "/v1/jobs", Some(&b), None).await.0, 200);
    tokio::time::sleep(Duration::from_secs(wait)).await;
    assert_eq!(call(addr, "GET", "/v1/jobs", Some(&a), None).await.0, 200);
}

fn binary(args: &[&str], tokens: &Path) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_impostor-server"))
        .args(args)
        .arg("--tokens")
        .arg(tokens)
        .output()
        .unwrap()
}

/// The real binary: `token add` prints the token and nothing else, the
/// file keeps no plain token, `token list` shows ids and tenants, `token
/// revoke` removes one; serving needs `--tokens` or `--no-auth`, and
/// `--no-auth` a loopback address.
#[test]
fn token_commands_and_the_no_auth_rule() {
    let dir = temp_dir("binary");
    let tokens = dir.join("tokens.json");
    let out = binary(&["token", "add", "--tenant", "studio"], &tokens);
    assert!(out.status.success(), "{out:?}");
    let stdout = String::from_utf8(out.stdout).unwrap();
    let token = stdout.strip_suffix('\n').unwrap();
    assert!(
        !token.contains('\n') && token.starts_with("imp_"),
        "{stdout:?}"
    );
    assert!(
        !std::fs::read_to_string(&tokens)
            .unwrap()
            .contains(&token[4..])
    );

    let out = binary(&["token", "list"], &tokens);
    let listing = String::from_utf8(out.stdout).unwrap();
    assert!(
        listing.contains("studio") && !listing.contains(&token[4..]),
        "{listing}"
    );
    let id = server::auth::list(&tokens).unwrap()[0].id.clone();
    assert!(listing.contains(&id), "{listing}");

    let out = binary(&["token", "add", "--tenant", "no spaces"], &tokens);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("tenant"));
    let out = binary(&["token", "revoke", "ffffffff"], &tokens);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("no token"));
    assert!(binary(&["token", "revoke", &id], &tokens).status.success());
    assert!(server::auth::list(&tokens).unwrap().is_empty());

    let serve = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_impostor-server"))
            .args(args)
            .arg("--data-dir")
            .arg(dir.join("data"))
            .output()
            .unwrap()
    };
    let out = serve(&["--listen", "127.0.0.1:0"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--tokens"));
    let out = serve(&["--no-auth", "--listen", "0.0.0.0:0"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("loopback"));
    let missing = dir.join("missing.json");
    let out = serve(&[
        "--listen",
        "127.0.0.1:0",
        "--tokens",
        missing.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("token add"));
}
