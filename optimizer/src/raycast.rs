//! Ray casting against the scene's triangles (temporary stub).
#![allow(missing_docs, dead_code)]
use crate::geometry::SceneGeometry;
use glam::DVec3;
pub struct RayCaster;
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub object: u32,
    pub t: f64,
    pub front: bool,
}
impl RayCaster {
    pub fn new(_g: &SceneGeometry) -> RayCaster {
        RayCaster
    }
    pub fn first_hit(&self, _o: DVec3, _d: DVec3, _tmin: f64, _tmax: f64) -> Option<Hit> {
        None
    }
    pub fn trace(
        &self,
        _o: DVec3,
        _d: DVec3,
        _tmin: f64,
        _tmax: f64,
        _v: &mut impl FnMut(u32),
    ) -> Option<Hit> {
        None
    }
    pub fn segment_clear(&self, _a: DVec3, _b: DVec3) -> bool {
        true
    }
}
