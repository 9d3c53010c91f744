//! Writes the synthetic sample report (`testutil::sample_report`) as
//! `report.html`, `report.json` and its CSV files into a directory, to look
//! at the page or check it with `tools/check-report.sh`.
//!
//! `cargo run --release -p optimizer --example report_sample [DIR]`
//! (default `report-sample`).

use optimizer::report::render::{csv_files, render_html};
use optimizer::testutil::sample_report;

fn main() -> std::io::Result<()> {
    let dir = std::path::PathBuf::from(
        std::env::args()
            .nth(1)
            .unwrap_or_else(|| "report-sample".into()),
    );
    std::fs::create_dir_all(&dir)?;
    let r = sample_report();
    std::fs::write(dir.join("report.html"), render_html(&r))?;
    let json = serde_json::to_string_pretty(&r).map_err(std::io::Error::other)?;
    std::fs::write(dir.join("report.json"), json)?;
    for (name, text) in csv_files(&r) {
        std::fs::write(dir.join(name), text)?;
    }
    println!("{}", dir.join("report.html").display());
    Ok(())
}
