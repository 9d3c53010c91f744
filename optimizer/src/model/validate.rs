//! The checks every consumer of a placement file runs first
//! ([`Placement::validate`]): the evaluation and the bake accept exactly
//! the same placements.

use glam::DVec3;

use crate::api::placement::Placement;
use crate::error::{Error, Result};
use crate::model::impostor::MAX_LAYERS;
use crate::scene::Scene;

/// The largest impostor texture side a placement may ask for, texels.
pub const MAX_RESOLUTION: u32 = 16384;

impl Placement {
    /// Checks that the placement can belong to `scene` (`source` names it
    /// in errors): ids are indices, every impostor represents existing
    /// objects inside its finite bounding sphere, has 1 to [`MAX_LAYERS`]
    /// layers of 1 to [`MAX_RESOLUTION`] texels per side and a possible view
    /// cell, and every problem view lists existing impostors that represent
    /// no object twice.
    pub fn validate(&self, scene: &Scene, source: &str) -> Result<()> {
        let n_obj = scene.objects.len() as u32;
        for (k, imp) in self.impostors.iter().enumerate() {
            let what = format!("{source}: impostors[{k}]");
            if imp.id as usize != k {
                return Err(Error::bad(what, format!("id {} is not its index", imp.id)));
            }
            let center = DVec3::from_array(imp.sphere.center);
            let radius = imp.sphere.radius;
            if !(center.is_finite() && radius.is_finite() && radius >= 0.0) {
                return Err(Error::bad(
                    format!("{what}.sphere"),
                    "must have a finite centre and a finite, non-negative radius",
                ));
            }
            if imp.objects.is_empty() {
                return Err(Error::bad(what, "represents no objects"));
            }
            for &o in &imp.objects {
                if o >= n_obj {
                    return Err(Error::bad(
                        format!("{what}.objects"),
                        format!(
                            "object id {o} does not exist in the scene ({n_obj} objects): the placement does not match the scene"
                        ),
                    ));
                }
                let ob = &scene.objects[o as usize];
                if center.distance(ob.center()) + ob.radius() > radius * (1.0 + 1e-9) + 1e-6 {
                    return Err(Error::bad(
                        format!("{what}.sphere"),
                        format!(
                            "does not contain object {o}: the placement does not match the scene"
                        ),
                    ));
                }
            }
            if !(1..=MAX_LAYERS).contains(&imp.layers)
                || !(1..=MAX_RESOLUTION).contains(&imp.resolution)
            {
                return Err(Error::bad(
                    what,
                    format!(
                        "layers ({}) must be in 1..={MAX_LAYERS} and resolution ({}) in 1..={MAX_RESOLUTION}",
                        imp.layers, imp.resolution
                    ),
                ));
            }
            if let Err((field, problem)) = imp.check_view_cell() {
                return Err(Error::bad(format!("{what}.{field}"), problem));
            }
        }
        for (k, c) in self.cpvs.iter().enumerate() {
            let what = format!("{source}: cpvs[{k}]");
            if c.id as usize != k {
                return Err(Error::bad(what, format!("id {} is not its index", c.id)));
            }
            let mut objects = Vec::new();
            for &i in &c.impostors {
                let imp = self.impostors.get(i as usize).ok_or_else(|| {
                    Error::bad(
                        format!("{what}.impostors"),
                        format!("impostor {i} does not exist"),
                    )
                })?;
                objects.extend_from_slice(&imp.objects);
            }
            let listed = objects.len();
            objects.sort_unstable();
            objects.dedup();
            if objects.len() != listed {
                return Err(Error::bad(
                    format!("{what}.impostors"),
                    "two impostors represent the same object",
                ));
            }
        }
        Ok(())
    }
}
