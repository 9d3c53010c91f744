//! The node graph of the GLB writer: nodes, their children and levels of
//! detail, and the scene's roots, kept a forest as they are added.

use gltf::json as gj;
use serde_json::Value;

use super::{GlbBuilder, LOD_EXTENSION, Node, Transform, all_finite, bad, to_u32};
use crate::{Error, Result};

impl GlbBuilder {
    /// Adds a node and returns its index. Its mesh must exist; its children must be
    /// existing, distinct nodes without a parent (so the node graph stays a forest).
    /// The rotation of a TRS transform is normalised.
    pub fn add_node(&mut self, node: Node) -> Result<u32> {
        let what = format!("node '{}'", node.name);
        let index = to_u32(self.root.nodes.len(), "nodes")?;
        let mut n = gj::Node {
            name: (!node.name.is_empty()).then(|| node.name.clone()),
            ..Default::default()
        };
        if let Some(m) = node.mesh {
            if m as usize >= self.root.meshes.len() {
                return Err(bad(&what, format!("unknown mesh {m}")));
            }
            n.mesh = Some(gj::Index::new(m));
        }
        match node.transform {
            Transform::Identity => {}
            Transform::Trs {
                translation,
                rotation,
                scale,
            } => {
                if !all_finite(&translation) || !all_finite(&rotation) || !all_finite(&scale) {
                    return Err(bad(&what, "transform is not finite"));
                }
                let len = rotation.iter().map(|c| c * c).sum::<f32>().sqrt();
                if len < 1e-6 {
                    return Err(bad(&what, "rotation quaternion has zero length"));
                }
                let rotation = rotation.map(|c| c / len);
                // Identity parts are left out, as glTF's defaults.
                n.translation = (translation != [0.0; 3]).then_some(translation);
                n.rotation = (rotation != [0.0, 0.0, 0.0, 1.0])
                    .then_some(gj::scene::UnitQuaternion(rotation));
                n.scale = (scale != [1.0; 3]).then_some(scale);
            }
            Transform::Matrix(m) => {
                if !all_finite(&m) {
                    return Err(bad(&what, "matrix is not finite"));
                }
                if m[3] != 0.0 || m[7] != 0.0 || m[11] != 0.0 || m[15] != 1.0 {
                    return Err(bad(
                        &what,
                        "matrix is not affine (last row must be 0 0 0 1)",
                    ));
                }
                n.matrix = Some(m);
            }
        }
        let mut levels = Vec::new();
        for (name, value) in &node.extensions {
            if name.is_empty() {
                return Err(bad(&what, "an extension name is empty"));
            }
            if name == LOD_EXTENSION {
                levels = self.lod_ids(value, index, &what)?;
            }
        }
        if !node.children.is_empty() {
            for (k, &c) in node.children.iter().enumerate() {
                if c >= index {
                    return Err(bad(&what, format!("unknown child {c}")));
                }
                if self.parent[c as usize].is_some() || node.children[..k].contains(&c) {
                    return Err(bad(&what, format!("child {c} already has a parent")));
                }
                if self.roots.as_ref().is_some_and(|r| r.contains(&c)) {
                    return Err(bad(&what, format!("child {c} is a scene root")));
                }
            }
            for &c in &node.children {
                self.parent[c as usize] = Some(index);
            }
            n.children = Some(node.children.iter().map(|&c| gj::Index::new(c)).collect());
        }
        if let Some(extras) = &node.extras {
            // `gltf-json` keeps extras as raw JSON text.
            let raw = serde_json::value::to_raw_value(extras)
                .map_err(|e| Error::Internal(format!("GLB writer: {what} extras: {e}")))?;
            n.extras = Some(raw);
        }
        self.extensions_used.extend(node.extensions.keys().cloned());
        if !node.extensions.is_empty() {
            n.extensions = Some(gj::extensions::scene::Node {
                others: node.extensions,
            });
        }
        for l in levels {
            self.lod_level[l as usize] = true;
        }
        self.root.nodes.push(n);
        self.parent.push(None);
        self.lod_level.push(false);
        Ok(index)
    }

    /// Checks an `MSFT_lod` value of node `index`: `{"ids": [...]}` naming
    /// distinct nodes added earlier; returns them.
    fn lod_ids(&self, value: &Value, index: u32, what: &str) -> Result<Vec<u32>> {
        let ids = value
            .get("ids")
            .and_then(Value::as_array)
            .filter(|ids| !ids.is_empty())
            .ok_or_else(|| bad(what, "MSFT_lod needs a non-empty `ids` array"))?;
        let mut out: Vec<u32> = Vec::with_capacity(ids.len());
        for id in ids {
            let id = id
                .as_u64()
                .and_then(|i| u32::try_from(i).ok())
                .filter(|&i| i < index)
                .ok_or_else(|| {
                    bad(
                        what,
                        format!("MSFT_lod id {id} is not a node added before this one"),
                    )
                })?;
            if out.contains(&id) {
                return Err(bad(what, format!("MSFT_lod names node {id} twice")));
            }
            out.push(id);
        }
        Ok(out)
    }

    /// Makes `child` (which must have no parent and not be a scene root or an ancestor
    /// of `parent`) a child of `parent`.
    pub fn add_child(&mut self, parent: u32, child: u32) -> Result<()> {
        let n = self.root.nodes.len();
        if parent as usize >= n || child as usize >= n {
            return Err(bad(
                "add_child",
                format!("unknown node {parent} or {child}"),
            ));
        }
        if self.parent[child as usize].is_some() {
            return Err(bad(
                "add_child",
                format!("node {child} already has a parent"),
            ));
        }
        if self.roots.as_ref().is_some_and(|r| r.contains(&child)) {
            return Err(bad("add_child", format!("node {child} is a scene root")));
        }
        let mut a = Some(parent);
        while let Some(x) = a {
            if x == child {
                return Err(bad(
                    "add_child",
                    format!("node {child} is an ancestor of {parent}"),
                ));
            }
            a = self.parent[x as usize];
        }
        self.parent[child as usize] = Some(parent);
        self.root.nodes[parent as usize]
            .children
            .get_or_insert_with(Vec::new)
            .push(gj::Index::new(child));
        Ok(())
    }

    /// Sets the root nodes of the (single) scene: existing, distinct nodes without a
    /// parent. Without this call the roots are all parentless nodes in index order,
    /// except levels of detail (nodes named in some `MSFT_lod.ids`). A
    /// document without any root node is written without a scene.
    pub fn set_scene_roots(&mut self, roots: &[u32]) -> Result<()> {
        for (k, &r) in roots.iter().enumerate() {
            if r as usize >= self.root.nodes.len() {
                return Err(bad("scene", format!("unknown node {r}")));
            }
            if self.parent[r as usize].is_some() {
                return Err(bad("scene", format!("node {r} has a parent")));
            }
            if roots[..k].contains(&r) {
                return Err(bad("scene", format!("node {r} listed twice")));
            }
        }
        self.roots = Some(roots.to_vec());
        Ok(())
    }

    /// Sets the (single) scene's `extras`. They are written only when the
    /// document has a scene (at least one root node).
    pub fn set_scene_extras(&mut self, extras: Value) {
        self.scene_extras = Some(extras);
    }

    /// Number of nodes added so far.
    pub fn node_count(&self) -> usize {
        self.root.nodes.len()
    }

    /// The scene's root nodes: those of [`GlbBuilder::set_scene_roots`], or
    /// else every parentless node that is not a level of detail, in index
    /// order.
    pub(super) fn scene_roots(&self) -> Vec<u32> {
        match &self.roots {
            Some(r) => r.clone(),
            None => (0..self.parent.len() as u32)
                .filter(|&i| self.parent[i as usize].is_none() && !self.lod_level[i as usize])
                .collect(),
        }
    }
}
