//! Helpers: the `impostor` binary, temporary directories, JSON files.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

/// The workspace root.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The `impostor` binary this test was built with.
pub fn impostor() -> &'static Path {
    Path::new(env!("CARGO_BIN_EXE_impostor"))
}

/// Runs `impostor` with `args`.
pub fn run(args: &[&str]) -> Output {
    Command::new(impostor())
        .args(args)
        .output()
        .expect("run impostor")
}

/// Exit code of an output, `-1` when killed.
pub fn code(o: &Output) -> i32 {
    o.status.code().unwrap_or(-1)
}

/// Standard error as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A fresh temporary directory for one test.
pub fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("impostor-e2e-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Reads a JSON file.
pub fn read_json(p: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display())))
        .unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Path as &str.
pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A generated city of the given scale, cached per test process.
pub fn city(scale: &str) -> PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    let dir = DIR.get_or_init(|| tmp("cities"));
    let path = dir.join(format!("city-{scale}.glb"));
    static LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _g = LOCK.lock().unwrap();
    if !path.exists() {
        let o = run(&["gen-city", "--scale", scale, "--seed", "1", "-o", s(&path)]);
        assert_eq!(code(&o), 0, "{}", stderr(&o));
    }
    path
}

/// Asserts that two files are byte-identical; on failure names the first
/// differing line instead of dumping the bytes.
pub fn assert_same_file(a: &Path, b: &Path) {
    let (x, y) = (std::fs::read(a).unwrap(), std::fs::read(b).unwrap());
    if x == y {
        return;
    }
    let (xs, ys) = (String::from_utf8_lossy(&x), String::from_utf8_lossy(&y));
    let line = xs
        .lines()
        .zip(ys.lines())
        .position(|(l, r)| l != r)
        .unwrap_or_else(|| xs.lines().count().min(ys.lines().count()));
    panic!(
        "{} and {} differ at line {}: {:?} vs {:?}",
        a.display(),
        b.display(),
        line + 1,
        xs.lines().nth(line),
        ys.lines().nth(line)
    );
}

/// Runs `impostor place SCENE --job JOB -o OUT` with `extra` arguments.
pub fn place(scene: &Path, job: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["place", s(scene), "--job", s(job), "-o", s(out)];
    args.extend_from_slice(extra);
    run(&args)
}

/// Runs `impostor evaluate SCENE --job JOB --placement P -o OUT --views N`.
pub fn evaluate(scene: &Path, job: &Path, placement: &Path, out: &Path, views: u32) -> Output {
    let views = views.to_string();
    run(&[
        "evaluate",
        s(scene),
        "--job",
        s(job),
        "--placement",
        s(placement),
        "-o",
        s(out),
        "--views",
        &views,
    ])
}
