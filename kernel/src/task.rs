//! Tasks. At this stage: the root task, created from syssw's ELF in the system image with
//! every ability, the system image mapped read-only and a stack.

use crate::mem::paging::{AddressSpace, MapError, Rights};
use crate::mem::{PAGE_SIZE, alloc_zeroed_frame, phys_to_virt};
use abi::syscall::{
    Abilities, ROOT_STACK_SIZE, ROOT_STACK_TOP, ROOT_SYSTEM_IMAGE_BASE, USER_END, USER_MIN,
};
use spin::Mutex;
use xmas_elf::ElfFile;
use xmas_elf::program::Type as SegmentType;

pub struct Task {
    pub name: &'static str,
    pub space: AddressSpace,
    pub abilities: Abilities,
}

/// The task whose thread runs now (single CPU, one thread so far).
pub static CURRENT: Mutex<Option<Task>> = Mutex::new(None);

/// Why the root task could not be created.
#[derive(Debug)]
pub enum LoadError {
    Elf(&'static str),
    Segment(u64, &'static str),
    Map(MapError),
}

impl From<MapError> for LoadError {
    fn from(e: MapError) -> Self {
        Self::Map(e)
    }
}

/// Loads `elf` into a fresh address space: each `PT_LOAD` segment into new frames with its
/// rights (W^X enforced). Returns the space and the entry point.
pub fn load_elf(elf: &[u8]) -> Result<(AddressSpace, u64), LoadError> {
    let file = ElfFile::new(elf).map_err(LoadError::Elf)?;
    let mut space = AddressSpace::new()?;
    for segment in file.program_iter() {
        if segment.get_type() != Ok(SegmentType::Load) || segment.mem_size() == 0 {
            continue;
        }
        let (vaddr, memsz, filesz, offset) = (
            segment.virtual_addr(),
            segment.mem_size(),
            segment.file_size(),
            segment.offset(),
        );
        let flags = segment.flags();
        if flags.is_write() && flags.is_execute() {
            return Err(LoadError::Segment(vaddr, "writable and executable (W^X)"));
        }
        let end = vaddr
            .checked_add(memsz)
            .ok_or(LoadError::Segment(vaddr, "size overflows"))?;
        if vaddr < USER_MIN || end > USER_END {
            return Err(LoadError::Segment(vaddr, "outside the user half"));
        }
        if filesz > memsz
            || offset
                .checked_add(filesz)
                .is_none_or(|e| e > elf.len() as u64)
        {
            return Err(LoadError::Segment(vaddr, "file range outside the ELF"));
        }
        let rights = Rights {
            write: flags.is_write(),
            execute: flags.is_execute(),
        };
        let mut page = vaddr & !(PAGE_SIZE - 1);
        while page < end {
            let frame = alloc_zeroed_frame().ok_or(MapError::OutOfMemory)?;
            // Copy the part of the file image that falls into this page.
            let (lo, hi) = (page.max(vaddr), (page + PAGE_SIZE).min(vaddr + filesz));
            if lo < hi {
                let src = &elf[(offset + lo - vaddr) as usize..(offset + hi - vaddr) as usize];
                // SAFETY: fresh frame, direct-mapped; lo - page + len <= PAGE_SIZE.
                unsafe {
                    core::ptr::copy_nonoverlapping(
                        src.as_ptr(),
                        (phys_to_virt(frame) + (lo - page)) as *mut u8,
                        src.len(),
                    )
                };
            }
            space.map(page, frame, rights).map_err(|e| match e {
                MapError::AlreadyMapped => {
                    LoadError::Segment(vaddr, "shares a page with another segment")
                }
                other => LoadError::Map(other),
            })?;
            page += PAGE_SIZE;
        }
    }
    Ok((space, file.header.pt2.entry_point()))
}

/// Creates the root task from `syssw` and maps the system image (physical `image_phys`,
/// `image_len` bytes) read-only plus a zeroed stack. Returns the entry point.
pub fn create_root(syssw: &[u8], image_phys: u64, image_len: u64) -> Result<u64, LoadError> {
    let (mut space, entry) = load_elf(syssw)?;
    let read_only = Rights {
        write: false,
        execute: false,
    };
    for offset in (0..image_len.max(1)).step_by(PAGE_SIZE as usize) {
        space.map(
            ROOT_SYSTEM_IMAGE_BASE + offset,
            image_phys + offset,
            read_only,
        )?;
    }
    let read_write = Rights {
        write: true,
        execute: false,
    };
    for page in (ROOT_STACK_TOP - ROOT_STACK_SIZE..ROOT_STACK_TOP).step_by(PAGE_SIZE as usize) {
        space.map(
            page,
            alloc_zeroed_frame().ok_or(MapError::OutOfMemory)?,
            read_write,
        )?;
    }
    space.activate();
    *CURRENT.lock() = Some(Task {
        name: "syssw",
        space,
        abilities: Abilities::all(),
    });
    Ok(entry)
}
