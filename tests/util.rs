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

/// A fresh temporary directory for one test, under Cargo's directory for
/// integration tests' temporary data: the next run replaces it, so runs do not
/// pile up (a failed test's files stay there to be looked at).
pub fn tmp(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("e2e-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Reads a JSON file.
pub fn read_json(p: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display())))
        .unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// A placement file as JSON with every CPV's impostor list whole (a file may
/// write a list as its change from the one before it), rebuilt by the
/// library's reader.
pub fn read_placement(p: &Path) -> serde_json::Value {
    let mut v = read_json(p);
    optimizer::api::placement::whole_lists(&mut v)
        .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    v
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

/// Runs `impostor bake SCENE --placement P --job JOB -o GLB --report R`.
pub fn bake(scene: &Path, placement: &Path, job: &Path, glb: &Path, report: &Path) -> Output {
    bake_with(scene, placement, job, glb, report, &[])
}

/// [`bake`] with `extra` arguments.
pub fn bake_with(
    scene: &Path,
    placement: &Path,
    job: &Path,
    glb: &Path,
    report: &Path,
    extra: &[&str],
) -> Output {
    let mut args = vec![
        "bake",
        s(scene),
        "--placement",
        s(placement),
        "--job",
        s(job),
        "-o",
        s(glb),
        "--report",
        s(report),
    ];
    args.extend_from_slice(extra);
    run(&args)
}

/// Runs `impostor evaluate SCENE --job JOB --placement P -o OUT --views N`.
pub fn evaluate(scene: &Path, job: &Path, placement: &Path, out: &Path, views: u32) -> Output {
    evaluate_with(scene, job, placement, out, views, &[])
}

/// [`evaluate`] with `extra` arguments.
pub fn evaluate_with(
    scene: &Path,
    job: &Path,
    placement: &Path,
    out: &Path,
    views: u32,
    extra: &[&str],
) -> Output {
    let views = views.to_string();
    let mut args = vec![
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
    ];
    args.extend_from_slice(extra);
    run(&args)
}

/// The figures of a guarantee check and its control.
pub struct Checked {
    /// The evaluation of the placement.
    pub eval: serde_json::Value,
    /// Views over the target, with every impostor removed, where the
    /// placement claims the target (uniform views in solved problem views or
    /// in none, and views sampled inside solved problem views).
    pub control_violations: u64,
}

/// Checks the frame-time guarantee of `placement` with its control:
/// evaluates it (`views` uniform views and as many inside problem views,
/// seed 1, `extra` arguments such as `--pvs`), then the same placement with
/// every impostor stripped, with the same views and seed. Asserts that the
/// stripped placement breaks the target where the placement claims to meet
/// it — in at least `min_share` of the views that lie in solved problem
/// views, so the check could have failed — that the evaluation's own `control`
/// reports the same figures, and that the placement itself breaks nothing.
pub fn check_guarantee(
    scene: &Path,
    job: &Path,
    placement: &Path,
    views: u32,
    min_share: f64,
    extra: &[&str],
) -> Checked {
    let dir = placement.parent().unwrap();
    let name = placement.file_stem().unwrap().to_string_lossy();
    let eval_of = |p: &Path, out: &Path| {
        let views = views.to_string();
        let mut args = vec![
            "evaluate",
            s(scene),
            "--job",
            s(job),
            "--placement",
            s(p),
            "-o",
            s(out),
            "--views",
            &views,
        ];
        args.extend_from_slice(extra);
        let o = run(&args);
        (code(&o), stderr(&o), read_json(out))
    };
    let (c, err, eval) = eval_of(placement, &dir.join(format!("{name}.eval.json")));
    assert_eq!(c, 0, "{}: {err}", placement.display());
    let mut stripped = read_placement(placement);
    for cpv in stripped["cpvs"].as_array_mut().unwrap() {
        cpv["impostors"] = serde_json::json!([]);
    }
    let sp = dir.join(format!("{name}.stripped.json"));
    std::fs::write(&sp, serde_json::to_vec(&stripped).unwrap()).unwrap();
    let (c, err, bare) = eval_of(&sp, &dir.join(format!("{name}.stripped.eval.json")));
    let bare_violations = bare["violations_in_solved"].as_u64().unwrap()
        + bare["violations_in_cpv_views"].as_u64().unwrap();
    let n = |k: &str| bare[k].as_u64().unwrap();
    let in_solved = n("views_in_cpvs") - n("views_in_unsolved_cpvs") + n("cpv_views")
        - n("cpv_views_in_unsolved");
    assert!(
        bare_violations as f64 >= min_share * in_solved as f64 && bare_violations > 0,
        "the control does not fail: without impostors {bare_violations} of {in_solved} views in \
         solved problem views break the target (want at least {:.1} %), so this check proves \
         nothing: {bare}",
        100.0 * min_share
    );
    assert_eq!(c, 4, "the stripped placement must fail the check: {err}");
    // The evaluation's own control is the stripped placement's figures.
    let control = &eval["control"];
    assert_eq!(
        control["violations_in_solved"], bare["violations_in_solved"],
        "{control}"
    );
    assert_eq!(
        control["violations_in_cpv_views"], bare["violations_in_cpv_views"],
        "{control}"
    );
    for k in [
        "violations_in_solved",
        "violations_in_cpv_views",
        "impostors_outside_view_cell",
    ] {
        assert_eq!(eval[k], 0, "{k}: {eval}");
    }
    Checked {
        eval,
        control_violations: bare_violations,
    }
}

/// A scene of `../shared/scenes/` by name (without `.glb`), or `None` with
/// a message when the folder is absent. With `IMPOSTOR_REQUIRE_SCENES` set
/// (as `.ci/run` does) a missing scene is a failure, not a skip.
pub fn shared_scene(name: &str) -> Option<PathBuf> {
    let path = root().join("../shared/scenes").join(format!("{name}.glb"));
    if path.exists() {
        return Some(path);
    }
    assert!(
        std::env::var_os("IMPOSTOR_REQUIRE_SCENES").is_none(),
        "{} is missing and IMPOSTOR_REQUIRE_SCENES is set",
        path.display()
    );
    eprintln!("skipped: {} is absent", path.display());
    None
}
