//! A real PostgreSQL server for the tests: Debian's `postgresql` package
//! (`initdb` and `pg_ctl` under `/usr/lib/postgresql/<version>/bin`, or on
//! the `PATH`), a cluster in a temporary folder, listening on a free
//! loopback port, run as a non-root user (`postgres` when the tests run as
//! root: PostgreSQL refuses to run as root). One cluster per test process,
//! started on first use; each caller gets a database of its own. A watcher
//! process stops the cluster and removes its folder when the test process
//! exits, however it exits.
//!
//! `tools/install-test-deps.sh` (run by the README's test command)
//! installs the package; without it these tests fail, naming the script.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;
use std::sync::atomic::{AtomicU32, Ordering};

struct Cluster {
    port: u16,
    /// Outlives this process on purpose (it stops the cluster after it).
    _watcher: std::process::Child,
}

static CLUSTER: OnceLock<Cluster> = OnceLock::new();
static NEXT_DB: AtomicU32 = AtomicU32::new(0);

/// The folder of PostgreSQL's server programs.
fn bin_dir() -> PathBuf {
    let mut found: Vec<PathBuf> = std::fs::read_dir("/usr/lib/postgresql")
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path().join("bin"))
        .filter(|p| p.join("initdb").exists() && p.join("pg_ctl").exists())
        .collect();
    // The newest version (folders are version numbers).
    found.sort_by_key(|p| {
        p.parent()
            .and_then(|v| v.file_name()?.to_str()?.parse::<u32>().ok())
            .unwrap_or(0)
    });
    if let Some(p) = found.pop() {
        return p;
    }
    let on_path = Command::new("sh")
        .args(["-c", "command -v initdb"])
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string());
    match on_path {
        Some(p) if !p.is_empty() => Path::new(&p)
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_default(),
        _ => panic!(
            "PostgreSQL's server programs (initdb, pg_ctl) are not installed: run \
             tools/install-test-deps.sh (Debian's postgresql package)"
        ),
    }
}

/// Whether this process runs as root.
fn is_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .map(|o| String::from_utf8_lossy(&o.stdout).trim() == "0")
        .unwrap_or(false)
}

/// Runs `program args` as the cluster's user: `postgres` when root.
fn as_user(program: &Path, args: &[&str]) -> Command {
    if is_root() {
        let mut c = Command::new("runuser");
        c.args(["-u", "postgres", "--"]).arg(program).args(args);
        c
    } else {
        let mut c = Command::new(program);
        c.args(args);
        c
    }
}

fn start_cluster() -> Cluster {
    let bin = bin_dir();
    let root = std::env::temp_dir().join(format!("impostor-pg-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    std::fs::create_dir_all(&root).unwrap();
    if is_root() {
        let ok = Command::new("chown")
            .args(["-R", "postgres:"])
            .arg(&root)
            .status()
            .is_ok_and(|s| s.success());
        assert!(ok, "cannot give {} to the postgres user", root.display());
    }
    let data = root.join("data");
    let data_s = data.to_string_lossy().to_string();
    let out = as_user(
        &bin.join("initdb"),
        &[
            "-D",
            &data_s,
            "-U",
            "impostor",
            "--auth=trust",
            "-E",
            "UTF8",
            "--no-sync",
        ],
    )
    .stdout(Stdio::null())
    .output()
    .expect("run initdb");
    assert!(
        out.status.success(),
        "initdb failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let opts = format!(
        "-p {port} -k {} -c listen_addresses=127.0.0.1 -c fsync=off -c max_connections=200",
        root.display()
    );
    let log = root.join("log").to_string_lossy().to_string();
    let out = as_user(
        &bin.join("pg_ctl"),
        &["-D", &data_s, "-o", &opts, "-l", &log, "-w", "start"],
    )
    .stdout(Stdio::null())
    .output()
    .expect("run pg_ctl");
    assert!(
        out.status.success(),
        "pg_ctl start failed: {} {}",
        String::from_utf8_lossy(&out.stderr),
        std::fs::read_to_string(&log).unwrap_or_default()
    );
    // Stops the cluster once this process is gone.
    let stop = format!(
        "while [ -d /proc/{pid} ]; do sleep 0.5; done; {ctl} -D {data_s} -m immediate stop; \
         rm -rf {root}",
        pid = std::process::id(),
        ctl = bin.join("pg_ctl").display(),
        root = root.display(),
    );
    let watcher = if is_root() {
        Command::new("runuser")
            .args(["-u", "postgres", "--", "sh", "-c", &stop])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
    } else {
        Command::new("sh")
            .args(["-c", &stop])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
    };
    Cluster {
        port,
        _watcher: watcher.expect("start the cluster's watcher"),
    }
}

/// The URL of a new, empty database of the test process's cluster.
pub fn database() -> String {
    let c = CLUSTER.get_or_init(start_cluster);
    let name = format!("t{}", NEXT_DB.fetch_add(1, Ordering::SeqCst));
    let admin = format!("postgres://impostor@127.0.0.1:{}/postgres", c.port);
    let mut client = postgres::Client::connect(&admin, postgres::NoTls).unwrap_or_else(|e| {
        let log = std::env::temp_dir().join(format!("impostor-pg-{}/log", std::process::id()));
        panic!(
            "cannot connect to the tests' PostgreSQL ({admin}): {e}\n{}",
            std::fs::read_to_string(log).unwrap_or_default()
        )
    });
    client
        .batch_execute(&format!("CREATE DATABASE {name}"))
        .expect("create database");
    format!("postgres://impostor@127.0.0.1:{}/{name}", c.port)
}

/// The backend the service tests run on: `IMPOSTOR_TEST_DATABASE=postgres`
/// gives each server a database of this process's PostgreSQL cluster;
/// otherwise SQLite in its data folder.
pub fn database_for_tests() -> Option<String> {
    match std::env::var("IMPOSTOR_TEST_DATABASE").as_deref() {
        Ok("postgres") => Some(database()),
        Ok("sqlite") | Err(_) => None,
        Ok(other) => panic!("IMPOSTOR_TEST_DATABASE must be postgres or sqlite, not {other:?}"),
    }
}
