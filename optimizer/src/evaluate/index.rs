//! The placement under evaluation, checked against its scene and job and
//! indexed by (grid cell, view direction).

use std::collections::HashMap;

use glam::DVec3;

use crate::api::job::Job;
use crate::api::placement::{PlacedImpostor, Placement};
use crate::error::{Error, Result};
use crate::math::geom::{Aabb, Sphere, Vdi, face_direction};
use crate::math::grid::Grid;
use crate::model::impostor::ViewCell;
use crate::scene::Scene;
use crate::views::leaf_level;

pub(super) struct IndexedImpostor {
    pub(super) sphere: Sphere,
    pub(super) layers: u32,
    pub(super) cell: ViewCell,
}

/// A placement checked against its scene and job, with the lookups a
/// view needs: its problem view, and that view's impostors and the objects
/// they replace. The CPVs' impostor lists are the placement's own, read
/// where they are (a large placement lists hundreds of millions of ids).
pub(super) struct PlacementIndex<'p> {
    pub(super) impostors: Vec<IndexedImpostor>,
    /// The placement's impostors, for the objects each replaces.
    placed: &'p [PlacedImpostor],
    /// Per CPV: the impostor ids.
    cpv_impostors: Vec<&'p [u32]>,
    /// Per CPV: solved (its final time within the target).
    pub(super) cpv_solved: Vec<bool>,
    /// Per CPV: its region (its cell, or the part of it where its views may
    /// exceed the target).
    cpv_region: Vec<Aabb>,
    lookup: HashMap<(u32, Vdi), u32>,
    /// The job's grid.
    pub(super) grid: Grid,
    level: u8,
}

impl<'p> PlacementIndex<'p> {
    /// Checks that the placement refers to the scene and the job (`source`
    /// names it in errors) and builds the lookups.
    pub(super) fn new(
        scene: &Scene,
        job: &Job,
        placement: &'p Placement,
        source: &str,
    ) -> Result<PlacementIndex<'p>> {
        placement.validate(scene, source)?;
        let mut impostors = Vec::with_capacity(placement.impostors.len());
        for imp in &placement.impostors {
            let sphere = Sphere {
                center: DVec3::from_array(imp.sphere.center),
                radius: imp.sphere.radius,
            };
            let cell = ViewCell::from(&imp.view_cell);
            impostors.push(IndexedImpostor {
                sphere,
                layers: imp.layers,
                cell,
            });
        }
        let grid = job.grid();
        let level = leaf_level(job.problem_views.min_vdi_deg);
        let mut lookup = HashMap::with_capacity(placement.cpvs.len());
        let mut cpv_impostors = Vec::with_capacity(placement.cpvs.len());
        let mut cpv_solved = Vec::with_capacity(placement.cpvs.len());
        let mut cpv_region = Vec::with_capacity(placement.cpvs.len());
        for (k, c) in placement.cpvs.iter().enumerate() {
            let what = format!("{source}: cpvs[{k}]");
            let region = Aabb::new(
                DVec3::from_array(c.region.min),
                DVec3::from_array(c.region.max),
            );
            let cell = grid
                .cell_of(region.center())
                .ok_or_else(|| Error::bad(&what, "region lies outside the job's view space"))?;
            // A problem view's region is its grid cell or the part of it
            // where its views may exceed the target.
            let expect = grid.cell_box(cell, cell.map(|i| i + 1));
            let tol = 1e-6 * (1.0 + expect.half_diagonal());
            let inside = (0..3).all(|a| {
                region.min[a] >= expect.min[a] - tol
                    && region.max[a] <= expect.max[a] + tol
                    && region.min[a] <= region.max[a]
            });
            if !inside {
                return Err(Error::bad(
                    &what,
                    "region does not lie in a cell of the job's view space grid: the placement does not match the job",
                ));
            }
            let d = &c.directions;
            if d.face > 5 {
                return Err(Error::bad(
                    format!("{what}.directions.face"),
                    format!("{} is not in 0..6", d.face),
                ));
            }
            let mid = |[a, b]: [f64; 2]| ((a.atan() + b.atan()) * 0.5).tan();
            let vdi = Vdi::containing(face_direction(d.face, mid(d.u), mid(d.v)), level);
            if (vdi.u_range()[0] - d.u[0]).abs() > 1e-9 || (vdi.v_range()[1] - d.v[1]).abs() > 1e-9
            {
                return Err(Error::bad(
                    format!("{what}.directions"),
                    "is not a minimum-size VDI of the job: the placement does not match the job",
                ));
            }
            if lookup.insert((grid.linear(cell), vdi), k as u32).is_some() {
                return Err(Error::bad(&what, "duplicate CPV"));
            }
            cpv_impostors.push(&c.impostors[..]);
            cpv_solved.push(c.time_ms_final <= job.target_frame_time_ms && c.solved);
            cpv_region.push(region);
        }
        Ok(PlacementIndex {
            impostors,
            placed: &placement.impostors,
            cpv_impostors,
            cpv_solved,
            cpv_region,
            lookup,
            grid,
            level,
        })
    }

    /// The CPV of a view (its eye, the eye's cell and the direction), with
    /// the objects its impostors replace (sorted) and the impostors; empty
    /// lists outside CPVs (including the parts of a cell outside its CPVs'
    /// regions, where no view exceeds the target).
    pub(super) fn view_cpv(
        &self,
        eye: DVec3,
        cell: [u32; 3],
        dir: DVec3,
    ) -> (Option<u32>, Vec<u32>, &'p [u32]) {
        let vdi = Vdi::containing(dir, self.level);
        match self.lookup.get(&(self.grid.linear(cell), vdi)).copied() {
            Some(c) if self.cpv_region[c as usize].contains_point(eye) => {
                let imps = self.cpv_impostors[c as usize];
                // Gathered for this view only: held for every CPV at once,
                // the replaced objects took several times the placement.
                let mut replaced: Vec<u32> = imps
                    .iter()
                    .flat_map(|&i| self.placed[i as usize].objects.iter().copied())
                    .collect();
                replaced.sort_unstable();
                (Some(c), replaced, imps)
            }
            _ => (None, Vec::new(), &[]),
        }
    }
}
