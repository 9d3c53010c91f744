//! The scene: objects with world bounds and rendering costs.
//!
//! Placement needs bounds and costs only, so a [`Scene`] holds no geometry.
//! It is built from a glTF file ([`crate::scene::gltf_load`]) or from a JSON scene
//! summary ([`SceneSummary`]).

pub mod geometry;
pub mod glb;
pub mod gltf_load;
pub mod hierarchy;
pub mod lod;
pub mod lod_write;
pub mod material;

use crate::api::scene::{LodLevel, SceneSummary, SummaryObject};
use glam::DVec3;

use crate::error::{Error, Result};

/// One object of the scene: a glTF node instance that draws a mesh, or one
/// entry of a JSON scene summary.
#[derive(Clone, Debug, PartialEq)]
pub struct Object {
    /// Name (glTF node name or summary name); may be empty.
    pub name: String,
    /// World-space bounding box minimum, metres.
    pub min: DVec3,
    /// World-space bounding box maximum, metres.
    pub max: DVec3,
    /// Triangle count (triangle-list index count / 3; strips and fans converted).
    pub triangles: u64,
    /// Draw calls (glTF primitives of the mesh).
    pub draw_calls: u32,
    /// Levels of detail, finest first, or empty when the object has none.
    /// When present, level 0 is the object itself (its `triangles` and
    /// `draw_calls`), and level `i` is drawn while the object's screen
    /// coverage is at least `lods[i].min_coverage` and below level `i − 1`'s;
    /// below the last level's threshold the object is not drawn (glTF
    /// `MSFT_lod` with `MSFT_screencoverage`). Every level lies within the
    /// object's bounds.
    pub lods: Vec<LodLevel>,
}

/// Most levels of detail an object may have.
pub const MAX_LODS: usize = 32;

/// Most objects a scene may have: 2²², four million (a large game map has
/// tens of thousands); checked before any per-object work.
pub const MAX_OBJECTS: usize = 1 << 22;

/// Most triangles one object (or one of its levels) may have: 2³², far
/// above any mesh a renderer draws, and low enough that the sums over a
/// scene's objects cannot overflow.
pub const MAX_OBJECT_TRIANGLES: u64 = 1 << 32;

impl Object {
    /// Centre of the bounding box (also the centre of the bounding sphere).
    pub fn center(&self) -> DVec3 {
        (self.min + self.max) * 0.5
    }

    /// Radius of the bounding sphere (the box's half-diagonal).
    pub fn radius(&self) -> f64 {
        (self.max - self.min).length() * 0.5
    }
}

/// A scene: its objects, indexed by object id (see DESIGN §5).
#[derive(Clone, Debug, Default)]
pub struct Scene {
    /// Objects; the index is the object id.
    pub objects: Vec<Object>,
}

impl Scene {
    /// Checks the invariants every stage relies on: at least one object,
    /// finite bounds with `min <= max`, at most [`MAX_OBJECT_TRIANGLES`]
    /// triangles an object. `source` names the input in errors.
    pub fn validate(&self, source: &str) -> Result<()> {
        if self.objects.is_empty() {
            return Err(Error::bad(
                source,
                "the scene has no objects (no node draws a mesh)",
            ));
        }
        if self.objects.len() > MAX_OBJECTS {
            return Err(Error::bad(
                source,
                format!(
                    "the scene has {} objects, more than the {MAX_OBJECTS} a scene may have",
                    self.objects.len()
                ),
            ));
        }
        for (id, o) in self.objects.iter().enumerate() {
            if !(o.min.is_finite() && o.max.is_finite()) {
                return Err(Error::bad(
                    format!("{source}: object {id} ({})", o.name),
                    "bounds are not finite (NaN or infinite coordinates)",
                ));
            }
            if o.min.cmpgt(o.max).any() {
                return Err(Error::bad(
                    format!("{source}: object {id} ({})", o.name),
                    format!("bounds min {:?} exceed max {:?}", o.min, o.max),
                ));
            }
            if o.max.abs().max_element() > 1e9 || o.min.abs().max_element() > 1e9 {
                return Err(Error::bad(
                    format!("{source}: object {id} ({})", o.name),
                    "coordinates beyond 1e9 m",
                ));
            }
            if o.triangles > MAX_OBJECT_TRIANGLES
                || o.lods.iter().any(|l| l.triangles > MAX_OBJECT_TRIANGLES)
            {
                return Err(Error::bad(
                    format!("{source}: object {id} ({})", o.name),
                    format!(
                        "{} triangles: an object (and each of its levels) may have at most {MAX_OBJECT_TRIANGLES}",
                        o.lods
                            .iter()
                            .map(|l| l.triangles)
                            .fold(o.triangles, u64::max)
                    ),
                ));
            }
            validate_lods(o)
                .map_err(|m| Error::bad(format!("{source}: object {id} ({}): lods", o.name), m))?;
        }
        Ok(())
    }

    /// True when some object has levels of detail.
    pub fn has_lods(&self) -> bool {
        self.objects.iter().any(|o| !o.lods.is_empty())
    }

    /// Bounds of all objects.
    pub fn bounds(&self) -> (DVec3, DVec3) {
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for o in &self.objects {
            lo = lo.min(o.min);
            hi = hi.max(o.max);
        }
        (lo, hi)
    }

    /// Total triangles over all objects.
    pub fn total_triangles(&self) -> u64 {
        self.objects
            .iter()
            .fold(0u64, |acc, o| acc.saturating_add(o.triangles))
    }

    /// The JSON scene summary of this scene.
    pub fn summary(&self) -> SceneSummary {
        SceneSummary {
            objects: self
                .objects
                .iter()
                .map(|o| SummaryObject {
                    name: (!o.name.is_empty()).then(|| o.name.clone()),
                    min: o.min.to_array(),
                    max: o.max.to_array(),
                    triangles: o.triangles,
                    draw_calls: o.draw_calls,
                    lods: o.lods.clone(),
                })
                .collect(),
        }
    }
}

/// Checks an object's levels: level 0 is the object itself, thresholds are
/// finite, in `[0, 1]` and strictly decreasing.
fn validate_lods(o: &Object) -> std::result::Result<(), String> {
    let Some(first) = o.lods.first() else {
        return Ok(());
    };
    if first.triangles != o.triangles || first.draw_calls != o.draw_calls {
        return Err(format!(
            "level 0 ({} triangles, {} draw calls) must be the object itself ({} triangles, {} draw calls)",
            first.triangles, first.draw_calls, o.triangles, o.draw_calls
        ));
    }
    if o.lods.len() > MAX_LODS {
        return Err(format!("{} levels (at most {MAX_LODS})", o.lods.len()));
    }
    let mut last = f64::INFINITY;
    for (i, l) in o.lods.iter().enumerate() {
        if !(l.min_coverage.is_finite() && (0.0..=1.0).contains(&l.min_coverage)) {
            return Err(format!(
                "level {i}: min_coverage {} must be in [0, 1]",
                l.min_coverage
            ));
        }
        if l.min_coverage >= last {
            return Err(format!(
                "level {i}: min_coverage {} must be below the previous level's {last}",
                l.min_coverage
            ));
        }
        last = l.min_coverage;
    }
    Ok(())
}

impl Scene {
    /// Parses a JSON scene summary; `source` names the input in errors.
    pub fn from_summary_json(bytes: &[u8], source: &str) -> Result<Scene> {
        let summary: SceneSummary = serde_json::from_slice(bytes)
            .map_err(|e| Error::bad(source, format!("invalid scene summary JSON: {e}")))?;
        let scene = Scene {
            objects: summary
                .objects
                .into_iter()
                .map(|o| Object {
                    name: o.name.unwrap_or_default(),
                    min: DVec3::from_array(o.min),
                    max: DVec3::from_array(o.max),
                    triangles: o.triangles,
                    draw_calls: o.draw_calls,
                    lods: o.lods,
                })
                .collect(),
        };
        scene.validate(source)?;
        Ok(scene)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_round_trip_keeps_levels() {
        let level = |min_coverage, triangles, draw_calls| LodLevel {
            min_coverage,
            triangles,
            draw_calls,
        };
        let scene = Scene {
            objects: vec![
                Object {
                    name: "tree".into(),
                    min: DVec3::new(-1.0, 0.0, -1.0),
                    max: DVec3::new(1.0, 8.5, 1.0),
                    triangles: 1040,
                    draw_calls: 2,
                    lods: vec![
                        level(0.08, 1040, 2),
                        level(0.0031, 192, 2),
                        level(0.0, 52, 2),
                    ],
                },
                Object {
                    name: String::new(),
                    min: DVec3::ZERO,
                    max: DVec3::ONE,
                    triangles: 12,
                    draw_calls: 1,
                    lods: Vec::new(),
                },
            ],
        };
        let json = crate::to_json_bytes(&scene.summary()).unwrap();
        let text = String::from_utf8(json.clone()).unwrap();
        assert_eq!(text.matches("\"lods\"").count(), 1, "omitted when empty");
        let back = Scene::from_summary_json(&json, "s.json").unwrap();
        assert_eq!(back.objects, scene.objects);
        // Invalid levels are rejected with the object named.
        let mut bad = scene.clone();
        bad.objects[0].lods[2].min_coverage = 0.5;
        let json = crate::to_json_bytes(&bad.summary()).unwrap();
        let e = Scene::from_summary_json(&json, "s.json")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("object 0 (tree): lods") && e.contains("level 2"),
            "{e}"
        );
    }
}
