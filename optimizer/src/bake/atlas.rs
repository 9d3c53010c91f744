//! Atlas packing of baked layers. Every layer of an impostor lies in the
//! same atlas, so that an impostor is one primitive with one material (one
//! draw call, as the cost model counts it).
//!
//! Shelf packing, largest impostors first (then impostor order): an
//! impostor's layers (all of its resolution) go into the first atlas whose
//! free shelves hold all of them, else into a new atlas, `atlas_size`
//! texels wide, or wider when the impostor alone needs more (it is never
//! split across atlases). Each layer is framed by a gutter of edge-extended
//! texels so that mip levels do not bleed between neighbours.

use super::Layer;

/// Where a layer went: atlas index and top-left texel of its interior.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Slot {
    pub(super) atlas: u32,
    pub(super) x: u32,
    pub(super) y: u32,
}

/// The layers of one impostor, packed together: `count` squares of `res`
/// texels per side.
#[derive(Clone, Copy, Debug)]
pub(super) struct Group {
    pub(super) res: u32,
    pub(super) count: u32,
}

/// An atlas being filled: its width (its height may grow up to the width),
/// the current shelf's top and height, and the cursor on that shelf.
#[derive(Clone, Copy, Debug)]
struct Page {
    width: u32,
    shelf_y: u32,
    shelf_h: u32,
    cursor: u32,
}

impl Page {
    fn new(width: u32) -> Self {
        Page {
            width,
            shelf_y: 0,
            shelf_h: 0,
            cursor: 0,
        }
    }

    /// Places `count` squares of side `side` (gutters included) on the
    /// page's shelves; returns their top-left corners, or `None` (the page
    /// unchanged) when they do not all fit.
    fn place(&mut self, side: u32, count: u32) -> Option<Vec<(u32, u32)>> {
        let mut p = *self;
        let mut out = Vec::with_capacity(count as usize);
        for _ in 0..count {
            if side > p.width {
                return None;
            }
            if p.cursor + side > p.width {
                p.shelf_y += p.shelf_h;
                (p.shelf_h, p.cursor) = (0, 0);
            }
            // Pages are at most square.
            if p.shelf_y + side > p.width {
                return None;
            }
            out.push((p.cursor, p.shelf_y));
            p.cursor += side;
            p.shelf_h = p.shelf_h.max(side);
        }
        *self = p;
        Some(out)
    }

    /// The height used so far.
    fn height(&self) -> u32 {
        self.shelf_y + self.shelf_h
    }
}

/// Packs the groups (sides `res + 2·gutter`) into atlases of at most
/// `atlas_size` texels per side unless one group alone needs more. Returns,
/// per group (same order), one slot per layer, and each atlas's size (the
/// height rounded up to a multiple of 4).
pub(super) fn pack(
    groups: &[Group],
    atlas_size: u32,
    gutter: u32,
) -> (Vec<Vec<Slot>>, Vec<(u32, u32)>) {
    let mut order: Vec<usize> = (0..groups.len()).collect();
    order.sort_by_key(|&i| (std::cmp::Reverse(groups[i].res), i));
    let mut slots = vec![Vec::new(); groups.len()];
    let mut pages: Vec<Page> = Vec::new();
    for i in order {
        let Group { res, count } = groups[i];
        let side = res + 2 * gutter;
        let fits = pages
            .iter_mut()
            .enumerate()
            .find_map(|(a, p)| p.place(side, count).map(|at| (a, at)));
        let (a, at) = match fits {
            Some(f) => f,
            None => {
                // A square of ⌈√count⌉ layers per side always holds them.
                let per_side = (f64::from(count).sqrt().ceil() as u32).max(1);
                let mut page = Page::new(atlas_size.max(per_side * side));
                let at = page
                    .place(side, count)
                    .expect("a page ⌈√count⌉ layers wide holds count layers");
                pages.push(page);
                (pages.len() - 1, at)
            }
        };
        slots[i] = at
            .into_iter()
            .map(|(x, y)| Slot {
                atlas: a as u32,
                x: x + gutter,
                y: y + gutter,
            })
            .collect();
    }
    let sizes = pages
        .iter()
        .map(|p| (p.width, p.height().div_ceil(4) * 4))
        .collect();
    (slots, sizes)
}

/// Copies a layer into an atlas with edge-extended gutters.
pub(super) fn blit(atlas: &mut [u8], aw: u32, layer: &Layer, slot: Slot, gutter: u32) {
    let res = layer.res as i64;
    let g = i64::from(gutter);
    for dy in -g..res + g {
        for dx in -g..res + g {
            let (sx, sy) = (dx.clamp(0, res - 1), dy.clamp(0, res - 1));
            let src = ((sy * res + sx) * 4) as usize;
            let (tx, ty) = (i64::from(slot.x) + dx, i64::from(slot.y) + dy);
            let dst = ((ty * i64::from(aw) + tx) * 4) as usize;
            atlas[dst..dst + 4].copy_from_slice(&layer.rgba[src..src + 4]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packing_never_overlaps_stays_inside_and_keeps_impostors_whole() {
        let mut rng = crate::math::rng::Rng::new(3);
        let groups: Vec<Group> = (0..120)
            .map(|_| Group {
                res: 4 + (rng.next_u64() % 120) as u32,
                count: 1 + (rng.next_u64() % 6) as u32,
            })
            .collect();
        let (gutter, atlas) = (4, 512);
        let (slots, atlases) = pack(&groups, atlas, gutter);
        assert!(atlases.len() > 1);
        let mut rects = Vec::new();
        for (g, s) in groups.iter().zip(&slots) {
            assert_eq!(s.len(), g.count as usize);
            // One atlas per impostor.
            assert!(s.iter().all(|x| x.atlas == s[0].atlas));
            for x in s {
                rects.push((x.atlas, x.x - gutter, x.y - gutter, g.res + 2 * gutter));
            }
        }
        for (i, &(a, x, y, side)) in rects.iter().enumerate() {
            let (w, h) = atlases[a as usize];
            assert!(x + side <= w && y + side <= h && w <= atlas && h <= atlas);
            for &(b, x2, y2, side2) in &rects[..i] {
                let apart = a != b
                    || x + side <= x2
                    || x2 + side2 <= x
                    || y + side <= y2
                    || y2 + side2 <= y;
                assert!(apart, "layers overlap");
            }
        }
        // An impostor larger than the atlas size gets an atlas of its own,
        // wide enough for all its layers; the next impostor fills that
        // atlas's free space, and once it is full a regular one starts.
        let big = |count| Group { res: 300, count };
        let small = Group { res: 10, count: 1 };
        let (slots, atlases) = pack(&[big(3), small], 512, 2);
        assert_eq!(atlases, vec![(608, 608)]);
        assert!(slots.iter().flatten().all(|s| s.atlas == 0));
        let (slots, atlases) = pack(&[big(4), small], 512, 2);
        assert_eq!(atlases, vec![(608, 608), (512, 16)]);
        assert_eq!(
            slots[1][0],
            Slot {
                atlas: 1,
                x: 2,
                y: 2
            }
        );
        // A control: without groups the three layers would not share one
        // 512 atlas, so the test above did exercise the growth.
        assert!(Page::new(512).place(304, 3).is_none());
    }
}
