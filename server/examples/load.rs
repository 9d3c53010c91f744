//! Status-route latency under load while jobs run and uploads are refused
//! (loopback only, bounded in count and time):
//!
//! ```sh
//! cargo run --release -p server --example load [-- RATE SECONDS]
//! ```
//!
//! Starts the service on 127.0.0.1 with a tokens file (every request
//! carries a token), a temporary data directory, two
//! workers and room for one waiting job, submits the full-scale generated
//! city with the reference job three times (two run, one waits: the queue
//! is full), then for `SECONDS` (default 10) sends `RATE` (default 200)
//! `GET /v1/jobs/{id}` requests per second and 20 uploads of the city's
//! summary (each refused with 429), and prints the status latency
//! percentiles, the uploads' answers and the process's peak resident memory
//! over the window.

use std::time::{Duration, Instant};

use serde_json::{Value, json};
use server::{AppState, Config, run};

#[path = "../tests/common/client.rs"]
#[allow(dead_code)] // the example sends every request with its token
mod client;

/// The API token every request carries (the service runs with tokens).
static TOKEN: std::sync::OnceLock<String> = std::sync::OnceLock::new();

/// One request with the token; status and body.
async fn request(
    addr: std::net::SocketAddr,
    method: &str,
    path: &str,
    ctype: Option<&str>,
    body: &[u8],
) -> std::io::Result<(u16, Vec<u8>)> {
    let auth = format!("Bearer {}", TOKEN.get().map_or("", String::as_str));
    let headers = [("Authorization", auth.as_str())];
    Ok(
        client::request_with(addr, method, path, &headers, ctype, body)
            .await?
            .0,
    )
}

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() -> std::io::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let rate: u64 = args
        .get(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(200)
        .clamp(1, 2000);
    let seconds: u64 = args
        .get(2)
        .and_then(|a| a.parse().ok())
        .unwrap_or(10)
        .clamp(1, 60);
    let dir = std::env::temp_dir().join(format!("impostor-load-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let tokens = std::env::temp_dir().join(format!("impostor-load-{}.json", std::process::id()));
    let _ = TOKEN.set(server::auth::add(&tokens, "load")?);
    let mut cfg = Config::new(&dir);
    cfg.tokens = Some(tokens.clone());
    cfg.workers = 2;
    cfg.max_queue = 1;
    let state = AppState::open(cfg)?;
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
    let addr = listener.local_addr()?;
    tokio::spawn(run(listener, state, std::future::pending()));

    let glb = optimizer::citygen::generate(&optimizer::citygen::CityParams {
        seed: 1,
        scale: 1.0,
        lod: false,
        ..Default::default()
    })
    .map_err(std::io::Error::other)?;
    let scene = optimizer::scene::gltf_load::load_scene_bytes(&glb, "city")
        .map_err(std::io::Error::other)?;
    let job: Value = serde_json::from_slice(&std::fs::read(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../fixtures/jobs/vienna-reference.json"
    ))?)?;
    let body = json!({"scene": serde_json::to_value(scene.summary())?, "job": job}).to_string();
    let mut ids = Vec::new();
    for _ in 0..3 {
        let (status, b) = request(
            addr,
            "POST",
            "/v1/jobs",
            Some("application/json"),
            body.as_bytes(),
        )
        .await?;
        assert_eq!(status, 202, "{}", String::from_utf8_lossy(&b));
        ids.push(
            serde_json::from_slice::<Value>(&b)?["id"]
                .as_str()
                .ok_or_else(|| std::io::Error::other("the answer has no job id"))?
                .to_string(),
        );
        // Let a worker take it, so that the third one waits.
        tokio::time::sleep(Duration::from_millis(300)).await;
    }
    let path = format!("/v1/jobs/{}", ids[0]);

    // 20 uploads over the window, each refused while the queue is full.
    let body = std::sync::Arc::new(body);
    let uploads: Vec<_> = (0..20u64)
        .map(|k| {
            let body = body.clone();
            tokio::spawn(async move {
                tokio::time::sleep(Duration::from_millis(k * seconds * 1000 / 20)).await;
                let r = request(
                    addr,
                    "POST",
                    "/v1/jobs",
                    Some("application/json"),
                    body.as_bytes(),
                )
                .await;
                r.map(|(s, _)| s).unwrap_or(0)
            })
        })
        .collect();
    // The process's resident memory, sampled over the window.
    let sampling = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(true));
    let sampler = {
        let sampling = sampling.clone();
        tokio::spawn(async move {
            let mut peak = 0u64;
            while sampling.load(std::sync::atomic::Ordering::Relaxed) {
                peak = peak.max(optimizer::place::current_rss_bytes());
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
            peak
        })
    };

    let mut tick = tokio::time::interval(Duration::from_micros(1_000_000 / rate));
    let mut tasks = Vec::new();
    let start = Instant::now();
    for _ in 0..rate * seconds {
        tick.tick().await;
        let path = path.clone();
        tasks.push(tokio::spawn(async move {
            let t = Instant::now();
            let r = request(addr, "GET", &path, None, b"").await;
            (t.elapsed(), r.map(|(s, _)| s).unwrap_or(0))
        }));
    }
    let mut lat = Vec::new();
    let mut failed = 0;
    for t in tasks {
        let (d, s) = t.await.map_err(std::io::Error::other)?;
        if s != 200 {
            failed += 1;
        }
        lat.push(d.as_secs_f64() * 1e3);
    }
    let elapsed = start.elapsed().as_secs_f64();
    let mut refused = 0;
    let mut other = Vec::new();
    for u in uploads {
        match u.await.map_err(std::io::Error::other)? {
            429 => refused += 1,
            s => other.push(s),
        }
    }
    sampling.store(false, std::sync::atomic::Ordering::Relaxed);
    let peak = sampler.await.map_err(std::io::Error::other)?;
    lat.sort_by(f64::total_cmp);
    let pct = |p: f64| lat[((lat.len() - 1) as f64 * p).round() as usize];
    let (_, b) = request(addr, "GET", &path, None, b"").await?;
    let v: Value = serde_json::from_slice(&b)?;
    println!(
        "{} requests in {elapsed:.1} s ({:.0}/s), {failed} failed: p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms; job {} at stage {} ({:.0} %)",
        lat.len(),
        lat.len() as f64 / elapsed,
        pct(0.5),
        pct(0.99),
        lat[lat.len() - 1],
        v["state"],
        v["stage"],
        v["progress"].as_f64().unwrap_or(0.0) * 100.0
    );
    println!(
        "uploads ({} bytes each): {refused} of 20 refused with 429{}; peak resident memory {:.0} MB",
        body.len(),
        if other.is_empty() {
            String::new()
        } else {
            format!(", others answered {other:?}")
        },
        peak as f64 / 1e6
    );
    for id in &ids {
        let _ = request(addr, "DELETE", &format!("/v1/jobs/{id}"), None, b"").await;
    }
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_file(&tokens);
    Ok(())
}
