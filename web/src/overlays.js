// Wireframe overlays of the viewer: impostors' view cells (shafts as cone
// frustums, boxes as boxes) and CPV regions (boxes).
import * as THREE from "three";

/// A box's edges from `min` to `max`.
export function boxLines(min, max, color) {
  const box = new THREE.Box3(new THREE.Vector3(...min), new THREE.Vector3(...max));
  return new THREE.Box3Helper(box, color);
}

/// The edges of many boxes as one object (`regions`: `{min, max}`).
export function regionLines(regions, color) {
  const pos = [];
  const edges = [[0, 1], [1, 3], [3, 2], [2, 0], [4, 5], [5, 7], [7, 6], [6, 4], [0, 4], [1, 5], [2, 6], [3, 7]];
  for (const r of regions) {
    const c = [];
    for (let i = 0; i < 8; i++) {
      c.push([i & 1 ? r.max[0] : r.min[0], i & 2 ? r.max[1] : r.min[1], i & 4 ? r.max[2] : r.min[2]]);
    }
    for (const [a, b] of edges) pos.push(...c[a], ...c[b]);
  }
  const geo = new THREE.BufferGeometry();
  geo.setAttribute("position", new THREE.Float32BufferAttribute(pos, 3));
  return new THREE.LineSegments(geo, new THREE.LineBasicMaterial({ color, transparent: true, opacity: 0.35 }));
}

/// A view cell: a shaft drawn from `min_distance` out to `length` metres
/// from its apex, or a box.
export function viewCell(cell, length, color) {
  if (cell.box) return boxLines(cell.box.min, cell.box.max, color);
  const s = cell.shaft;
  const tan = Math.tan((s.half_angle_deg * Math.PI) / 180);
  const near = s.min_distance, far = Math.max(near + 1, length);
  const height = far - near;
  // A cylinder along +y, wide end at the top, then turned onto the axis.
  const geo = new THREE.CylinderGeometry(far * tan, near * tan, height, 24, 1, true);
  geo.translate(0, near + height / 2, 0);
  const mesh = new THREE.Mesh(geo, new THREE.MeshBasicMaterial({ color, wireframe: true, transparent: true, opacity: 0.4 }));
  mesh.quaternion.setFromUnitVectors(new THREE.Vector3(0, 1, 0), new THREE.Vector3(...s.axis).normalize());
  mesh.position.set(...s.apex);
  return mesh;
}
