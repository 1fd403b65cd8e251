//! How a static Linux executable (ELF64, x86-64) is laid out in a new process: its
//! `PT_LOAD` segments with their rights, the page runs they cover, the entry point, where
//! the program headers lie in memory (for `AT_PHDR`) and where the heap (`brk`) starts.
//!
//! Static executables (`ET_EXEC`) load at their link addresses; static position-independent
//! ones (`ET_DYN` without `PT_INTERP`, self-relocating) load at [`PIE_BASE`]. An executable
//! that names an interpreter (dynamically linked) is refused: the guest has no dynamic
//! loader yet. Every offset, size and address is checked, so a hostile file yields an
//! [`ElfError`], never a panic.

use crate::memory::{PAGE, Rights, USER_TOP, page_down, page_up};

/// Most `PT_LOAD` segments a loadable executable may have.
pub const MAX_SEGMENTS: usize = 8;
/// Where a static PIE is loaded (Linux's `ELF_ET_DYN_BASE` on x86-64).
pub const PIE_BASE: u64 = 0x5555_5555_4000;
/// Lowest address a segment may occupy (the zero page stays unmapped).
pub const LOW_LIMIT: u64 = 0x1_0000;

const PT_LOAD: u32 = 1;
const PT_INTERP: u32 = 3;
const PT_PHDR: u32 = 6;
const ET_EXEC: u16 = 2;
const ET_DYN: u16 = 3;
const EM_X86_64: u16 = 62;
const PF_X: u32 = 1;
const PF_W: u32 = 2;
/// Size of one program header (`Elf64_Phdr`).
pub const PHENT: u64 = 56;

/// Why an executable cannot be loaded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ElfError {
    /// Not an ELF64 little-endian x86-64 file (or shorter than its header).
    NotElf,
    /// Neither `ET_EXEC` nor `ET_DYN`.
    NotExecutable,
    /// It names an interpreter (`PT_INTERP`): a dynamically linked program.
    Dynamic,
    /// The program-header table is malformed or outside the file.
    BadProgramHeaders,
    /// A segment (at this virtual address) is outside the file or user space, overlaps
    /// another, or has more file bytes than memory bytes.
    BadSegment(u64),
    TooManySegments,
    NoSegments,
    /// The entry point is not in an executable segment.
    BadEntry(u64),
}

impl core::fmt::Display for ElfError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::NotElf => write!(f, "not an ELF64 little-endian x86-64 file"),
            Self::NotExecutable => write!(f, "not an executable (ET_EXEC or ET_DYN)"),
            Self::Dynamic => write!(
                f,
                "dynamically linked (it names an interpreter); only static executables run"
            ),
            Self::BadProgramHeaders => write!(f, "malformed program-header table"),
            Self::BadSegment(at) => write!(f, "bad PT_LOAD segment at {at:#x}"),
            Self::TooManySegments => write!(f, "more than {MAX_SEGMENTS} PT_LOAD segments"),
            Self::NoSegments => write!(f, "no PT_LOAD segment"),
            Self::BadEntry(at) => write!(f, "entry point {at:#x} is not in an executable segment"),
        }
    }
}

/// One `PT_LOAD` segment, relocated.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Segment {
    pub vaddr: u64,
    pub mem_size: u64,
    pub file_offset: u64,
    pub file_size: u64,
    pub rights: Rights,
}

impl Segment {
    fn first_page(&self) -> u64 {
        page_down(self.vaddr)
    }
    fn end_page(&self) -> u64 {
        page_up(self.vaddr + self.mem_size)
    }
}

/// The pages to map for an executable: segments' pages, with the rights of every segment
/// that touches them (two segments may share a boundary page).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PageRun {
    pub start: u64,
    pub pages: u64,
    pub rights: Rights,
}

/// The layout of an executable in a new process.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LoadPlan {
    pub entry: u64,
    /// Where the program headers are in memory (`AT_PHDR`), their count and entry size.
    pub phdr: u64,
    pub phnum: u64,
    pub phent: u64,
    /// First address after the highest segment, page-aligned: the heap starts here.
    pub brk_start: u64,
    segments: [Segment; MAX_SEGMENTS],
    count: usize,
}

fn u16_at(b: &[u8], at: usize) -> Option<u16> {
    Some(u16::from_le_bytes(b.get(at..at + 2)?.try_into().ok()?))
}
fn u32_at(b: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(at..at + 4)?.try_into().ok()?))
}
fn u64_at(b: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(b.get(at..at + 8)?.try_into().ok()?))
}

impl LoadPlan {
    /// Checks `elf` and plans its layout.
    pub fn new(elf: &[u8]) -> Result<Self, ElfError> {
        if elf.len() < 64 || elf[..4] != *b"\x7fELF" || elf[4] != 2 || elf[5] != 1 {
            return Err(ElfError::NotElf);
        }
        if u16_at(elf, 18) != Some(EM_X86_64) {
            return Err(ElfError::NotElf);
        }
        let kind = u16_at(elf, 16).ok_or(ElfError::NotElf)?;
        let entry = u64_at(elf, 24).ok_or(ElfError::NotElf)?;
        let phoff = u64_at(elf, 32).ok_or(ElfError::NotElf)?;
        let phentsize = u16_at(elf, 54).ok_or(ElfError::NotElf)? as u64;
        let phnum = u16_at(elf, 56).ok_or(ElfError::NotElf)? as u64;
        let bias = match kind {
            ET_EXEC => 0,
            ET_DYN => PIE_BASE,
            _ => return Err(ElfError::NotExecutable),
        };
        if phentsize != PHENT || phnum == 0 {
            return Err(ElfError::BadProgramHeaders);
        }
        let table_end = phnum
            .checked_mul(PHENT)
            .and_then(|n| n.checked_add(phoff))
            .ok_or(ElfError::BadProgramHeaders)?;
        if table_end > elf.len() as u64 {
            return Err(ElfError::BadProgramHeaders);
        }
        let mut plan = LoadPlan {
            entry: entry.checked_add(bias).ok_or(ElfError::BadEntry(entry))?,
            phdr: 0,
            phnum,
            phent: PHENT,
            brk_start: 0,
            segments: [Segment::default(); MAX_SEGMENTS],
            count: 0,
        };
        let mut phdr_segment = None;
        for i in 0..phnum {
            let at = (phoff + i * PHENT) as usize;
            let field = |o: usize| u64_at(elf, at + o).ok_or(ElfError::BadProgramHeaders);
            let kind = u32_at(elf, at).ok_or(ElfError::BadProgramHeaders)?;
            let flags = u32_at(elf, at + 4).ok_or(ElfError::BadProgramHeaders)?;
            let (offset, vaddr, file_size, mem_size) =
                (field(8)?, field(16)?, field(32)?, field(40)?);
            match kind {
                PT_INTERP => return Err(ElfError::Dynamic),
                PT_PHDR => phdr_segment = Some(vaddr),
                PT_LOAD => {
                    let vaddr = vaddr.checked_add(bias).ok_or(ElfError::BadSegment(vaddr))?;
                    let bad = ElfError::BadSegment(vaddr);
                    let end = vaddr.checked_add(mem_size).ok_or(bad)?;
                    let file_end = offset.checked_add(file_size).ok_or(bad)?;
                    if file_size > mem_size
                        || file_end > elf.len() as u64
                        || vaddr < LOW_LIMIT
                        || end > USER_TOP
                        || mem_size == 0
                    {
                        return Err(bad);
                    }
                    let mut rights = Rights::READ;
                    if flags & PF_W != 0 {
                        rights |= Rights::WRITE;
                    }
                    if flags & PF_X != 0 {
                        rights |= Rights::EXECUTE;
                    }
                    if plan.count == MAX_SEGMENTS {
                        return Err(ElfError::TooManySegments);
                    }
                    let s = Segment {
                        vaddr,
                        mem_size,
                        file_offset: offset,
                        file_size,
                        rights,
                    };
                    // In ascending order, no byte shared (a page may be).
                    if let Some(prev) = plan.segments().last()
                        && prev.vaddr + prev.mem_size > vaddr
                    {
                        return Err(bad);
                    }
                    plan.segments[plan.count] = s;
                    plan.count += 1;
                }
                _ => {}
            }
        }
        if plan.count == 0 {
            return Err(ElfError::NoSegments);
        }
        plan.phdr = match phdr_segment {
            Some(vaddr) => vaddr.checked_add(bias).ok_or(ElfError::BadProgramHeaders)?,
            // No PT_PHDR: the table is wherever the segment holding its file bytes puts it.
            None => plan
                .segments()
                .iter()
                .find(|s| s.file_offset <= phoff && table_end <= s.file_offset + s.file_size)
                .map(|s| s.vaddr + (phoff - s.file_offset))
                .ok_or(ElfError::BadProgramHeaders)?,
        };
        let plan_entry = plan.entry;
        if !plan.segments().iter().any(|s| {
            s.rights.contains(Rights::EXECUTE)
                && s.vaddr <= plan_entry
                && plan_entry < s.vaddr + s.mem_size
        }) {
            return Err(ElfError::BadEntry(plan_entry));
        }
        plan.brk_start = plan
            .segments()
            .iter()
            .map(Segment::end_page)
            .max()
            .unwrap_or(0);
        Ok(plan)
    }

    pub fn segments(&self) -> &[Segment] {
        &self.segments[..self.count]
    }

    /// The page runs to map, in ascending order, disjoint: each segment's pages; a page
    /// shared by two segments once, with the later segment's rights (as on Linux, whose
    /// mapping of the later segment replaces the earlier one's there) and both segments'
    /// bytes.
    pub fn page_runs(&self) -> ([PageRun; MAX_SEGMENTS * 2], usize) {
        let mut runs = [PageRun::default(); MAX_SEGMENTS * 2];
        let mut n = 0;
        for s in self.segments() {
            let (mut start, end) = (s.first_page(), s.end_page());
            if n > 0 {
                let last = &mut runs[n - 1];
                let last_end = last.start + last.pages * PAGE;
                if last_end > start {
                    // The shared page: split it off the previous run.
                    last.pages -= 1;
                    let shared = PageRun {
                        start,
                        pages: 1,
                        rights: s.rights,
                    };
                    if last.pages == 0 {
                        n -= 1;
                    }
                    runs[n] = shared;
                    n += 1;
                    start += PAGE;
                }
            }
            if start < end {
                runs[n] = PageRun {
                    start,
                    pages: (end - start) / PAGE,
                    rights: s.rights,
                };
                n += 1;
            }
        }
        (runs, n)
    }

    /// Fills `chunk`, the memory at user address `address`, with what the executable puts
    /// there (file bytes of the segments, zero elsewhere).
    pub fn fill(&self, elf: &[u8], address: u64, chunk: &mut [u8]) {
        chunk.fill(0);
        let chunk_end = address + chunk.len() as u64;
        for s in self.segments() {
            let (lo, hi) = (s.vaddr.max(address), (s.vaddr + s.file_size).min(chunk_end));
            if lo < hi {
                let from = (s.file_offset + (lo - s.vaddr)) as usize;
                let to = from + (hi - lo) as usize;
                // Checked by `new`: the segment's file bytes lie inside the file.
                if let Some(bytes) = elf.get(from..to) {
                    chunk[(lo - address) as usize..(hi - address) as usize].copy_from_slice(bytes);
                }
            }
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    pub(crate) struct Seg {
        pub vaddr: u64,
        pub offset: u64,
        pub file: u64,
        pub mem: u64,
        pub flags: u32,
    }

    /// An ELF image with these program headers (kind, segment) at offset 64.
    pub(crate) fn elf(kind: u16, entry: u64, headers: &[(u32, Seg)], size: usize) -> Vec<u8> {
        let mut e = vec![0u8; size.max(64 + 56 * headers.len())];
        e[..4].copy_from_slice(b"\x7fELF");
        e[4] = 2;
        e[5] = 1;
        e[6] = 1;
        e[16..18].copy_from_slice(&kind.to_le_bytes());
        e[18..20].copy_from_slice(&EM_X86_64.to_le_bytes());
        e[24..32].copy_from_slice(&entry.to_le_bytes());
        e[32..40].copy_from_slice(&64u64.to_le_bytes());
        e[54..56].copy_from_slice(&56u16.to_le_bytes());
        e[56..58].copy_from_slice(&(headers.len() as u16).to_le_bytes());
        for (i, (t, s)) in headers.iter().enumerate() {
            let ph = &mut e[64 + 56 * i..64 + 56 * (i + 1)];
            ph[..4].copy_from_slice(&t.to_le_bytes());
            ph[4..8].copy_from_slice(&s.flags.to_le_bytes());
            ph[8..16].copy_from_slice(&s.offset.to_le_bytes());
            ph[16..24].copy_from_slice(&s.vaddr.to_le_bytes());
            ph[24..32].copy_from_slice(&s.vaddr.to_le_bytes());
            ph[32..40].copy_from_slice(&s.file.to_le_bytes());
            ph[40..48].copy_from_slice(&s.mem.to_le_bytes());
        }
        e
    }

    /// Like busybox: a read-only header segment, text, rodata, data+bss sharing no page.
    pub(crate) fn static_exe() -> Vec<u8> {
        let mut e = elf(
            ET_EXEC,
            0x40_1010,
            &[
                (
                    PT_LOAD,
                    Seg {
                        vaddr: 0x40_0000,
                        offset: 0,
                        file: 0x200,
                        mem: 0x200,
                        flags: 4,
                    },
                ),
                (
                    PT_LOAD,
                    Seg {
                        vaddr: 0x40_1000,
                        offset: 0x1000,
                        file: 0x30,
                        mem: 0x30,
                        flags: 5,
                    },
                ),
                (
                    PT_LOAD,
                    Seg {
                        vaddr: 0x40_2f00,
                        offset: 0x1f00,
                        file: 0x180,
                        mem: 0x2000,
                        flags: 6,
                    },
                ),
                (
                    7,
                    Seg {
                        vaddr: 0x40_2f00,
                        offset: 0x1f00,
                        file: 8,
                        mem: 16,
                        flags: 4,
                    },
                ),
            ],
            0x2100,
        );
        // Text: `mov eax, 60; xor edi, edi; syscall` (exit(0)).
        e[0x1010..0x101b].copy_from_slice(&[0xb8, 60, 0, 0, 0, 0x31, 0xff, 0x0f, 0x05, 0xeb, 0xfe]);
        e[0x1f00..0x1f08].copy_from_slice(b"DATADATA");
        e
    }

    #[test]
    fn plans_a_static_executable() {
        let e = static_exe();
        let p = LoadPlan::new(&e).unwrap();
        assert_eq!(p.entry, 0x40_1010);
        assert_eq!((p.phdr, p.phnum, p.phent), (0x40_0040, 4, 56));
        assert_eq!(p.segments().len(), 3);
        assert_eq!(p.segments()[1].rights, Rights::READ | Rights::EXECUTE);
        assert_eq!(p.segments()[2].rights, Rights::READ | Rights::WRITE);
        assert_eq!(p.brk_start, 0x40_5000);
        let (runs, n) = p.page_runs();
        assert_eq!(
            &runs[..n],
            [
                PageRun {
                    start: 0x40_0000,
                    pages: 1,
                    rights: Rights::READ
                },
                PageRun {
                    start: 0x40_1000,
                    pages: 1,
                    rights: Rights::READ | Rights::EXECUTE
                },
                PageRun {
                    start: 0x40_2000,
                    pages: 3,
                    rights: Rights::READ | Rights::WRITE
                },
            ]
        );
        // The data page: zero up to the segment, its file bytes, zero (bss) after them.
        let mut page = [0xaau8; 4096];
        p.fill(&e, 0x40_2000, &mut page);
        assert!(page[..0xf00].iter().all(|&b| b == 0));
        assert_eq!(&page[0xf00..0xf08], b"DATADATA");
        p.fill(&e, 0x40_3000, &mut page);
        assert!(page.iter().all(|&b| b == 0), "bss is zero");
    }

    #[test]
    fn a_page_shared_by_two_segments_gets_the_later_ones_rights() {
        let e = elf(
            ET_EXEC,
            0x40_0100,
            &[
                (
                    PT_LOAD,
                    Seg {
                        vaddr: 0x40_0000,
                        offset: 0,
                        file: 0x1800,
                        mem: 0x1800,
                        flags: 5,
                    },
                ),
                (
                    PT_LOAD,
                    Seg {
                        vaddr: 0x40_1800,
                        offset: 0x1800,
                        file: 0x100,
                        mem: 0x2000,
                        flags: 6,
                    },
                ),
            ],
            0x2000,
        );
        let mut e = e;
        e[0x1700] = 0xc3;
        e[0x1800..0x1808].copy_from_slice(b"DATADATA");
        let p = LoadPlan::new(&e).unwrap();
        let mut page = [0u8; 4096];
        p.fill(&e, 0x40_1000, &mut page);
        assert_eq!((page[0x700], &page[0x800..0x808]), (0xc3, &b"DATADATA"[..]));
        let (runs, n) = p.page_runs();
        assert_eq!(
            &runs[..n],
            [
                PageRun {
                    start: 0x40_0000,
                    pages: 1,
                    rights: Rights::READ | Rights::EXECUTE
                },
                PageRun {
                    start: 0x40_1000,
                    pages: 1,
                    rights: Rights::READ | Rights::WRITE
                },
                PageRun {
                    start: 0x40_2000,
                    pages: 2,
                    rights: Rights::READ | Rights::WRITE
                },
            ]
        );
    }

    #[test]
    fn a_static_pie_loads_at_the_pie_base() {
        let e = elf(
            ET_DYN,
            0x1000,
            &[(
                PT_LOAD,
                Seg {
                    vaddr: 0,
                    offset: 0,
                    file: 0x1100,
                    mem: 0x1100,
                    flags: 5,
                },
            )],
            0x1100,
        );
        let p = LoadPlan::new(&e).unwrap();
        assert_eq!((p.entry, p.phdr), (PIE_BASE + 0x1000, PIE_BASE + 64));
    }

    #[test]
    fn refuses_what_it_cannot_load() {
        let seg = |vaddr, file, mem, flags| Seg {
            vaddr,
            offset: 0,
            file,
            mem,
            flags,
        };
        let load = |kind, entry, h: &[(u32, Seg)]| LoadPlan::new(&elf(kind, entry, h, 0x1000));
        assert_eq!(LoadPlan::new(b"\x7fELF"), Err(ElfError::NotElf));
        assert_eq!(
            load(1, 0, &[(PT_LOAD, seg(0x40_0000, 8, 8, 5))]),
            Err(ElfError::NotExecutable)
        );
        assert_eq!(
            load(
                ET_DYN,
                0x1000,
                &[
                    (PT_INTERP, seg(0, 8, 8, 4)),
                    (PT_LOAD, seg(0, 8, 0x2000, 5))
                ]
            ),
            Err(ElfError::Dynamic)
        );
        assert_eq!(
            load(
                ET_EXEC,
                0x40_0000,
                &[(PT_LOAD, seg(0x40_0000, 0x2000, 0x2000, 5))]
            ),
            Err(ElfError::BadSegment(0x40_0000)),
            "file bytes beyond the file"
        );
        assert_eq!(
            load(ET_EXEC, 0x40_0000, &[(PT_LOAD, seg(0x40_0000, 16, 8, 5))]),
            Err(ElfError::BadSegment(0x40_0000)),
            "more file than memory bytes"
        );
        assert_eq!(
            load(ET_EXEC, 0, &[(PT_LOAD, seg(0, 8, 8, 5))]),
            Err(ElfError::BadSegment(0)),
            "the zero page"
        );
        assert_eq!(
            load(
                ET_EXEC,
                0x40_0000,
                &[(PT_LOAD, seg(USER_TOP - 0x1000, 8, 0x2000, 5))]
            ),
            Err(ElfError::BadSegment(USER_TOP - 0x1000))
        );
        assert_eq!(
            load(ET_EXEC, 0x40_0000, &[(PT_LOAD, seg(u64::MAX - 4, 0, 8, 5))]),
            Err(ElfError::BadSegment(u64::MAX - 4))
        );
        assert_eq!(
            load(
                ET_EXEC,
                0x50_0000,
                &[(PT_LOAD, seg(0x40_0000, 0x100, 0x100, 5))]
            ),
            Err(ElfError::BadEntry(0x50_0000))
        );
        assert_eq!(
            load(
                ET_EXEC,
                0x40_0000,
                &[(PT_LOAD, seg(0x40_0000, 0x100, 0x100, 6))]
            ),
            Err(ElfError::BadEntry(0x40_0000)),
            "entry in a non-executable segment"
        );
        assert_eq!(
            load(
                ET_EXEC,
                0x40_0000,
                &[
                    (PT_LOAD, seg(0x40_0000, 8, 0x2000, 5)),
                    (PT_LOAD, seg(0x40_1000, 8, 8, 6))
                ]
            ),
            Err(ElfError::BadSegment(0x40_1000)),
            "overlapping segments"
        );
        assert_eq!(
            load(ET_EXEC, 0x40_0000, &[(4, seg(0, 0, 0, 0))]),
            Err(ElfError::NoSegments)
        );
        let mut e = static_exe();
        e[56..58].copy_from_slice(&1000u16.to_le_bytes());
        assert_eq!(LoadPlan::new(&e), Err(ElfError::BadProgramHeaders));
    }

    #[test]
    fn truncations_and_bit_flips_never_panic() {
        let e = static_exe();
        for cut in 0..e.len().min(400) {
            let _ = LoadPlan::new(&e[..cut]);
        }
        for i in 0..400 {
            let mut bad = e.clone();
            bad[i] ^= 0xff;
            if let Ok(p) = LoadPlan::new(&bad) {
                let _ = p.page_runs();
                let mut chunk = [0u8; 4096];
                p.fill(&bad, p.segments()[0].vaddr & !0xfff, &mut chunk);
            }
        }
    }
}
