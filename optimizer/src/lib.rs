//! Automatic impostor placement for guaranteed frame rates and low memory
//! requirements (Jeschke, Wimmer, Schumann, Purgathofer 2005).
//!
//! The pipeline, one module per stage, plain data between stages:
//!
//! ```text
//! scene ──► hierarchy ──► problem_views ──► candidates ──► greedy ──► placement
//! (glTF/JSON)  (BVH)       (cells × VDIs)   (shafts, boxes)  (lazy)      │
//!                                                                      └─► evaluate
//! ```

#![deny(missing_docs)]

pub mod api;
pub mod bake;
pub mod candidates;
pub mod citygen;
pub mod control;
pub mod error;
pub mod evaluate;
pub mod export;
pub mod files;
pub mod greedy;
pub mod input;
pub mod math;
pub mod methods;
pub mod model;
pub mod place;
pub mod render;
pub mod report;
pub mod scene;
pub mod sysmem;
pub mod testutil;
pub mod views;
pub mod visibility;

pub use error::{Error, Result};

/// `value` in the byte format of every JSON file the tool writes
/// ([`files::write_json`]), in memory.
pub fn to_json_bytes(value: &impl serde::Serialize) -> Result<Vec<u8>> {
    let mut v = Vec::new();
    files::write_json(&mut v, value).map_err(|e| Error::Internal(e.to_string()))?;
    Ok(v)
}

/// Version of this library.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
