// Which CPV of a placement a view belongs to (../shared/DESIGN.md,
// "Conventions"): its position in the CPV's region (min inclusive, max
// exclusive, except at the view space's maximum) and its direction in the
// CPV's VDI (a rectangle [u], [v] on one cube face).

/// The cube face of direction `d` and its (u, v): face = 2·axis + (0 if
/// positive else 1); a direction on an edge belongs to the lower face.
export function cubeFace(d) {
  let axis = 0;
  for (let a = 1; a < 3; a++) if (Math.abs(d[a]) > Math.abs(d[axis])) axis = a;
  const m = Math.abs(d[axis]);
  const face = 2 * axis + (d[axis] >= 0 ? 0 : 1);
  const rest = [0, 1, 2].filter((a) => a !== axis).map((a) => d[a] / m);
  return { face, u: rest[0], v: rest[1] };
}

function inRegion(p, r, vsMax) {
  for (let a = 0; a < 3; a++) {
    if (p[a] < r.min[a]) return false;
    if (p[a] > r.max[a]) return false;
    if (p[a] === r.max[a] && r.max[a] !== vsMax[a]) return false;
  }
  return true;
}

function inVdi(f, dirs) {
  return f.face === dirs.face && f.u >= dirs.u[0] && f.u <= dirs.u[1] &&
    f.v >= dirs.v[0] && f.v <= dirs.v[1];
}

/// The first CPV of `cpvs` holding the view at `p` looking along `d`, or
/// null (a view in no CPV was proven within the target without impostors).
export function findCpv(cpvs, vsMax, p, d) {
  const f = cubeFace(d);
  for (const c of cpvs) {
    if (inVdi(f, c.directions) && inRegion(p, c.region, vsMax)) return c;
  }
  return null;
}

/// Gives every CPV of `cpvs` (as a placement file holds them,
/// `schemas/placement.schema.json`) its whole impostor list: a CPV written
/// as a change (`impostors_added`, `impostors_removed`) gets the list of the
/// CPV before it without the removed ids and with the added ones, ascending.
export function expandCpvLists(cpvs) {
  let prev = [];
  for (const [k, c] of cpvs.entries()) {
    if (!c.impostors) {
      if (k === 0) throw new Error("the placement's first CPV has no impostor list");
      const removed = new Set(c.impostors_removed || []);
      c.impostors = prev.filter((i) => !removed.has(i))
        .concat(c.impostors_added || []).sort((a, b) => a - b);
      delete c.impostors_added;
      delete c.impostors_removed;
    }
    prev = c.impostors;
  }
  return cpvs;
}
