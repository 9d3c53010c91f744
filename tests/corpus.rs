//! The hostile-input corpus (`tests/corpus/`): every case exits with its
//! expected code and one message naming the problem, never panics and
//! writes no output file.

use crate::util::*;

#[test]
fn every_corpus_case_fails_cleanly() {
    let dir = root().join("tests/corpus");
    let cases = read_json(&dir.join("cases.json"));
    let cases = cases.as_array().expect("a list of cases");
    assert!(cases.len() >= 40, "{} cases", cases.len());
    let work = tmp("corpus");
    let mut failures = Vec::new();
    for (k, c) in cases.iter().enumerate() {
        let name = c["case"].as_str().expect("case name");
        let out = work.join(format!("out-{k}"));
        let args: Vec<String> = c["args"]
            .as_array()
            .expect("args")
            .iter()
            .map(|a| {
                a.as_str()
                    .expect("string arg")
                    .replace("{dir}", s(&dir))
                    .replace("{out}", s(&out))
            })
            .collect();
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = run(&args);
        let err = stderr(&o);
        let want = c["exit"].as_i64().expect("exit") as i32;
        let needle = c["stderr"].as_str().expect("stderr");
        let lines: Vec<&str> = err.lines().filter(|l| l.starts_with("error")).collect();
        if code(&o) != want
            || !err.contains(needle)
            || err.contains("panicked")
            || lines.len() != 1
            || out.exists()
        {
            failures.push(format!(
                "{name}: exit {} (want {want}), output written: {}, stderr: {err}",
                code(&o),
                out.exists()
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
