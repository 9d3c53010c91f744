//! `impostor schema`: the JSON Schemas of the wire types.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use optimizer::api::schema;
use optimizer::{Error, Result};

use crate::output::write_output;

#[derive(Args)]
pub struct SchemaArgs {
    /// Output directory.
    #[arg(long, default_value = "schemas")]
    out_dir: PathBuf,
}

pub fn run(a: SchemaArgs) -> Result<ExitCode> {
    std::fs::create_dir_all(&a.out_dir).map_err(|e| Error::io(&a.out_dir, e))?;
    for (name, text) in schema::all() {
        write_output(Some(&a.out_dir.join(name)), text.as_bytes())?;
    }
    Ok(ExitCode::SUCCESS)
}
