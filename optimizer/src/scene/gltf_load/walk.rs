//! The scene walk shared by the scene and geometry loaders: object ids in
//! depth-first pre-order, `MSFT_lod` chains and their screen coverages,
//! GPU instances (`EXT_mesh_gpu_instancing`), world transforms.

use super::*;

/// The coarser levels of detail of an object (`MSFT_lod`).
pub(crate) struct LodChain {
    /// Levels 1, 2, … (level 0 is the object's own node).
    pub(crate) levels: Vec<LodNode>,
    /// `min_coverage` of levels 0, 1, …: one more value than `levels`,
    /// finite, in `[0, 1]`, strictly decreasing.
    pub(crate) min_coverage: Vec<f64>,
}

/// One coarser level: a node named in `MSFT_lod.ids`, placed where the
/// object's node is.
pub(crate) struct LodNode {
    pub(crate) mesh: usize,
    /// The object's parent world transform × this node's local transform.
    pub(crate) world: DAffine3,
}

/// The glTF extension that draws one node's mesh many times, each instance
/// placed by its own translation, rotation and scale.
pub(crate) const EXT_INSTANCING: &str = "EXT_mesh_gpu_instancing";

/// A node's `EXT_mesh_gpu_instancing`: the accessors of its instances'
/// `TRANSLATION`, `ROTATION` and `SCALE` (each optional, at least one
/// given) and how many instances they hold (their common count).
#[derive(Clone, Copy, Debug)]
pub(crate) struct GpuInstancing {
    trs: [Option<usize>; 3],
    count: usize,
}

/// The instancing of node `n`, `None` without the extension; checked from
/// the JSON alone: attributes naming existing accessors of one count of at
/// least 1 (their data is read by [`place_gpu_instances`]).
pub(crate) fn gpu_instancing(
    doc: &gltf::Document,
    n: usize,
    source: &str,
) -> Result<Option<GpuInstancing>> {
    let json = doc.as_json();
    let Some(ext) = json.nodes[n]
        .extensions
        .as_ref()
        .and_then(|e| e.others.get(EXT_INSTANCING))
    else {
        return Ok(None);
    };
    let what = format!("{source}: node {n} extensions.{EXT_INSTANCING}");
    let Some(attributes) = ext.get("attributes").and_then(serde_json::Value::as_object) else {
        return Err(Error::bad(what, "has no `attributes` object"));
    };
    let accessors = &json.accessors;
    let mut trs = [None; 3];
    let mut count: Option<(usize, &str)> = None;
    for (k, name) in ["TRANSLATION", "ROTATION", "SCALE"].into_iter().enumerate() {
        let Some(v) = attributes.get(name) else {
            continue;
        };
        let a = v
            .as_u64()
            .and_then(|a| usize::try_from(a).ok())
            .filter(|&a| a < accessors.len())
            .ok_or_else(|| {
                Error::bad(
                    &what,
                    format!(
                        "attributes.{name} ({v}) is not an accessor index (the file has {} \
                         accessors)",
                        accessors.len()
                    ),
                )
            })?;
        let c = usize::try_from(accessors[a].count.0).unwrap_or(usize::MAX);
        match count {
            None => count = Some((c, name)),
            Some((other, first)) if other != c => {
                return Err(Error::bad(
                    &what,
                    format!(
                        "attributes.{name} holds {c} instances, attributes.{first} {other}: \
                         every attribute needs one value per instance"
                    ),
                ));
            }
            Some(_) => {}
        }
        trs[k] = Some(a);
    }
    match count {
        None => Err(Error::bad(
            what,
            "names none of TRANSLATION, ROTATION and SCALE",
        )),
        Some((0, name)) => Err(Error::bad(
            what,
            format!("attributes.{name} holds no instance (count 0)"),
        )),
        Some((count, _)) => Ok(Some(GpuInstancing { trs, count })),
    }
}

/// Places the GPU instances [`walk_scene`] lists: the world transform of
/// each object that is instance `k` of a node becomes the node's world
/// transform × the instance's own (its translation, rotation and scale, in
/// the node's space, as the extension defines). Rotations must be unit
/// quaternions up to rounding (they are normalised); every transform must
/// stay finite.
pub(crate) fn place_gpu_instances(
    doc: &gltf::Document,
    buffers: &[Cow<'_, [u8]>],
    instances: &mut [Instance],
    source: &str,
) -> Result<()> {
    let mut i = 0;
    while i < instances.len() {
        if instances[i].gpu_instance.is_none() {
            i += 1;
            continue;
        }
        let n = instances[i].node;
        let end = i + instances[i..].iter().take_while(|x| x.node == n).count();
        let g = gpu_instancing(doc, n, source)?
            .ok_or_else(|| Error::Internal(format!("node {n} lost its instancing")))?;
        let what = format!("{source}: node {n} extensions.{EXT_INSTANCING}");
        let accessor = |k: usize| g.trs[k].and_then(|a| doc.accessors().nth(a));
        let read3 = |k: usize, name: &str| {
            accessor(k)
                .map(|a| read_floats::<3>(&a, buffers, &format!("{what} {name}"), Dimensions::Vec3))
                .transpose()
        };
        let translation = read3(0, "TRANSLATION")?;
        let rotation = accessor(1)
            .map(|a| read_floats::<4>(&a, buffers, &format!("{what} ROTATION"), Dimensions::Vec4))
            .transpose()?;
        let scale = read3(2, "SCALE")?;
        for inst in &mut instances[i..end] {
            let k = inst.gpu_instance.unwrap_or(0) as usize;
            let at = |v: &Option<Vec<[f32; 3]>>, default: DVec3| {
                v.as_ref()
                    .map_or(default, |v| DVec3::from_array(v[k].map(f64::from)))
            };
            let t = at(&translation, DVec3::ZERO);
            let s = at(&scale, DVec3::ONE);
            let q = rotation.as_ref().map_or(DQuat::IDENTITY, |r| {
                let [x, y, z, w] = r[k].map(f64::from);
                DQuat::from_xyzw(x, y, z, w)
            });
            let len = q.length();
            if !len.is_finite() || len < 1e-6 {
                return Err(Error::bad(
                    format!("{what} ROTATION"),
                    format!("instance {k}: {q:?} is not a unit quaternion"),
                ));
            }
            let world = inst.world * DAffine3::from_scale_rotation_translation(s, q / len, t);
            if !world.is_finite() {
                return Err(Error::bad(
                    what,
                    format!("instance {k}: the world transform is not finite"),
                ));
            }
            inst.world = world;
        }
        i = end;
    }
    Ok(())
}

/// Most coarser levels one node may name (so an object has at most 32).
pub(super) const MAX_LOD_IDS: usize = 31;

/// The `MSFT_lod.ids` of every node that has them (checked: integers naming
/// other, existing nodes, each once, at most [`MAX_LOD_IDS`]).
pub(super) fn lod_ids(doc: &gltf::Document, source: &str) -> Result<Vec<Option<Vec<usize>>>> {
    let json_nodes = &doc.as_json().nodes;
    let count = json_nodes.len();
    let mut out = Vec::with_capacity(count);
    for (n, node) in json_nodes.iter().enumerate() {
        let Some(ext) = node
            .extensions
            .as_ref()
            .and_then(|e| e.others.get("MSFT_lod"))
        else {
            out.push(None);
            continue;
        };
        let what = format!("{source}: node {n} extensions.MSFT_lod.ids");
        let Some(list) = ext.get("ids").and_then(serde_json::Value::as_array) else {
            return Err(Error::bad(what, "is missing or not an array"));
        };
        if list.is_empty() {
            return Err(Error::bad(what, "is empty"));
        }
        if list.len() > MAX_LOD_IDS {
            return Err(Error::bad(
                what,
                format!("names {} levels, at most {MAX_LOD_IDS}", list.len()),
            ));
        }
        let mut ids: Vec<usize> = Vec::with_capacity(list.len());
        for (k, v) in list.iter().enumerate() {
            let id = v
                .as_u64()
                .and_then(|id| usize::try_from(id).ok())
                .filter(|&id| id < count)
                .ok_or_else(|| {
                    Error::bad(
                        &what,
                        format!("entry {k} ({v}) is not a node index (the file has {count} nodes)"),
                    )
                })?;
            if id == n {
                return Err(Error::bad(
                    &what,
                    format!("entry {k} names the node itself"),
                ));
            }
            if ids.contains(&id) {
                return Err(Error::bad(&what, format!("entry {k} repeats node {id}")));
            }
            ids.push(id);
        }
        out.push(Some(ids));
    }
    Ok(out)
}

/// The `extras.MSFT_screencoverage` of node `n` as the `min_coverage` of
/// levels 0 … `levels` (`levels + 1` values, or `levels` values and a final
/// 0), or `None` when the node has no such entry.
pub(super) fn screen_coverage(
    extras: &gltf::json::Extras,
    n: usize,
    levels: usize,
    source: &str,
) -> Result<Option<Vec<f64>>> {
    /// The one entry of a node's extras that matters here.
    #[derive(serde::Deserialize)]
    struct NodeExtras {
        #[serde(rename = "MSFT_screencoverage", default)]
        coverage: Option<serde_json::Value>,
    }
    let what = format!("{source}: node {n} extras.MSFT_screencoverage");
    let Some(raw) = extras else {
        return Ok(None);
    };
    // Only an object can carry the entry (a struct would also accept an array).
    if !raw.get().trim_start().starts_with('{') {
        return Ok(None);
    }
    let parsed: NodeExtras = serde_json::from_str(raw.get())
        .map_err(|e| Error::bad(&what, format!("the node's extras cannot be read: {e}")))?;
    let Some(value) = parsed.coverage else {
        return Ok(None);
    };
    let Some(list) = value.as_array() else {
        return Err(Error::bad(what, "is not an array of numbers"));
    };
    let mut values = Vec::with_capacity(levels + 1);
    for (k, v) in list.iter().enumerate() {
        match v.as_f64() {
            Some(c) if c.is_finite() && (0.0..=1.0).contains(&c) => values.push(c),
            _ => {
                return Err(Error::bad(
                    what,
                    format!("value {k} ({v}) is not a number in [0, 1]"),
                ));
            }
        }
    }
    if values.len() == levels {
        if values.last().is_some_and(|&c| c <= 0.0) {
            return Err(Error::bad(
                what,
                format!(
                    "has {levels} values ending in 0 for {levels} MSFT_lod levels: the last \
                     level would never be drawn"
                ),
            ));
        }
        values.push(0.0);
    } else if values.len() != levels + 1 {
        return Err(Error::bad(
            what,
            format!(
                "has {} values for {levels} MSFT_lod levels; expected {} (one per level, the \
                 node's own first) or {levels} (the last level never culled)",
                values.len(),
                levels + 1
            ),
        ));
    }
    if let Some(k) = (1..values.len()).find(|&k| values[k] >= values[k - 1]) {
        return Err(Error::bad(
            what,
            format!(
                "values must be strictly decreasing, but value {k} ({}) is not below value {} ({})",
                values[k],
                k - 1,
                values[k - 1]
            ),
        ));
    }
    Ok(Some(values))
}

/// Walks the default scene depth-first in pre-order, children in array
/// order, without recursion; returns the nodes that carry a mesh with their
/// world transforms and their levels of detail.
///
/// A node with `EXT_mesh_gpu_instancing` is one object per instance, in
/// instance order, each with the node's world transform until
/// [`place_gpu_instances`] adds the instance's own (the walk reads no
/// buffer). Its instances cannot have `MSFT_lod` levels.
///
/// Nodes named in some node's `MSFT_lod.ids` are levels of detail, not
/// objects: wherever they appear in the scene they and their subtrees are
/// skipped. An object whose node has `MSFT_lod` and
/// `extras.MSFT_screencoverage` gets its levels, each placed by the object's
/// parent world transform × the level node's local transform.
pub(crate) fn walk_scene(doc: &gltf::Document, source: &str) -> Result<Vec<Instance>> {
    const UNVISITED: usize = usize::MAX;
    const ROOT: usize = usize::MAX - 1;

    let Some(scene) = doc.default_scene().or_else(|| doc.scenes().next()) else {
        return Ok(Vec::new());
    };
    // Each node is reached at most once, so the objects are at most the
    // nodes that draw a mesh and their GPU instances: too many is refused
    // before the walk.
    let instancing: Vec<Option<GpuInstancing>> = doc
        .nodes()
        .map(|n| match n.mesh() {
            Some(_) => gpu_instancing(doc, n.index(), source),
            None => Ok(None),
        })
        .collect::<Result<_>>()?;
    let drawing = doc
        .nodes()
        .filter(|n| n.mesh().is_some())
        .map(|n| instancing[n.index()].map_or(1, |g| g.count))
        .fold(0usize, usize::saturating_add);
    if drawing > crate::scene::MAX_OBJECTS {
        return Err(Error::bad(
            source,
            format!(
                "{drawing} nodes and GPU instances draw a mesh, more than the {} objects a \
                 scene may have",
                crate::scene::MAX_OBJECTS
            ),
        ));
    }
    let nodes: Vec<gltf::Node> = doc.nodes().collect();
    let json_nodes = &doc.as_json().nodes;
    let lod_ids = lod_ids(doc, source)?;
    let mut is_level = vec![false; nodes.len()];
    for &id in lod_ids.iter().flatten().flatten() {
        is_level[id] = true;
    }
    // parent[n]: the node n was reached from (ROOT for scene roots).
    let mut parent = vec![UNVISITED; nodes.len()];
    let mut instances = Vec::new();
    let mut stack: Vec<(usize, usize, DAffine3)> = Vec::new();
    let roots: Vec<usize> = scene.nodes().map(|n| n.index()).collect();
    stack.extend(roots.iter().rev().map(|&n| (n, ROOT, DAffine3::IDENTITY)));

    while let Some((n, from, parent_world)) = stack.pop() {
        if parent[n] != UNVISITED {
            let what = format!("{source}: node {n}");
            // Is n an ancestor of (or equal to) the node it was reached from?
            let mut a = from;
            while a != ROOT {
                if a == n {
                    return Err(Error::bad(
                        what,
                        "the node hierarchy has a cycle through this node",
                    ));
                }
                a = parent[a];
            }
            if from == ROOT && parent[n] == ROOT {
                return Err(Error::bad(
                    what,
                    format!("is listed twice in scene {}", scene.index()),
                ));
            }
            let describe = |p: usize| {
                if p == ROOT {
                    format!("scene {}", scene.index())
                } else {
                    format!("node {p}")
                }
            };
            return Err(Error::bad(
                what,
                format!(
                    "is reachable twice (from {} and from {}); every node must have one parent",
                    describe(parent[n]),
                    describe(from)
                ),
            ));
        }
        parent[n] = from;
        if is_level[n] {
            // A level of detail of some object, not an object itself.
            continue;
        }
        let node = &nodes[n];
        let local = local_transform(node, source)?;
        let world = parent_world * local;
        if !world.is_finite() {
            return Err(Error::bad(
                format!("{source}: node {n}"),
                "the world transform is not finite (overflow in the node hierarchy)",
            ));
        }
        if let Some(mesh) = node.mesh() {
            let lods = match &lod_ids[n] {
                None => None,
                Some(ids) => match screen_coverage(&json_nodes[n].extras, n, ids.len(), source)? {
                    None => None,
                    Some(min_coverage) => Some(LodChain {
                        levels: ids
                            .iter()
                            .enumerate()
                            .map(|(k, &id)| lod_node(&nodes[id], n, k + 1, parent_world, source))
                            .collect::<Result<_>>()?,
                        min_coverage,
                    }),
                },
            };
            match instancing[n] {
                None => instances.push(Instance {
                    node: n,
                    mesh: mesh.index(),
                    world,
                    lods,
                    gpu_instance: None,
                }),
                Some(_) if lods.is_some() => {
                    return Err(Error::bad(
                        format!("{source}: node {n}"),
                        format!(
                            "has both MSFT_lod levels and {EXT_INSTANCING}; levels of detail of \
                             GPU instances are not supported (expand the instances into nodes)"
                        ),
                    ));
                }
                Some(g) => instances.extend((0..g.count).map(|k| Instance {
                    node: n,
                    mesh: mesh.index(),
                    world,
                    lods: None,
                    gpu_instance: Some(k as u32),
                })),
            }
        }
        if let Some(children) = &json_nodes[n].children {
            stack.extend(children.iter().rev().map(|c| (c.value(), n, world)));
        }
    }
    Ok(instances)
}

/// Level `level` of the object of node `base`: the node `node`, which must
/// carry a mesh, placed by the base's parent world transform.
pub(super) fn lod_node(
    node: &gltf::Node,
    base: usize,
    level: usize,
    parent_world: DAffine3,
    source: &str,
) -> Result<LodNode> {
    let id = node.index();
    let Some(mesh) = node.mesh() else {
        return Err(Error::bad(
            format!("{source}: node {id}"),
            format!("is level {level} of node {base} (MSFT_lod) but has no mesh"),
        ));
    };
    let world = parent_world * local_transform(node, source)?;
    if !world.is_finite() {
        return Err(Error::bad(
            format!("{source}: node {id}"),
            format!("the world transform of level {level} of node {base} is not finite"),
        ));
    }
    Ok(LodNode {
        mesh: mesh.index(),
        world,
    })
}

/// A node's local transform in f64; rejects non-finite, non-affine and
/// degenerate rotations.
pub(super) fn local_transform(node: &gltf::Node, source: &str) -> Result<DAffine3> {
    let what = || format!("{source}: node {}", node.index());
    match node.transform() {
        gltf::scene::Transform::Matrix { matrix } => {
            let m = matrix.map(|c| c.map(f64::from));
            if !m.iter().flatten().all(|v| v.is_finite()) {
                return Err(Error::bad(format!("{} matrix", what()), "is not finite"));
            }
            let last_row = [m[0][3], m[1][3], m[2][3], m[3][3]];
            let affine = last_row
                .iter()
                .zip([0.0, 0.0, 0.0, 1.0])
                .all(|(a, b)| (a - b).abs() <= 1e-5);
            if !affine {
                return Err(Error::bad(
                    format!("{} matrix", what()),
                    format!("is not affine: its last row is {last_row:?}, expected [0, 0, 0, 1]"),
                ));
            }
            let col = |i: usize| DVec3::new(m[i][0], m[i][1], m[i][2]);
            Ok(DAffine3 {
                matrix3: DMat3::from_cols(col(0), col(1), col(2)),
                translation: col(3),
            })
        }
        gltf::scene::Transform::Decomposed {
            translation,
            rotation,
            scale,
        } => {
            let t = DVec3::from_array(translation.map(f64::from));
            let s = DVec3::from_array(scale.map(f64::from));
            let r = rotation.map(f64::from);
            if !t.is_finite() {
                return Err(Error::bad(
                    format!("{} translation", what()),
                    "is not finite",
                ));
            }
            if !s.is_finite() {
                return Err(Error::bad(format!("{} scale", what()), "is not finite"));
            }
            let q = DQuat::from_xyzw(r[0], r[1], r[2], r[3]);
            let len = q.length();
            if !len.is_finite() || len < 1e-6 {
                return Err(Error::bad(
                    format!("{} rotation", what()),
                    format!("{r:?} is not a unit quaternion"),
                ));
            }
            Ok(DAffine3::from_scale_rotation_translation(s, q / len, t))
        }
    }
}

/// The world box of the 8 corners of a local box under an affine transform.
pub(super) fn transform_box(world: &DAffine3, min: DVec3, max: DVec3) -> (DVec3, DVec3) {
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    for corner in 0..8 {
        let p = DVec3::new(
            if corner & 1 == 0 { min.x } else { max.x },
            if corner & 2 == 0 { min.y } else { max.y },
            if corner & 4 == 0 { min.z } else { max.z },
        );
        let w = world.transform_point3(p);
        lo = lo.min(w);
        hi = hi.max(w);
    }
    (lo, hi)
}
