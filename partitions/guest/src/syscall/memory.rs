//! The memory calls of a process: `brk`, `mmap`, `munmap`, `mremap`, `mprotect`,
//! `madvise`, and the locks (`mlock`, `mlock2`, `munlock`, `mlockall`, `munlockall`). The calls change the process's areas ([`crate::memory::Areas`]); an
//! anonymous page is backed when first touched ([`Host::fault_in`]); a file mapping's
//! pages are filled from the file when it is mapped ([`Host::fill_in`]: POSIX leaves it open
//! whether a private mapping sees later writes to the file; this one does not). They never
//! map a page writable and executable (W^X).

use super::table::Ctx;
use super::{Host, MAX_HEAP, MMAP_BOTTOM, SysResult};
use crate::linux::{self, Errno};
use crate::memory::{Area, AreaError, Kind, MMAP_TOP, PAGE, Rights, USER_TOP, page_up};
use crate::process::{File, Process};
use crate::vfs::dev::Device;

/// Linux's `brk`: returns the new break, or the old one if it cannot move there. The heap's
/// pages are backed when first touched.
pub(super) fn brk(c: &mut Ctx<'_, '_, impl Host>, requested: u64) -> u64 {
    let (p, _, host) = c.parts();
    if requested < p.brk_start || requested - p.brk_start > MAX_HEAP {
        return p.brk;
    }
    let (old_end, new_end) = (page_up(p.brk), page_up(requested));
    if new_end > old_end {
        let grown = if old_end == p.brk_start {
            p.areas.insert(Area {
                start: p.brk_start,
                end: new_end,
                rights: Rights::READ | Rights::WRITE,
                kind: Kind::Heap,
            })
        } else {
            p.areas.resize(old_end, new_end)
        };
        if grown.is_err() {
            return p.brk;
        }
    } else if new_end < old_end {
        host.unmap(new_end, (old_end - new_end) / PAGE);
        let _ = if new_end == p.brk_start {
            p.areas.remove(p.brk_start, old_end, |_| ())
        } else {
            p.areas.resize(old_end, new_end)
        };
    }
    p.brk = requested;
    requested
}

pub(super) fn area_error(e: AreaError) -> Errno {
    match e {
        AreaError::Invalid => Errno::EINVAL,
        AreaError::Overlaps => Errno::EEXIST,
        AreaError::TooMany => Errno::ENOMEM,
    }
}

/// The lowest address a hint may name (Linux's default `vm.mmap_min_addr`).
const MMAP_MIN_ADDR: u64 = 0x1_0000;

/// Linux's `mmap`: anonymous or file-backed (private; shared read-only, as nothing can
/// write the files) mappings at a free place (below [`MMAP_TOP`], the hint if it is free),
/// or at a fixed address (`MAP_FIXED` replaces what was there, `MAP_FIXED_NOREPLACE`
/// fails with `EEXIST`).
pub(super) fn mmap(c: &mut Ctx<'_, '_, impl Host>, a: [u64; 6]) -> SysResult<u64> {
    let (p, f, host) = c.parts();
    let fs = &*f.fs;
    let [hint, len, prot, flags, fd, offset] = a;
    let rights = Rights::from_prot(prot).ok_or(Errno::EINVAL)?;
    if rights.writable_and_executable() {
        return Err(Errno::EACCES);
    }
    if len == 0 || flags & (linux::MAP_SHARED | linux::MAP_PRIVATE) == 0 {
        return Err(Errno::EINVAL);
    }
    // The bytes a file mapping starts with (`None`: zeros, also for `/dev/zero`).
    let contents: Option<&[u8]> = if flags & linux::MAP_ANONYMOUS == 0 {
        let Some(File::Open(id)) = p.file(fd) else {
            return Err(if p.file(fd).is_none() {
                Errno::EBADF
            } else {
                Errno::ENODEV
            });
        };
        let open = fs.description(id).ok_or(Errno::EBADF)?;
        if !offset.is_multiple_of(PAGE) {
            return Err(Errno::EINVAL);
        }
        if open.flags & linux::O_ACCMODE == linux::O_WRONLY {
            return Err(Errno::EACCES);
        }
        if flags & linux::MAP_SHARED != 0
            && rights.contains(Rights::WRITE)
            && open.flags & linux::O_ACCMODE != linux::O_RDWR
        {
            return Err(Errno::EACCES);
        }
        match fs.device(open.node) {
            Some(Device::Zero) => None,
            Some(_) => return Err(Errno::ENODEV),
            None => Some(fs.file_bytes(open.node).ok_or(Errno::ENODEV)?),
        }
    } else {
        None
    };
    if contents.is_some() && flags & linux::MAP_SHARED != 0 && rights.contains(Rights::WRITE) {
        // Writes through a shared mapping would have to reach the file.
        return Err(Errno::EACCES);
    }
    let len = len.checked_add(PAGE - 1).ok_or(Errno::ENOMEM)? & !(PAGE - 1);
    let fixed = flags & (linux::MAP_FIXED | linux::MAP_FIXED_NOREPLACE) != 0;
    let start = if fixed {
        let end = hint.checked_add(len).ok_or(Errno::ENOMEM)?;
        if !hint.is_multiple_of(PAGE) || hint == 0 || end > USER_TOP {
            return Err(Errno::EINVAL);
        }
        if p.areas.overlaps(hint, end) {
            if flags & linux::MAP_FIXED_NOREPLACE != 0 {
                return Err(Errno::EEXIST);
            }
            unmap(p, host, hint, len)?;
        }
        hint
    } else {
        let hinted = hint.is_multiple_of(PAGE)
            && hint >= MMAP_MIN_ADDR
            && hint
                .checked_add(len)
                .is_some_and(|end| end <= USER_TOP && !p.areas.overlaps(hint, end));
        if hinted {
            hint
        } else {
            p.areas
                .free_below(MMAP_TOP, MMAP_BOTTOM, len)
                .ok_or(Errno::ENOMEM)?
        }
    };
    let kind = if contents.is_some() {
        Kind::File
    } else {
        Kind::Anonymous
    };
    p.areas
        .insert(Area {
            start,
            end: start + len,
            rights,
            kind,
        })
        .map_err(area_error)?;
    if let Some(bytes) = contents {
        // The file's bytes from `offset` on, zeros after its end.
        let from = usize::try_from(offset)
            .unwrap_or(usize::MAX)
            .min(bytes.len());
        let bytes = &bytes[from..];
        let mut page = start;
        while page < start + len && ((page - start) as usize) < bytes.len() {
            let at = (page - start) as usize;
            let piece = &bytes[at..bytes.len().min(at + PAGE as usize)];
            let filled = host.fill_in(page, &mut |frame| {
                frame[..piece.len()].copy_from_slice(piece)
            });
            if let Err(e) = filled {
                let _ = unmap(p, host, start, len);
                return Err(e);
            }
            page += PAGE;
        }
    }
    Ok(start)
}

/// Linux's `munmap` (parts of areas too; pages not mapped are fine).
fn unmap(p: &mut Process, host: &mut impl Host, start: u64, len: u64) -> SysResult<u64> {
    if !start.is_multiple_of(PAGE) || len == 0 {
        return Err(Errno::EINVAL);
    }
    let end = start
        .checked_add(page_up(len))
        .filter(|&e| e <= USER_TOP)
        .ok_or(Errno::EINVAL)?;
    // Locks go with the pages (checked first: cutting a locked range may not fit).
    let mut locks = p.locks;
    locks.unlock(start, end).map_err(|_| Errno::ENOMEM)?;
    let mut parts = [(0u64, 0u64); crate::memory::MAX_AREAS + 2];
    let mut n = 0;
    p.areas
        .remove(start, end, |a| {
            if n < parts.len() {
                parts[n] = (a.start, a.end);
                n += 1;
            }
        })
        .map_err(area_error)?;
    p.locks = locks;
    for &(s, e) in &parts[..n] {
        host.unmap(s, (e - s) / PAGE);
    }
    Ok(0)
}

/// Linux's `munmap`.
pub(super) fn munmap(c: &mut Ctx<'_, '_, impl Host>, start: u64, len: u64) -> SysResult<u64> {
    let (p, _, host) = c.parts();
    unmap(p, host, start, len)
}

/// Linux's `mprotect` (every page of the range must be in some area: else `ENOMEM`).
pub(super) fn mprotect(
    c: &mut Ctx<'_, '_, impl Host>,
    start: u64,
    len: u64,
    prot: u64,
) -> SysResult<u64> {
    let (p, _, host) = c.parts();
    let rights = Rights::from_prot(prot).ok_or(Errno::EINVAL)?;
    if rights.writable_and_executable() {
        return Err(Errno::EACCES);
    }
    if !start.is_multiple_of(PAGE) {
        return Err(Errno::EINVAL);
    }
    if len == 0 {
        return Ok(0);
    }
    let end = start
        .checked_add(page_up(len))
        .filter(|&e| e <= USER_TOP)
        .ok_or(Errno::ENOMEM)?;
    if !p.areas.covers(start, end) {
        return Err(Errno::ENOMEM);
    }
    p.areas
        .protect(start, end, rights, |_| ())
        .map_err(area_error)?;
    host.protect(start, (end - start) / PAGE, rights)?;
    Ok(0)
}

/// Linux's `madvise`: `MADV_DONTNEED` drops the pages of the range (the next touch gives
/// zeros, or a file mapping's bytes again); other advice changes nothing. `ENOMEM` when a
/// page of the range is in no area.
pub(super) fn madvise(
    c: &mut Ctx<'_, '_, impl Host>,
    start: u64,
    len: u64,
    advice: u64,
) -> SysResult<u64> {
    let (p, _, host) = c.parts();
    const MADV_DONTNEED: u64 = 4;
    if !start.is_multiple_of(PAGE) {
        return Err(Errno::EINVAL);
    }
    let end = start
        .checked_add(page_up(len))
        .filter(|&e| e <= USER_TOP)
        .ok_or(Errno::EINVAL)?;
    if len == 0 {
        return Ok(0);
    }
    if !p.areas.covers(start, end) {
        return Err(Errno::ENOMEM);
    }
    if advice == MADV_DONTNEED {
        // Anonymous pages come back zeroed; a file mapping's pages keep their bytes (they
        // were filled when it was mapped, and a private mapping's own changes stay).
        let mut at = start;
        while at < end {
            let Some(area) = p.areas.find(at) else {
                break;
            };
            let until = area.end.min(end);
            if area.kind != Kind::File {
                host.unmap(at, (until - at) / PAGE);
            }
            at = until;
        }
    }
    Ok(0)
}

/// Linux's `mremap` of `old_len` bytes at `old` (within one area) to `new_len`: shrinks in
/// place, grows in place when the pages after the area are free, else moves the pages to a
/// free place with `MREMAP_MAYMOVE` (`ENOMEM` without). `MREMAP_FIXED` and
/// `MREMAP_DONTUNMAP` are not served (`EINVAL`).
pub(super) fn mremap(
    c: &mut Ctx<'_, '_, impl Host>,
    old: u64,
    old_len: u64,
    new_len: u64,
    flags: u64,
) -> SysResult<u64> {
    let (p, _, host) = c.parts();
    const MREMAP_MAYMOVE: u64 = 1;
    if !old.is_multiple_of(PAGE) || new_len == 0 || flags & !MREMAP_MAYMOVE != 0 {
        return Err(Errno::EINVAL);
    }
    let (old_len, new_len) = (page_up(old_len), page_up(new_len));
    let old_end = old.checked_add(old_len).ok_or(Errno::EFAULT)?;
    let area = *p
        .areas
        .find(old)
        .filter(|a| old_end <= a.end && old_len > 0)
        .ok_or(Errno::EFAULT)?;
    let new_end = old.checked_add(new_len).ok_or(Errno::ENOMEM)?;
    if new_len <= old_len {
        if new_len < old_len {
            unmap(p, host, new_end, old_len - new_len)?;
        }
        return Ok(old);
    }
    if old_end == area.end
        && area.kind != Kind::Heap
        && new_end <= USER_TOP
        && !p.areas.overlaps(old_end, new_end)
        && p.areas.resize(old_end, new_end).is_ok()
    {
        return Ok(old);
    }
    if flags & MREMAP_MAYMOVE == 0 {
        return Err(Errno::ENOMEM);
    }
    let to = p
        .areas
        .free_below(MMAP_TOP, MMAP_BOTTOM, new_len)
        .ok_or(Errno::ENOMEM)?;
    p.areas
        .insert(Area {
            start: to,
            end: to + new_len,
            kind: Kind::Anonymous,
            ..area
        })
        .map_err(area_error)?;
    if let Err(e) = p.areas.remove(old, old_end, |_| ()) {
        let _ = p.areas.remove(to, to + new_len, |_| ());
        return Err(area_error(e));
    }
    host.move_pages(old, to, old_len / PAGE);
    Ok(to)
}

/// The bytes `RLIMIT_MEMLOCK` lets `p` lock (whole pages), or `EPERM` when it may lock
/// none: the guest gives no process `CAP_IPC_LOCK`, so its locks are bounded as those of
/// an unprivileged Linux process.
fn lock_limit(p: &Process) -> SysResult<u64> {
    match p.limits[linux::RLIMIT_MEMLOCK as usize].soft {
        0 => Err(Errno::EPERM),
        limit => Ok(limit & !(PAGE - 1)),
    }
}

/// The pages `start..start + len` touches, as `mlock` and `munlock` round them (`EINVAL`
/// when the range wraps, `ENOMEM` beyond user space).
fn lock_range(start: u64, len: u64) -> SysResult<(u64, u64)> {
    let end = start.checked_add(len).ok_or(Errno::EINVAL)?;
    let end = end.checked_next_multiple_of(PAGE).ok_or(Errno::EINVAL)?;
    if end > USER_TOP {
        return Err(Errno::ENOMEM);
    }
    Ok((start & !(PAGE - 1), end))
}

/// Linux's `mlock` and `mlock2` (`MLOCK_ONFAULT`): the range must be mapped (`ENOMEM`),
/// and the process's locked bytes stay within `RLIMIT_MEMLOCK` (`ENOMEM`; `EPERM` when it
/// is 0). The pages are backed when touched, as always: the guest never pages out.
pub(super) fn mlock(
    c: &mut Ctx<'_, '_, impl Host>,
    start: u64,
    len: u64,
    flags: u64,
) -> SysResult<u64> {
    const MLOCK_ONFAULT: u64 = 1;
    if flags & !MLOCK_ONFAULT != 0 {
        return Err(Errno::EINVAL);
    }
    let p = &mut *c.p;
    let limit = lock_limit(p)?;
    let (start, end) = lock_range(start, len)?;
    if start == end {
        return Ok(0);
    }
    if p.locks.bytes() + p.locks.unlocked_in(start, end) > limit || !p.areas.covers(start, end) {
        return Err(Errno::ENOMEM);
    }
    p.locks.lock(start, end).map_err(|_| Errno::EAGAIN)?;
    Ok(0)
}

/// Linux's `munlock`: the range must be mapped (`ENOMEM`).
pub(super) fn munlock(c: &mut Ctx<'_, '_, impl Host>, start: u64, len: u64) -> SysResult<u64> {
    let p = &mut *c.p;
    let (start, end) = lock_range(start, len)?;
    if start == end {
        return Ok(0);
    }
    if !p.areas.covers(start, end) {
        return Err(Errno::ENOMEM);
    }
    p.locks.unlock(start, end).map_err(|_| Errno::EAGAIN)?;
    Ok(0)
}

/// Linux's `mlockall`: `MCL_CURRENT` locks every area (`ENOMEM` when they are more than
/// `RLIMIT_MEMLOCK`), `MCL_FUTURE` is recorded (new mappings are not counted against the
/// limit), `MCL_ONFAULT` goes with one of them.
pub(super) fn mlockall(c: &mut Ctx<'_, '_, impl Host>, flags: u64) -> SysResult<u64> {
    const MCL_CURRENT: u64 = 1;
    const MCL_FUTURE: u64 = 2;
    const MCL_ONFAULT: u64 = 4;
    if flags & !(MCL_CURRENT | MCL_FUTURE | MCL_ONFAULT) != 0
        || flags & (MCL_CURRENT | MCL_FUTURE) == 0
    {
        return Err(Errno::EINVAL);
    }
    let p = &mut *c.p;
    let limit = lock_limit(p)?;
    if flags & MCL_CURRENT != 0 {
        let total: u64 = p.areas.iter().map(|a| a.end - a.start).sum();
        if total > limit {
            return Err(Errno::ENOMEM);
        }
        let mut locks = crate::memory::Locks::default();
        for a in p.areas.iter() {
            // As many ranges as areas at most: always fits.
            locks.lock(a.start, a.end).map_err(|_| Errno::EAGAIN)?;
        }
        p.locks = locks;
    }
    p.lock_future = flags & MCL_FUTURE != 0;
    Ok(0)
}

/// Linux's `munlockall`.
pub(super) fn munlockall(c: &mut Ctx<'_, '_, impl Host>) -> SysResult<u64> {
    c.p.locks = Default::default();
    c.p.lock_future = false;
    Ok(0)
}
