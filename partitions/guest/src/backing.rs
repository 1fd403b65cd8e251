//! Which page of the guest's pool backs which page of a process: a table sorted by the
//! process's page address, stored in memory the caller provides (16 bytes an entry: the
//! page address and the pool page index, little-endian), so its capacity follows the pool's
//! size rather than a constant.

/// Bytes of one entry.
pub const ENTRY: usize = 16;

/// The table is full.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Full;

pub struct Backing<'b> {
    bytes: &'b mut [u8],
    len: usize,
}

impl<'b> Backing<'b> {
    /// An empty table in `bytes` (room for `bytes.len() / 16` entries).
    pub fn new(bytes: &'b mut [u8]) -> Self {
        Self { bytes, len: 0 }
    }

    pub fn capacity(&self) -> usize {
        self.bytes.len() / ENTRY
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    fn entry(&self, i: usize) -> (u64, usize) {
        let e = &self.bytes[i * ENTRY..(i + 1) * ENTRY];
        let page = u64::from_le_bytes(e[..8].try_into().unwrap_or_default());
        let index = u64::from_le_bytes(e[8..].try_into().unwrap_or_default());
        (page, index as usize)
    }

    fn set(&mut self, i: usize, page: u64, index: usize) {
        let e = &mut self.bytes[i * ENTRY..(i + 1) * ENTRY];
        e[..8].copy_from_slice(&page.to_le_bytes());
        e[8..].copy_from_slice(&(index as u64).to_le_bytes());
    }

    /// Position of `page`, or where it would go.
    fn search(&self, page: u64) -> Result<usize, usize> {
        let (mut lo, mut hi) = (0, self.len);
        while lo < hi {
            let mid = (lo + hi) / 2;
            match self.entry(mid).0.cmp(&page) {
                core::cmp::Ordering::Equal => return Ok(mid),
                core::cmp::Ordering::Less => lo = mid + 1,
                core::cmp::Ordering::Greater => hi = mid,
            }
        }
        Err(lo)
    }

    /// Position of the first entry at or after `page`.
    fn first_at(&self, page: u64) -> usize {
        self.search(page).unwrap_or_else(|i| i)
    }

    /// The pool page backing the process page at `page` (page-aligned).
    pub fn get(&self, page: u64) -> Option<usize> {
        self.search(page).ok().map(|i| self.entry(i).1)
    }

    /// The first entry at or after `page`: its page and pool page.
    pub fn first_from(&self, page: u64) -> Option<(u64, usize)> {
        let i = self.first_at(page);
        (i < self.len).then(|| self.entry(i))
    }

    /// Records that pool page `index` backs `page` (replacing an older entry for it).
    pub fn insert(&mut self, page: u64, index: usize) -> Result<(), Full> {
        match self.search(page) {
            Ok(i) => self.set(i, page, index),
            Err(i) => {
                if self.len == self.capacity() {
                    return Err(Full);
                }
                self.bytes
                    .copy_within(i * ENTRY..self.len * ENTRY, (i + 1) * ENTRY);
                self.set(i, page, index);
                self.len += 1;
            }
        }
        Ok(())
    }

    /// The entry at position `i` (below [`Backing::len`]): its page and pool page.
    pub fn at(&self, i: usize) -> (u64, usize) {
        self.entry(i)
    }

    /// The positions of the entries with pages in `from..to`.
    pub fn positions(&self, from: u64, to: u64) -> core::ops::Range<usize> {
        let start = self.first_at(from);
        start..self.first_at(to).max(start)
    }

    /// Copies the entries with pages in `from..to` to the same pages moved to `onto`
    /// (`onto + (page - from)`), backed by the same pool pages, in one move of the entries
    /// after them; the range they go to must hold no entry and not overlap `from..to`.
    /// Returns how many were copied; nothing is copied when they do not all fit.
    pub fn copy_range(&mut self, from: u64, to: u64, onto: u64) -> Result<usize, Full> {
        let source = self.positions(from, to);
        let n = source.len();
        let at = self.first_at(onto);
        debug_assert_eq!(
            self.positions(onto, onto + (to - from)).len(),
            0,
            "copy onto backed pages"
        );
        if self.len + n > self.capacity() {
            return Err(Full);
        }
        self.bytes
            .copy_within(at * ENTRY..self.len * ENTRY, (at + n) * ENTRY);
        // The source moved along when it lay after the gap.
        let first = if source.start >= at {
            source.start + n
        } else {
            source.start
        };
        for i in 0..n {
            let (page, index) = self.entry(first + i);
            self.set(at + i, page - from + onto, index);
        }
        self.len += n;
        Ok(n)
    }

    /// Forgets `page`; returns the pool page that backed it.
    pub fn remove(&mut self, page: u64) -> Option<usize> {
        let i = self.search(page).ok()?;
        let index = self.entry(i).1;
        self.bytes
            .copy_within((i + 1) * ENTRY..self.len * ENTRY, i * ENTRY);
        self.len -= 1;
        Some(index)
    }

    /// Forgets every page in `from..to`, handing each page and pool page to `removed` (the
    /// entries after them move once).
    pub fn remove_range(&mut self, from: u64, to: u64, mut removed: impl FnMut(u64, usize)) {
        let core::ops::Range { start, end } = self.positions(from, to);
        for i in start..end {
            let (page, index) = self.entry(i);
            removed(page, index);
        }
        self.bytes
            .copy_within(end * ENTRY..self.len * ENTRY, start * ENTRY);
        self.len -= end - start;
    }

    /// Empties the table, handing each pool page to `free`.
    pub fn drain(&mut self, mut free: impl FnMut(usize)) {
        for i in 0..self.len {
            free(self.entry(i).1);
        }
        self.len = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_pages_sorted_and_bounded() {
        let mut bytes = [0u8; 4 * ENTRY];
        let mut b = Backing::new(&mut bytes);
        assert_eq!(b.capacity(), 4);
        b.insert(0x3000, 7).unwrap();
        b.insert(0x1000, 5).unwrap();
        b.insert(0x2000, 6).unwrap();
        b.insert(0x2000, 9).unwrap(); // replaced
        assert_eq!(
            (b.get(0x1000), b.get(0x2000), b.get(0x3000)),
            (Some(5), Some(9), Some(7))
        );
        assert_eq!(b.get(0x4000), None);
        assert_eq!(b.first_from(0x1800), Some((0x2000, 9)));
        assert_eq!(b.first_from(0x3000), Some((0x3000, 7)));
        assert_eq!(b.first_from(0x3001), None);
        b.insert(0x4000, 1).unwrap();
        assert_eq!(b.insert(0x5000, 2), Err(Full));
        assert_eq!(b.remove(0x2000), Some(9));
        assert_eq!(b.remove(0x2000), None);
        assert_eq!(b.len(), 3);
        b.insert(0x2000, 9).unwrap();
        let mut gone = Vec::new();
        b.remove_range(0x1800, 0x4000, |page, i| gone.push((page, i)));
        assert_eq!(gone, [(0x2000, 9), (0x3000, 7)]);
        assert_eq!(
            (b.len(), b.get(0x1000), b.get(0x4000)),
            (2, Some(5), Some(1))
        );
        b.remove_range(0x5000, 0x1000, |_, _| panic!("an empty range"));
        b.insert(0x3000, 7).unwrap();
        let mut freed = Vec::new();
        b.drain(|i| freed.push(i));
        assert_eq!(freed, [5, 7, 1]);
        assert!(b.is_empty());
    }

    #[test]
    fn a_range_is_copied_in_one_move_before_or_after_its_source() {
        let mut bytes = [0u8; 8 * ENTRY];
        let mut b = Backing::new(&mut bytes);
        for (page, index) in [(0x1_1000, 1), (0x1_2000, 2), (0x2_0000, 3), (0x3_5000, 4)] {
            b.insert(page, index).unwrap();
        }
        // After the source, between other entries.
        assert_eq!(b.copy_range(0x1_0000, 0x1_8000, 0x2_8000), Ok(2));
        let all = |b: &Backing| (0..b.len()).map(|i| b.at(i)).collect::<Vec<_>>();
        assert_eq!(
            all(&b),
            [
                (0x1_1000, 1),
                (0x1_2000, 2),
                (0x2_0000, 3),
                (0x2_9000, 1),
                (0x2_a000, 2),
                (0x3_5000, 4)
            ]
        );
        // Before the source.
        assert_eq!(b.copy_range(0x3_0000, 0x4_0000, 0x0), Ok(1));
        assert_eq!(b.at(0), (0x5000, 4));
        assert_eq!(b.positions(0x2_8000, 0x3_0000), 4..6);
        assert_eq!(b.get(0x3_5000), Some(4), "the source stays");
        // Nothing is copied when the entries do not all fit.
        assert_eq!(b.copy_range(0x0, 0x3_0000, 0x4_0000), Err(Full));
        assert_eq!(b.len(), 7);
        assert_eq!(b.copy_range(0x9_0000, 0xa_0000, 0x4_0000), Ok(0));
    }
}
