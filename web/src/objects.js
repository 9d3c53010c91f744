// Object ids of a glTF scene, as the optimizer numbers them (the contract
// of optimizer/src/scene/gltf_load/walk.rs, ARCHITECTURE.md "Object ids"):
// a depth-first pre-order walk of the default scene (`scene`, else scene
// 0), roots and children in array order, counting each node that carries a
// mesh, once per instance when it has `EXT_mesh_gpu_instancing`; a node named
// as a coarser level of detail by another node's `MSFT_lod.ids` is not an
// object and its subtree is not walked.

/// The JSON chunk of a GLB file.
export function glbJson(buffer) {
  const view = new DataView(buffer);
  if (buffer.byteLength < 20 || view.getUint32(0, true) !== 0x46546c67) {
    throw new Error("not a GLB file (no glTF magic)");
  }
  const length = view.getUint32(12, true);
  if (view.getUint32(16, true) !== 0x4e4f534a) throw new Error("the GLB's first chunk is not JSON");
  return JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 20, length)));
}

/// The number of GPU instances of `node` (`EXT_mesh_gpu_instancing`: the
/// count of its attributes' accessors), `null` without the extension.
function instanceCount(gltf, node) {
  const ext = node.extensions && node.extensions.EXT_mesh_gpu_instancing;
  if (!ext || !ext.attributes) return null;
  const a = ext.attributes.TRANSLATION ?? ext.attributes.ROTATION ?? ext.attributes.SCALE;
  const accessor = a === undefined ? undefined : (gltf.accessors || [])[a];
  if (!accessor) throw new Error("a node's EXT_mesh_gpu_instancing names no accessor");
  return accessor.count;
}

/// `{objects, instances, levels}`: the glTF node index of each object id, in
/// id order; which GPU instance of its node each object is (`null` for a
/// node drawn once); and the node indices that are `MSFT_lod` levels.
export function objectNodes(gltf) {
  const nodes = gltf.nodes || [];
  const levels = new Set();
  for (const n of nodes) {
    const ids = n.extensions && n.extensions.MSFT_lod && n.extensions.MSFT_lod.ids;
    if (Array.isArray(ids)) ids.forEach((id) => levels.add(id));
  }
  const scenes = gltf.scenes || [];
  const scene = scenes[gltf.scene ?? 0];
  const objects = [];
  const instances = [];
  if (!scene) return { objects, instances, levels };
  const stack = [...(scene.nodes || [])].reverse();
  const seen = new Set();
  while (stack.length) {
    const n = stack.pop();
    // The optimizer refuses scenes with cycles or shared nodes.
    if (seen.has(n)) throw new Error(`node ${n} is reachable twice`);
    seen.add(n);
    if (levels.has(n)) continue;
    const node = nodes[n];
    if (node.mesh !== undefined) {
      const count = instanceCount(gltf, node);
      if (count === null) {
        objects.push(n);
        instances.push(null);
      } else {
        for (let k = 0; k < count; k++) {
          objects.push(n);
          instances.push(k);
        }
      }
    }
    if (node.children) stack.push(...[...node.children].reverse());
  }
  return { objects, instances, levels };
}
