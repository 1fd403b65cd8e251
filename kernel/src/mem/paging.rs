//! User address spaces: a PML4 per task whose kernel half (slots 256..511) is shared with
//! the kernel's and supervisor-only; user mappings get the U bit and their own rights.

use super::{PAGE_SIZE, alloc_zeroed_frame, phys_to_virt};
use abi::syscall::{USER_END, USER_MIN};

const PRESENT: u64 = 1;
const WRITABLE: u64 = 1 << 1;
const USER: u64 = 1 << 2;
const HUGE: u64 = 1 << 7;
const NO_EXECUTE: u64 = 1 << 63;
const ADDRESS: u64 = 0x000f_ffff_ffff_f000;

/// Rights of a user page.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Rights {
    pub write: bool,
    pub execute: bool,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MapError {
    OutOfMemory,
    NotUserAddress,
    AlreadyMapped,
}

pub struct AddressSpace {
    root: u64,
}

fn table(phys: u64) -> &'static mut [u64; 512] {
    // SAFETY: `phys` is a page-table frame owned by an address space; the direct map covers
    // it and the non-preemptible kernel never holds two references to one table at once.
    unsafe { &mut *(phys_to_virt(phys) as *mut [u64; 512]) }
}

fn index(virt: u64, level: u32) -> usize {
    ((virt >> (12 + 9 * level)) & 511) as usize
}

impl AddressSpace {
    /// A new, empty user half sharing the current kernel half.
    pub fn new() -> Result<Self, MapError> {
        let root = alloc_zeroed_frame().ok_or(MapError::OutOfMemory)?;
        let (current, _) = x86_64::registers::control::Cr3::read();
        let kernel = table(current.start_address().as_u64());
        table(root)[256..].copy_from_slice(&kernel[256..]);
        Ok(Self { root })
    }

    pub fn root(&self) -> u64 {
        self.root
    }

    /// Maps the user page `virt` to frame `phys`.
    pub fn map(&mut self, virt: u64, phys: u64, rights: Rights) -> Result<(), MapError> {
        if !(USER_MIN..USER_END).contains(&virt) || virt % PAGE_SIZE != 0 {
            return Err(MapError::NotUserAddress);
        }
        let mut t = self.root;
        for level in (1..4).rev() {
            let entry = &mut table(t)[index(virt, level)];
            if *entry & PRESENT == 0 {
                *entry =
                    alloc_zeroed_frame().ok_or(MapError::OutOfMemory)? | PRESENT | WRITABLE | USER;
            }
            t = *entry & ADDRESS;
        }
        let leaf = &mut table(t)[index(virt, 0)];
        if *leaf & PRESENT != 0 {
            return Err(MapError::AlreadyMapped);
        }
        *leaf = phys
            | PRESENT
            | USER
            | if rights.write { WRITABLE } else { 0 }
            | if rights.execute { 0 } else { NO_EXECUTE };
        Ok(())
    }

    /// The frame and rights behind user address `virt`, if it is a present user page.
    pub fn translate(&self, virt: u64) -> Option<(u64, Rights)> {
        if !(USER_MIN..USER_END).contains(&virt) {
            return None;
        }
        let mut t = self.root;
        for level in (0..4).rev() {
            let entry = table(t)[index(virt, level)];
            if entry & (PRESENT | USER) != PRESENT | USER || entry & HUGE != 0 {
                return None;
            }
            if level == 0 {
                let rights = Rights {
                    write: entry & WRITABLE != 0,
                    execute: entry & NO_EXECUTE == 0,
                };
                return Some((entry & ADDRESS, rights));
            }
            t = entry & ADDRESS;
        }
        None
    }

    /// Copies user memory at `ptr` into `out`; `false` if any byte is not a present user page.
    pub fn copy_from_user(&self, ptr: u64, out: &mut [u8]) -> bool {
        let mut done = 0;
        while done < out.len() {
            let at = ptr.wrapping_add(done as u64);
            let Some((frame, _)) = self.translate(at & !(PAGE_SIZE - 1)) else {
                return false;
            };
            let offset = (at % PAGE_SIZE) as usize;
            let n = (PAGE_SIZE as usize - offset).min(out.len() - done);
            // SAFETY: `frame` is a present user frame, mapped by the direct map; the copy stays
            // inside it (offset + n <= PAGE_SIZE).
            let src = unsafe {
                core::slice::from_raw_parts((phys_to_virt(frame) as *const u8).add(offset), n)
            };
            out[done..done + n].copy_from_slice(src);
            done += n;
        }
        true
    }

    pub fn activate(&self) {
        // SAFETY: the root maps the kernel half identically to the current tables.
        unsafe {
            x86_64::registers::control::Cr3::write(
                x86_64::structures::paging::PhysFrame::containing_address(x86_64::PhysAddr::new(
                    self.root,
                )),
                x86_64::registers::control::Cr3Flags::empty(),
            )
        };
    }
}
