//! The loadable segments of an ELF64 executable, checked once for every loader (the UEFI
//! loader for the kernel, the kernel for the root task, syssw for partitions): each
//! `PT_LOAD` segment must be W^X, lie inside `range`, and have its file bytes inside the
//! file. Loaders only copy and map.

use crate::syscall::PageRights;
use xmas_elf::ElfFile;
use xmas_elf::program::Type;

/// One checked `PT_LOAD` segment.
#[derive(Clone, Copy, Debug)]
pub struct LoadSegment<'a> {
    pub vaddr: u64,
    /// Bytes in memory (>= `file.len()`; the rest is zero).
    pub mem_size: u64,
    /// The bytes the file provides, copied to `vaddr`.
    pub file: &'a [u8],
    pub rights: PageRights,
}

/// Why an image cannot be loaded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ElfError {
    /// Not a parsable ELF file (xmas-elf's reason).
    Malformed(&'static str),
    /// A segment at this address breaks a rule.
    Segment(u64, &'static str),
    /// More `PT_LOAD` segments than the caller can take.
    TooManySegments,
}

impl core::fmt::Display for ElfError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Malformed(why) => write!(f, "not a valid ELF file: {why}"),
            Self::Segment(at, why) => write!(f, "segment at {at:#x}: {why}"),
            Self::TooManySegments => write!(f, "too many PT_LOAD segments"),
        }
    }
}

/// Entry point and the non-empty `PT_LOAD` segments (at most `N`) of `elf`, each checked
/// against `range` (virtual addresses the image may occupy).
pub fn load_segments<const N: usize>(
    elf: &[u8],
    range: core::ops::Range<u64>,
) -> Result<(u64, [Option<LoadSegment<'_>>; N]), ElfError> {
    let file = ElfFile::new(elf).map_err(ElfError::Malformed)?;
    let mut out = [None; N];
    let mut n = 0;
    for segment in file.program_iter() {
        if segment.get_type() != Ok(Type::Load) || segment.mem_size() == 0 {
            continue;
        }
        let (vaddr, mem_size, file_size, offset) = (
            segment.virtual_addr(),
            segment.mem_size(),
            segment.file_size(),
            segment.offset(),
        );
        let flags = segment.flags();
        if flags.is_write() && flags.is_execute() {
            return Err(ElfError::Segment(vaddr, "writable and executable (W^X)"));
        }
        let end = vaddr
            .checked_add(mem_size)
            .ok_or(ElfError::Segment(vaddr, "size overflows"))?;
        if vaddr < range.start || end > range.end {
            return Err(ElfError::Segment(
                vaddr,
                "outside the allowed address range",
            ));
        }
        let file_end = offset.checked_add(file_size);
        if file_size > mem_size || file_end.is_none_or(|e| e > elf.len() as u64) {
            return Err(ElfError::Segment(vaddr, "file range outside the ELF"));
        }
        let mut rights = PageRights::empty();
        rights.set(PageRights::WRITE, flags.is_write());
        rights.set(PageRights::EXECUTE, flags.is_execute());
        *out.get_mut(n).ok_or(ElfError::TooManySegments)? = Some(LoadSegment {
            vaddr,
            mem_size,
            file: &elf[offset as usize..(offset + file_size) as usize],
            rights,
        });
        n += 1;
    }
    Ok((file.header.pt2.entry_point(), out))
}
