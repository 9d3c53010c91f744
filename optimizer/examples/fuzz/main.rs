//! A bounded mutation fuzzer over the parsers that face users' files (see
//! `engine.rs`): deterministic for a seed; a target stops at its first
//! panic, whose input is written to the temporary folder.
//!
//! ```sh
//! cargo run --release -p optimizer --example fuzz -- [CASES [SEED]]   # default 100000 1
//! ```

mod engine;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let cases: u64 = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(100_000);
    let seed: u64 = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(1);
    let mut failed = false;
    for o in engine::run(cases, seed) {
        match o.panic {
            None => println!(
                "{}: {} cases clean in {:.1} s (slowest {:.1} ms)",
                o.name,
                o.cases,
                o.seconds,
                o.slowest * 1e3
            ),
            Some((case, input)) => {
                let path = std::env::temp_dir()
                    .join(format!("fuzz-{}-{case}.bin", o.name.replace(' ', "-")));
                let _ = std::fs::write(&path, &input);
                println!(
                    "{}: PANIC at case {case}; input written to {}",
                    o.name,
                    path.display()
                );
                failed = true;
            }
        }
    }
    if failed {
        std::process::exit(1);
    }
}
