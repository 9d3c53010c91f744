//! Potentially visible set files (`schemas/pvs.schema.json`): view cells
//! (boxes) with the ids of the objects that may be visible from them.
//! `impostor pvs` writes the grid cells of a job in this format, so a PVS
//! computed once (or by another tool) can be reused with `"visibility":
//! "precomputed"`.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::{Error, Result};

/// A PVS file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PvsFile {
    /// Number of objects of the scene the file was made for.
    pub objects: u64,
    /// The view cells.
    pub cells: Vec<PvsCell>,
}

/// One view cell of a PVS file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PvsCell {
    /// Box minimum `[x, y, z]`, metres.
    pub min: [f64; 3],
    /// Box maximum `[x, y, z]`, metres.
    pub max: [f64; 3],
    /// Ids of the objects that may be visible from the cell.
    pub visible: Vec<u32>,
}

impl PvsFile {
    /// Parses a PVS file; `source` names it in errors.
    pub fn from_json(bytes: &[u8], source: &str) -> Result<PvsFile> {
        let f: PvsFile = serde_json::from_slice(bytes)
            .map_err(|e| Error::bad(source, format!("invalid PVS JSON: {e}")))?;
        f.check_shape(source)?;
        Ok(f)
    }

    fn check_shape(&self, source: &str) -> Result<()> {
        for (i, c) in self.cells.iter().enumerate() {
            let what = || format!("{source}: cells[{i}]");
            if c.min
                .iter()
                .chain(&c.max)
                .any(|v| !v.is_finite() || v.abs() > 1e9)
            {
                return Err(Error::bad(what(), "box is not finite"));
            }
            if (0..3).any(|a| c.min[a] > c.max[a]) {
                return Err(Error::bad(what(), "box is inverted (min above max)"));
            }
            if let Some(&o) = c.visible.iter().find(|&&o| u64::from(o) >= self.objects) {
                return Err(Error::bad(
                    format!("{}.visible", what()),
                    format!(
                        "object id {o} is not below the file's object count {}",
                        self.objects
                    ),
                ));
            }
        }
        // No two cells may overlap (positive-volume intersection).
        let mut order: Vec<usize> = (0..self.cells.len()).collect();
        order.sort_by(|&a, &b| self.cells[a].min[0].total_cmp(&self.cells[b].min[0]));
        for (k, &i) in order.iter().enumerate() {
            let a = &self.cells[i];
            for &j in &order[k + 1..] {
                let b = &self.cells[j];
                if b.min[0] >= a.max[0] {
                    break;
                }
                let overlap = (0..3).all(|ax| {
                    let lo = a.min[ax].max(b.min[ax]);
                    let hi = a.max[ax].min(b.max[ax]);
                    hi > lo || (a.min[ax] == a.max[ax] && b.min[ax] == b.max[ax] && lo == hi)
                });
                if overlap {
                    return Err(Error::bad(
                        format!("{source}: cells[{}] and cells[{}]", i.min(j), i.max(j)),
                        "overlap; PVS cells must not overlap",
                    ));
                }
            }
        }
        Ok(())
    }

    /// Checks that the file was made for a scene of `objects` objects.
    pub fn check(&self, objects: usize, source: &str) -> Result<()> {
        if self.objects != objects as u64 {
            return Err(Error::bad(
                source,
                format!(
                    "the PVS file is for {} objects but the scene has {objects}: it does not match the scene",
                    self.objects
                ),
            ));
        }
        self.check_shape(source)
    }
}
