//! `impostor info`: a scene's objects, triangles, draw calls and bounds.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use optimizer::Result;
use optimizer::scene::gltf_load;

use crate::output::write_json;

#[derive(Args)]
pub struct InfoArgs {
    /// Scene: .glb, .gltf or a JSON scene summary.
    scene: PathBuf,
}

pub fn run(a: InfoArgs) -> Result<ExitCode> {
    let scene = gltf_load::load_scene_file(&a.scene)?;
    let (lo, hi) = scene.bounds();
    let calls: u64 = scene.objects.iter().map(|o| u64::from(o.draw_calls)).sum();
    let info = serde_json::json!({
        "objects": scene.objects.len(),
        "triangles": scene.total_triangles(),
        "draw_calls": calls,
        "bounds": { "min": lo.to_array(), "max": hi.to_array() },
    });
    write_json(None, &info)?;
    Ok(ExitCode::SUCCESS)
}
