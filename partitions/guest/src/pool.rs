//! The guest's page pool: the free memory of its partition (syssw maps it at
//! `POOL_BASE`, see `user_rt::partition`) handed out page by page to back its processes'
//! memory. A bitmap over the pool's pages; runs of contiguous pages are handed out first
//! fit, so a segment can be mapped into a process with one `map` call. Each page in use
//! counts its references: a page a `fork` shares between parent and child (copy-on-write)
//! has one per process, and is free again when the last one goes.

/// Most pages a pool manages (256 MiB).
pub const MAX_POOL_PAGES: usize = 65536;

/// Most references one page can have (more processes than a guest ever has).
pub const MAX_REFERENCES: u8 = u8::MAX;

/// Free/used state and reference counts of up to [`MAX_POOL_PAGES`] pages, by index.
pub struct PagePool {
    used: [u64; MAX_POOL_PAGES / 64],
    references: [u8; MAX_POOL_PAGES],
    pages: usize,
    free: usize,
}

impl PagePool {
    /// A pool of `pages` free pages (at most [`MAX_POOL_PAGES`]; more are ignored).
    pub const fn new(pages: usize) -> Self {
        let pages = if pages > MAX_POOL_PAGES {
            MAX_POOL_PAGES
        } else {
            pages
        };
        Self {
            used: [0; MAX_POOL_PAGES / 64],
            references: [0; MAX_POOL_PAGES],
            pages,
            free: pages,
        }
    }

    pub fn free_pages(&self) -> usize {
        self.free
    }

    pub fn is_used(&self, page: usize) -> bool {
        page < self.pages && self.used[page / 64] & (1 << (page % 64)) != 0
    }

    fn set(&mut self, page: usize, used: bool) {
        if used {
            self.used[page / 64] |= 1 << (page % 64);
        } else {
            self.used[page / 64] &= !(1 << (page % 64));
        }
    }

    /// The first free page from `page` on (a word of 64 used pages at a time).
    fn first_free_from(&self, page: usize) -> Option<usize> {
        let mut p = page;
        while p < self.pages {
            // The pages below `p` in its word count as used.
            let word = self.used[p / 64] | ((1u64 << (p % 64)) - 1);
            if word != u64::MAX {
                let free = p / 64 * 64 + word.trailing_ones() as usize;
                return (free < self.pages).then_some(free);
            }
            p = (p / 64 + 1) * 64;
        }
        None
    }

    /// The first run of `count` free pages, marked used with one reference each; `None`
    /// if there is none.
    pub fn alloc(&mut self, count: usize) -> Option<usize> {
        if count == 0 || count > self.free {
            return None;
        }
        let mut start = self.first_free_from(0)?;
        while start + count <= self.pages {
            match (start..start + count).rev().find(|&p| self.is_used(p)) {
                Some(used) => start = self.first_free_from(used + 1)?,
                None => {
                    for p in start..start + count {
                        self.set(p, true);
                        self.references[p] = 1;
                    }
                    self.free -= count;
                    return Some(start);
                }
            }
        }
        None
    }

    /// How many references page `page` has (0: free).
    pub fn references(&self, page: usize) -> u8 {
        if self.is_used(page) {
            self.references[page]
        } else {
            0
        }
    }

    /// Adds a reference to page `page` (in use); false if it is free or has
    /// [`MAX_REFERENCES`] already (then nothing changed).
    pub fn share(&mut self, page: usize) -> bool {
        if !self.is_used(page) || self.references[page] == MAX_REFERENCES {
            return false;
        }
        self.references[page] += 1;
        true
    }

    /// Drops a reference to page `page`; the last one frees it (returns whether it did).
    /// A page not in use is left as it is.
    pub fn free(&mut self, page: usize) -> bool {
        if !self.is_used(page) {
            return false;
        }
        self.references[page] = self.references[page].saturating_sub(1);
        if self.references[page] > 0 {
            return false;
        }
        self.set(page, false);
        self.free += 1;
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hands_out_runs_first_fit_and_takes_them_back() {
        let mut p = PagePool::new(10);
        assert_eq!(p.alloc(3), Some(0));
        assert_eq!(p.alloc(3), Some(3));
        p.free(1);
        assert_eq!(p.alloc(2), Some(6));
        assert_eq!(p.alloc(1), Some(1));
        assert_eq!(p.free_pages(), 2);
        assert_eq!(p.alloc(3), None);
        assert_eq!(p.alloc(2), Some(8));
        assert_eq!(p.alloc(1), None);
        p.free(100);
        p.free(0);
        p.free(0);
        assert_eq!(p.free_pages(), 1);
        assert_eq!(p.alloc(0), None);
        assert_eq!(PagePool::new(usize::MAX).free_pages(), MAX_POOL_PAGES);
    }

    #[test]
    fn a_shared_page_is_free_after_its_last_reference() {
        let mut p = PagePool::new(4);
        let a = p.alloc(1).unwrap();
        assert_eq!(p.references(a), 1);
        assert!(p.share(a));
        assert!(p.share(a));
        assert_eq!(p.references(a), 3);
        assert!(!p.free(a));
        assert!(!p.free(a));
        assert_eq!(p.free_pages(), 3);
        assert!(p.free(a));
        assert_eq!((p.references(a), p.free_pages()), (0, 4));
        assert!(!p.share(a), "a free page cannot be shared");
        assert!(!p.free(a));
        let b = p.alloc(1).unwrap();
        for _ in 1..MAX_REFERENCES {
            assert!(p.share(b));
        }
        assert!(!p.share(b), "the count never wraps");
        assert_eq!(p.references(b), MAX_REFERENCES);
    }

    #[test]
    fn finds_free_pages_past_full_words_and_holes() {
        let mut p = PagePool::new(200);
        assert_eq!(p.alloc(130), Some(0));
        p.free(5);
        p.free(70);
        p.free(71);
        assert_eq!(p.alloc(3), Some(130), "no hole of three");
        assert_eq!(p.alloc(2), Some(70));
        assert_eq!(p.alloc(1), Some(5));
        assert_eq!(p.free_pages(), 67);
        assert_eq!(p.alloc(68), None);
        p.free(7);
        assert_eq!(p.alloc(2), Some(133), "past the single hole at 7");
        assert_eq!(p.alloc(1), Some(7));
        assert_eq!(p.alloc(65), Some(135));
        assert_eq!(p.alloc(1), None);
    }
}
