//! The house rules of the code, checked: the optimizer's modules form
//! layers that depend only downward (no cycles), nothing but the report
//! (and the CLI and the server, other crates) imports the evaluation, and no
//! source file grows past the size a reader can hold.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use crate::util::root;

/// The optimizer's top-level modules, lowest layer first. A module may use
/// the modules of lower layers and its own; `evaluate`, the independent
/// oracle, sits above everything it checks, so no stage can lean on it.
const LAYERS: &[&[&str]] = &[
    &["error", "control", "files", "sysmem"],
    &["math"],
    &["api"],
    &["scene"],
    &["model"],
    &["render"],
    &["visibility"],
    &["input"],
    &["views"],
    &["candidates"],
    &["greedy"],
    &["methods"],
    &["place"],
    &["bake"],
    &["export"],
    &["evaluate"],
    &["report"],
    &["citygen"],
    &["testutil"],
];

/// Items of the crate root (`lib.rs`) that any module may use.
const ROOT_ITEMS: &[&str] = &["Error", "Result", "VERSION", "to_json_bytes"];

fn layer(module: &str) -> Option<usize> {
    LAYERS.iter().position(|l| l.contains(&module))
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The source without comments and without `#[cfg(test)]` items (their
/// braces matched), so only what the library compiles to is checked.
fn library_code(text: &str) -> String {
    let no_comments: String = text
        .lines()
        .map(|l| match l.find("//") {
            Some(i) => &l[..i],
            None => l,
        })
        .collect::<Vec<_>>()
        .join("\n");
    let mut out = String::new();
    let mut rest = no_comments.as_str();
    while let Some(i) = rest.find("#[cfg(test)]") {
        out.push_str(&rest[..i]);
        let after = &rest[i..];
        let Some(open) = after.find(['{', ';']) else {
            rest = "";
            break;
        };
        if after.as_bytes()[open] == b';' {
            rest = &after[open + 1..];
            continue;
        }
        let mut depth = 0usize;
        let mut end = after.len();
        for (k, c) in after[open..].char_indices() {
            match c {
                '{' => depth += 1,
                '}' => {
                    depth -= 1;
                    if depth == 0 {
                        end = open + k + 1;
                        break;
                    }
                }
                _ => {}
            }
        }
        rest = &after[end..];
    }
    out.push_str(rest);
    out
}

/// The module path of a source file (`visibility/pvs.rs` → `[visibility,
/// pvs]`, `views/mod.rs` → `[views]`, `lib.rs` → `[]`).
fn module_path(src: &Path, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(src).unwrap();
    let mut parts: Vec<String> = rel
        .iter()
        .map(|c| c.to_string_lossy().trim_end_matches(".rs").to_string())
        .collect();
    if parts.last().is_some_and(|l| l == "mod" || l == "lib") {
        parts.pop();
    }
    parts
}

/// The top-level modules a piece of library code names through `crate::`
/// and `super::` paths.
fn used_modules(code: &str, path: &[String]) -> BTreeSet<String> {
    let mut used = BTreeSet::new();
    let ident = |s: &str| -> String {
        s.chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect()
    };
    for (i, _) in code.match_indices("crate::") {
        let rest = &code[i + "crate::".len()..];
        if let Some(list) = rest.strip_prefix('{') {
            let inner = &list[..list.find('}').unwrap_or(list.len())];
            for item in inner.split(',') {
                used.insert(ident(item.trim()));
            }
        } else {
            used.insert(ident(rest));
        }
    }
    // `super::` chains: each one climbs one module from the file's own
    // module (a `mod.rs` is its folder's module).
    let mut at = 0;
    while let Some(i) = code[at..].find("super::") {
        let start = at + i;
        if start > 0 && code.as_bytes()[start - 1].is_ascii_alphanumeric() {
            at = start + 7;
            continue;
        }
        let mut rest = &code[start..];
        let mut up = 0;
        while let Some(r) = rest.strip_prefix("super::") {
            up += 1;
            rest = r;
        }
        if up <= path.len() {
            let base = &path[..path.len() - up];
            let target = match base.first() {
                Some(top) => top.clone(),
                None => ident(rest),
            };
            used.insert(target);
        }
        at = start + 7 * up;
    }
    used.retain(|m| !m.is_empty() && m != "self");
    used
}

#[test]
fn optimizer_modules_depend_only_downward() {
    let src = root().join("optimizer/src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    files.sort();
    let mut problems = Vec::new();
    for file in &files {
        let path = module_path(&src, file);
        let Some(top) = path.first() else {
            continue; // lib.rs declares the modules
        };
        let Some(own) = layer(top) else {
            problems.push(format!(
                "{}: module `{top}` has no layer in tests/architecture.rs",
                file.display()
            ));
            continue;
        };
        let code = library_code(&std::fs::read_to_string(file).unwrap());
        for m in used_modules(&code, &path) {
            if &m == top || ROOT_ITEMS.contains(&m.as_str()) {
                continue;
            }
            match layer(&m) {
                Some(l) if l < own => {}
                Some(_) => problems.push(format!(
                    "{}: `{top}` uses `{m}`, which is not below it",
                    file.display()
                )),
                None => problems.push(format!(
                    "{}: `{top}` uses unknown crate item `{m}`",
                    file.display()
                )),
            }
        }
    }
    assert!(problems.is_empty(), "\n{}", problems.join("\n"));
}

#[test]
fn only_the_report_the_cli_and_the_server_use_the_evaluation() {
    // Inside the optimizer the layer order enforces it; the crates around
    // it are the CLI and the server, which may. Nothing else exists.
    let members = std::fs::read_to_string(root().join("Cargo.toml")).unwrap();
    let listed: Vec<&str> = members
        .lines()
        .find(|l| l.starts_with("members"))
        .unwrap()
        .split('"')
        .skip(1)
        .step_by(2)
        .collect();
    assert_eq!(
        listed,
        ["optimizer", "server"],
        "new crates must be checked here"
    );
    let evaluate = layer("evaluate").unwrap();
    let above: Vec<&str> = LAYERS[evaluate + 1..]
        .iter()
        .flat_map(|l| l.iter().copied())
        .collect();
    assert_eq!(above, ["report", "citygen", "testutil"]);
    for file in ["citygen", "testutil"] {
        let mut files = Vec::new();
        let dir = root().join("optimizer/src").join(file);
        if dir.is_dir() {
            rust_files(&dir, &mut files);
        } else {
            files.push(root().join(format!("optimizer/src/{file}.rs")));
        }
        for f in files {
            let code = library_code(&std::fs::read_to_string(&f).unwrap());
            assert!(
                !code.contains("crate::evaluate"),
                "{} uses the evaluation",
                f.display()
            );
        }
    }
}

#[test]
fn no_source_file_has_more_than_800_lines_outside_its_tests() {
    let mut files = Vec::new();
    for dir in ["optimizer/src", "server/src", "cli"] {
        let d = root().join(dir);
        if d.is_dir() {
            rust_files(&d, &mut files);
        }
    }
    let long: Vec<String> = files
        .iter()
        .filter_map(|f| {
            let code = library_code(&std::fs::read_to_string(f).unwrap());
            let n = code.lines().count();
            (n > 800).then(|| format!("{}: {n} lines", f.display()))
        })
        .collect();
    assert!(long.is_empty(), "\n{}", long.join("\n"));
}
