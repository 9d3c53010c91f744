//! Ascending ids written as the gaps between them, seven bits a byte
//! (LEB128): about a byte an id where the ids lie close together, instead
//! of four. The greedy's log of what each accept changed and a tile's
//! packed placement both hold their id lists so.

/// Appends `ids` (ascending) to `buf` as gaps from 0 and between them.
pub fn push(buf: &mut Vec<u8>, ids: impl IntoIterator<Item = u32>) {
    let mut last = 0u32;
    for id in ids {
        debug_assert!(id >= last, "ids in ascending order");
        let mut gap = id - last;
        last = id;
        while gap >= 0x80 {
            buf.push((gap & 0x7f) as u8 | 0x80);
            gap >>= 7;
        }
        buf.push(gap as u8);
    }
}

/// The ids [`push`] wrote into `bytes` (one call's bytes, whole).
pub fn read(bytes: &[u8]) -> Read<'_> {
    Read {
        bytes,
        at: 0,
        last: 0,
    }
}

/// Iterator of [`read`].
pub struct Read<'a> {
    bytes: &'a [u8],
    at: usize,
    last: u32,
}

impl Iterator for Read<'_> {
    type Item = u32;

    fn next(&mut self) -> Option<u32> {
        let (mut gap, mut shift) = (0u32, 0);
        loop {
            let b = *self.bytes.get(self.at)?;
            self.at += 1;
            gap |= u32::from(b & 0x7f) << shift;
            if b & 0x80 == 0 {
                self.last += gap;
                return Some(self.last);
            }
            shift += 7;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Gaps of one to five bytes read back as written.
    #[test]
    fn ids_read_back_as_pushed() {
        let ids = [0u32, 127, 128, 16_383, 16_384, 2_097_152, u32::MAX];
        let mut buf = Vec::new();
        push(&mut buf, ids);
        // Gaps 0, 127, 1, 16,255, 1, 2,080,768 and 4,292,870,143.
        assert_eq!(buf.len(), 1 + 1 + 1 + 2 + 1 + 3 + 5);
        assert_eq!(read(&buf).collect::<Vec<_>>(), ids);
        assert_eq!(read(&[]).count(), 0);
        // Gaps of exactly 128 and 2¹⁴ take a byte more than one below.
        let edges = [128u32, 256, 256 + (1 << 14)];
        let mut buf = Vec::new();
        push(&mut buf, edges);
        assert_eq!(buf.len(), 2 + 2 + 3);
        assert_eq!(read(&buf).collect::<Vec<_>>(), edges);
    }
}
