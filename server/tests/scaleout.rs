//! Scale-out on PostgreSQL: one API process and several worker processes
//! (the real binary), each with a data folder of its own, sharing a
//! database and an artifact store (`--artifacts file://…`); a worker killed
//! with SIGKILL mid-job loses its lease and another runs the job again.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::{Value, json};

mod common;

use common::process::{request, small_job, submit_summary};

const BIN: &str = env!("CARGO_BIN_EXE_impostor-server");

fn get_json(addr: SocketAddr, path: &str) -> (u16, Value) {
    let (s, b) = request(addr, "GET", path, b"").expect("request");
    (s, serde_json::from_slice(&b).unwrap_or(Value::Null))
}

/// The status of job `id` once it has succeeded; fails when it ends
/// otherwise or is still unfinished at `deadline`.
fn succeeded(addr: SocketAddr, id: &str, deadline: Instant) -> Value {
    loop {
        let (s, v) = get_json(addr, &format!("/v1/jobs/{id}"));
        assert_eq!(s, 200, "{v}");
        match v["state"].as_str() {
            Some("succeeded") => return v,
            Some("failed" | "cancelled") => panic!("job {id}: {v}"),
            _ => {}
        }
        assert!(Instant::now() < deadline, "job {id} unfinished: {v}");
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// The artifact store every process of the deployment in `dir` shares.
fn artifacts(dir: &Path) -> String {
    format!("file://{}", dir.join("artifacts").display())
}

fn api(dir: &Path, db: &str, addr: SocketAddr) -> Child {
    let child = Command::new(BIN)
        .args(["--no-auth", "--role", "api", "--listen", &addr.to_string()])
        .args(["--max-queue", "100", "--database", db])
        .args(["--artifacts", &artifacts(dir), "--data-dir"])
        .arg(dir.join("api"))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start the API process");
    let start = Instant::now();
    while request(addr, "GET", "/healthz", b"").is_none() {
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "API did not start"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    child
}

/// A worker process of the deployment in `dir`, with a data folder of its
/// own: what it shares with the others is the database and the artifacts.
fn worker(dir: &Path, db: &str) -> Child {
    static STARTED: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let n = STARTED.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    Command::new(BIN)
        .args(["worker", "--lease-seconds", "2", "--database", db])
        .args(["--artifacts", &artifacts(dir), "--data-dir"])
        .arg(dir.join(format!("worker-{n}")))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start a worker process")
}

/// A database of the tests' PostgreSQL, an empty folder for the
/// deployment's files, an API process on a free loopback port and
/// `workers` worker processes.
fn deploy(name: &str, workers: usize) -> (String, PathBuf, SocketAddr, Child, Vec<Child>) {
    let db = common::postgres::database();
    let dir = std::env::temp_dir().join(format!("impostor-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let addr = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap();
    let api = api(&dir, &db, addr);
    let workers = (0..workers).map(|_| worker(&dir, &db)).collect();
    (db, dir, addr, api, workers)
}

fn terminate(child: &mut Child) -> std::process::ExitStatus {
    common::process::terminate(child, Duration::from_secs(30))
}

/// One API process, three workers, 30 jobs of three kinds; a worker is
/// killed with SIGKILL while it runs a job and a fourth is started. Every
/// job succeeds with the command line's placement bytes, none is recorded
/// as finished twice, and the killed worker's job was run again (the
/// control: the kill did hit a running job).
#[test]
fn workers_on_postgres_finish_every_job_when_one_is_killed() {
    let (db, dir, addr, mut api, mut workers) = deploy("scaleout", 3);

    let glb = common::city(0.1);
    let scene = optimizer::scene::gltf_load::load_scene_bytes(&glb, "c").unwrap();
    let summary = serde_json::to_value(scene.summary()).unwrap();
    let base = small_job();
    let kinds: Vec<(Vec<u8>, Vec<u8>)> = [None, Some(5.0), Some(7.0)]
        .iter()
        .map(|target| {
            let mut job = base.clone();
            if let Some(t) = target {
                job["target_frame_time_ms"] = json!(t);
            }
            let body = json!({"scene": summary, "job": job}).to_string();
            let bytes = serde_json::to_vec(&job).unwrap();
            (body.into_bytes(), common::cli_placement(&glb, &bytes))
        })
        .collect();
    let mut ids = Vec::new();
    for i in 0..30 {
        let (s, b) = request(addr, "POST", "/v1/jobs", &kinds[i % 3].0).unwrap();
        assert_eq!(s, 202, "{}", String::from_utf8_lossy(&b));
        let v: Value = serde_json::from_slice(&b).unwrap();
        ids.push(v["id"].as_str().unwrap().to_string());
    }

    // Kill the first worker while it runs a job.
    let mut pg = postgres::Client::connect(&db, postgres::NoTls).unwrap();
    let victim = workers[0].id();
    let waited = Instant::now();
    let killed_job: i64 = loop {
        let rows = pg
            .query(
                "SELECT id FROM jobs WHERE state = 'running' AND progress > 0
                 AND lease_owner LIKE $1",
                &[&format!("%:{victim}:%")],
            )
            .unwrap();
        if let Some(r) = rows.first() {
            break r.get(0);
        }
        assert!(
            waited.elapsed() < Duration::from_secs(60),
            "the first worker never ran a job"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    workers[0].kill().unwrap(); // SIGKILL
    workers[0].wait().unwrap();
    workers.push(worker(&dir, &db));

    let deadline = Instant::now() + Duration::from_secs(300);
    for id in &ids {
        succeeded(addr, id, deadline);
    }
    for (i, id) in ids.iter().enumerate() {
        let (s, p) = request(addr, "GET", &format!("/v1/jobs/{id}/placement"), b"").unwrap();
        assert_eq!(s, 200);
        assert!(
            p == kinds[i % 3].1,
            "job {id}: not the command line's bytes"
        );
    }
    // No job is recorded as finished twice; the killed one ran again.
    let rows = pg
        .query(
            "SELECT id, completions, attempts FROM jobs ORDER BY id",
            &[],
        )
        .unwrap();
    assert_eq!(rows.len(), 30);
    for r in &rows {
        let (id, completions, attempts): (i64, i64, i64) = (r.get(0), r.get(1), r.get(2));
        assert_eq!(completions, 1, "job {id} finished {completions} times");
        if id == killed_job {
            assert!(
                attempts >= 2,
                "job {id}, killed mid-run, ran {attempts} times"
            );
        }
    }
    // The metrics see the finished jobs and the live workers.
    let (s, text) = request(addr, "GET", "/metrics", b"").unwrap();
    assert_eq!(s, 200);
    let text = String::from_utf8(text).unwrap();
    let metric = |name: &str| -> f64 {
        text.lines()
            .find_map(|l| l.strip_prefix(name)?.strip_prefix(' ')?.parse().ok())
            .unwrap_or_else(|| panic!("no {name} in {text}"))
    };
    assert_eq!(metric("impostor_queue_depth"), 0.0);
    assert_eq!(metric("impostor_jobs_running"), 0.0);
    assert_eq!(metric("impostor_jobs{state=\"succeeded\"}"), 30.0);
    assert_eq!(metric("impostor_job_duration_seconds_count"), 30.0);
    assert!(metric("impostor_workers") >= 3.0, "{text}");

    // SIGTERM stops a worker gracefully.
    for w in workers.iter_mut().skip(1) {
        let status = terminate(w);
        assert_eq!(status.code(), Some(0), "{status:?}");
    }
    api.kill().unwrap();
    api.wait().unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

/// A tiled job (2 × 2) runs as one job per tile, claimed by any worker,
/// then a merge once every tile is final: its placement is the command
/// line's for the same tiled job, byte for byte, and keeps the guarantee;
/// the listing shows the job, not its tiles.
#[test]
fn a_tiled_job_runs_its_tiles_on_the_workers_and_merges_them() {
    let (db, dir, addr, mut api, mut workers) = deploy("tiled", 2);
    let glb = common::city(0.1);
    let mut job = small_job();
    job["partition"] = json!({"tiles": [2, 2]});
    let expected = common::cli_placement(&glb, &serde_json::to_vec(&job).unwrap());
    let id = submit_summary(addr, &glb, &job);
    let status = succeeded(addr, &id, Instant::now() + Duration::from_secs(120));
    let (s, p) = request(addr, "GET", &format!("/v1/jobs/{id}/placement"), b"").unwrap();
    assert_eq!(s, 200);
    assert!(
        p == expected,
        "the merged placement is not the command line's"
    );
    assert_eq!(status["summary"]["violations_in_solved"], 0, "{status}");
    assert_eq!(status["summary"]["violations_in_cpv_views"], 0, "{status}");
    let (_, list) = get_json(addr, "/v1/jobs");
    assert_eq!(list["jobs"].as_array().unwrap().len(), 1, "{list}");
    // The files are in the shared store (the job's and its four tiles'),
    // none in a process's own folder.
    let stored: Vec<_> = std::fs::read_dir(dir.join("artifacts"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(stored.len(), 5);
    // The tiles are placed only: the merge alone is evaluated and reported.
    let evaluated = stored
        .iter()
        .filter(|d| d.join("evaluation.json").exists())
        .count();
    assert_eq!(evaluated, 1, "{stored:?}");
    assert_eq!(
        stored
            .iter()
            .filter(|d| d.join("placement.json").exists())
            .count(),
        5
    );
    assert!(!dir.join("api").join("jobs").exists());
    let mut pg = postgres::Client::connect(&db, postgres::NoTls).unwrap();
    let rows = pg
        .query(
            "SELECT c.state, c.completions FROM jobs c JOIN jobs p ON c.parent_id = p.id
             WHERE p.uid = $1",
            &[&id],
        )
        .unwrap();
    assert_eq!(rows.len(), 4);
    for r in &rows {
        assert_eq!(r.get::<_, String>(0), "succeeded");
        assert_eq!(r.get::<_, i64>(1), 1);
    }
    for w in &mut workers {
        assert_eq!(terminate(w).code(), Some(0));
    }
    api.kill().unwrap();
    api.wait().unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

/// A worker that stalls past its lease (SIGSTOP) while its job runs loses
/// the job to another worker; resumed (SIGCONT) while that one runs it, it
/// finds the lease gone and records nothing: the job is finished once.
#[test]
fn a_stalled_worker_loses_its_job_and_records_nothing() {
    let (db, dir, addr, mut api, mut workers) = deploy("stalled", 1);
    let glb = common::city(0.1);
    let job = small_job();
    let id = submit_summary(addr, &glb, &job);
    let mut pg = postgres::Client::connect(&db, postgres::NoTls).unwrap();
    let waited = Instant::now();
    while pg
        .query(
            "SELECT 1 FROM jobs WHERE state = 'running' AND progress > 0",
            &[],
        )
        .unwrap()
        .is_empty()
    {
        assert!(waited.elapsed() < Duration::from_secs(60), "never running");
        std::thread::sleep(Duration::from_millis(20));
    }
    let signal = |sig: &str, pid: u32| {
        let ok = Command::new("kill")
            .args([sig, &pid.to_string()])
            .status()
            .is_ok_and(|s| s.success());
        assert!(ok, "kill {sig}");
    };
    let stalled = workers[0].id();
    signal("-STOP", stalled);
    workers.push(worker(&dir, &db));
    // Resumed while the second worker runs the job: its next renewal finds
    // the lease taken (without the owner checks both runs would finish).
    while pg
        .query("SELECT 1 FROM jobs WHERE attempts = 2", &[])
        .unwrap()
        .is_empty()
    {
        assert!(
            waited.elapsed() < Duration::from_secs(60),
            "never claimed again"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    signal("-CONT", stalled);
    succeeded(addr, &id, Instant::now() + Duration::from_secs(120));
    std::thread::sleep(Duration::from_secs(8));
    let r = pg
        .query_one("SELECT completions, attempts, state FROM jobs", &[])
        .unwrap();
    let (completions, attempts, state): (i64, i64, String) = (r.get(0), r.get(1), r.get(2));
    assert_eq!(attempts, 2, "the second worker ran it again");
    assert_eq!(completions, 1, "recorded as finished {completions} times");
    assert_eq!(state, "succeeded");
    for w in &mut workers {
        assert_eq!(terminate(w).code(), Some(0));
    }
    api.kill().unwrap();
    api.wait().unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

/// A worker needs a shared PostgreSQL database: given SQLite (or nothing
/// a worker can share), it exits 2 naming the fix.
#[test]
fn a_worker_refuses_a_database_it_cannot_share() {
    let out = Command::new(BIN)
        .args(["worker", "--database", "sqlite:/tmp/x.sqlite"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("postgres://"), "{err}");
}

/// An artifact store the server cannot use is refused at the start, exit
/// 2, naming the option and what it takes.
#[test]
fn an_unusable_artifact_store_is_refused_at_the_start() {
    let dir = std::env::temp_dir().join(format!("impostor-badart-{}", std::process::id()));
    let file = dir.join("a-file");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(&file, b"x").unwrap();
    let file_url = format!("file://{}", file.display());
    for (url, says) in [
        ("gs://bucket/jobs", "unsupported scheme"),
        ("s3:///jobs", "no bucket"),
        (file_url.as_str(), "artifacts folder"),
    ] {
        let out = Command::new(BIN)
            .args(["--no-auth", "--listen", "127.0.0.1:0", "--artifacts", url])
            .arg("--data-dir")
            .arg(dir.join("data"))
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "{url}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(says), "{url}: {err}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
