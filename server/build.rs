//! Builds the web page (`../web`) into `OUT_DIR/web`, which `src/web.rs`
//! embeds: `npm ci` when `web/node_modules` is missing or was installed
//! from another `package-lock.json`, then the page's esbuild script.
//! Node.js and npm are needed to build the server.

use std::path::{Path, PathBuf};
use std::process::Command;

fn main() {
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    let web = manifest.join("..").join("web");
    for watched in [
        "src",
        "build.mjs",
        "package.json",
        "package-lock.json",
        "../schemas/job.schema.json",
    ] {
        println!("cargo:rerun-if-changed={}", web.join(watched).display());
    }
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets it")).join("web");
    for tool in ["node", "npm"] {
        if let Err(e) = Command::new(tool).arg("--version").output() {
            fail(&format!(
                "`{tool} --version` cannot be run ({e}): the server embeds its web page, \
                 built with Node.js (20 or later) and npm; install them (Debian: \
                 apt-get install nodejs npm) and build again"
            ));
        }
    }
    install(&web);
    let _ = std::fs::remove_dir_all(&out);
    run(
        Command::new("node").arg(web.join("build.mjs")).arg(&out),
        "node web/build.mjs (bundling the web page)",
    );
}

/// `npm ci` in `web` unless its `node_modules` was installed from the
/// current lock file (a copy of which is kept there as a stamp).
fn install(web: &Path) {
    let lock = std::fs::read(web.join("package-lock.json"))
        .unwrap_or_else(|e| fail(&format!("web/package-lock.json cannot be read: {e}")));
    let stamp = web.join("node_modules").join(".impostor-lock.json");
    if std::fs::read(&stamp).ok().as_deref() == Some(&lock[..]) {
        return;
    }
    run(
        Command::new("npm")
            .args(["ci", "--no-audit", "--no-fund", "--loglevel=error"])
            .current_dir(web),
        "npm ci in web/ (installing three.js, esbuild and ajv from the npm registry)",
    );
    std::fs::write(&stamp, &lock)
        .unwrap_or_else(|e| fail(&format!("{} cannot be written: {e}", stamp.display())));
}

fn run(cmd: &mut Command, what: &str) {
    match cmd.status() {
        Ok(s) if s.success() => {}
        Ok(s) => fail(&format!("{what} failed ({s})")),
        Err(e) => fail(&format!("{what} cannot be started: {e}")),
    }
}

fn fail(msg: &str) -> ! {
    eprintln!("error: {msg}");
    panic!("{msg}");
}
