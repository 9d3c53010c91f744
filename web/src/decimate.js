// Decimation of large scenes for display: the viewer draws the scene as
// uploaded unless it has more triangles than a budget; then every mesh's
// index buffer is simplified by the same ratio with meshoptimizer's
// simplifier (edges collapsed, or vertices clustered for meshes of many
// small parts, within a tenth of the mesh's size), so a map of tens of
// millions of triangles stays drawable.
// Only what is drawn changes: objects, their meshes and node transforms,
// and the placement are untouched.
import * as THREE from "three";
import { MeshoptSimplifier } from "meshoptimizer";

/// Scenes over this many triangles (counted per drawn instance) are
/// decimated for display unless the page says otherwise
/// (`#/jobs/ID/view?triangles=N`, 0: never).
export const DISPLAY_TRIANGLES = 5_000_000;

/// The triangles of one geometry.
function triangles(g) {
  return (g.index ? g.index.count : g.attributes.position.count) / 3;
}

/// Each geometry of `root` with the number of times it is drawn, but for
/// the subtrees of the nodes in `skip` (levels of detail not drawn).
function geometryUses(root, skip) {
  const uses = new Map();
  const visit = (o) => {
    if (skip.has(o)) return;
    if (o.isMesh && o.geometry) {
      const n = o.isInstancedMesh ? o.count : 1;
      uses.set(o.geometry, (uses.get(o.geometry) || 0) + n);
    }
    for (const c of o.children) visit(c);
  };
  visit(root);
  return uses;
}

/// Simplifies the meshes of `root` (but under `skip`) towards `budget`
/// triangles when it has more; returns { before, after } (equal when
/// nothing was done). Meshes too simple to lose triangles within the error
/// keep them, so `after` can stay above the budget.
export async function decimate(root, budget, skip = new Set()) {
  const uses = geometryUses(root, skip);
  let before = 0;
  for (const [g, n] of uses) before += triangles(g) * n;
  if (!(budget > 0) || before <= budget) return { before, after: before };
  await MeshoptSimplifier.ready;
  const ratio = budget / before;
  let after = 0;
  for (const [g, n] of uses) {
    const pos = g.attributes.position;
    if (g.drawRange.count !== Infinity || g.groups.length > 1 || pos.count < 3) {
      after += triangles(g) * n;
      continue;
    }
    // Positions as plain floats (quantized or interleaved attributes read
    // through the accessor).
    const positions = new Float32Array(pos.count * 3);
    for (let i = 0; i < pos.count; i++) {
      positions[3 * i] = pos.getX(i);
      positions[3 * i + 1] = pos.getY(i);
      positions[3 * i + 2] = pos.getZ(i);
    }
    const index = g.index
      ? Uint32Array.from(g.index.array)
      : Uint32Array.from({ length: pos.count }, (_, i) => i);
    const target = Math.max(3, Math.floor((index.length * ratio) / 3) * 3);
    // Edge collapses first (small disconnected parts may go); meshes built
    // of many small parts (windows, leaves) that keep more than half as
    // much again as the target are clustered instead.
    let [out] = MeshoptSimplifier.simplify(index, positions, 3, target, 0.1, ["Prune"]);
    if (out.length > 1.5 * target) {
      const [sloppy] = MeshoptSimplifier.simplifySloppy(index, positions, 3, null, target, 0.1);
      if (sloppy.length > 0 && sloppy.length < out.length) out = sloppy;
    }
    if (out.length < index.length) g.setIndex(new THREE.BufferAttribute(out, 1));
    after += triangles(g) * n;
  }
  return { before, after };
}
