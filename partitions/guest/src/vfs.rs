//! Path lookup in the initramfs (read-only): absolute and relative paths (relative to `/`,
//! the only working directory so far), `.` and `..`, and symbolic links (at most
//! [`MAX_LINKS`] in one lookup, as Linux's `ELOOP` limit for nested links).

use crate::cpio::{Archive, Entry};
use crate::linux::Errno;

/// Longest path (Linux's `PATH_MAX`).
pub const PATH_MAX: usize = 4096;
/// Most symbolic links followed in one lookup.
pub const MAX_LINKS: usize = 8;
/// Longest normalised path the guest handles.
const MAX_PATH: usize = 256;

/// A normalised absolute path without the leading `/` (`"bin/sh"`; `""` is the root).
#[derive(Clone, Copy)]
pub struct PathBuf {
    bytes: [u8; MAX_PATH],
    len: usize,
}

impl core::fmt::Debug for PathBuf {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "/{}", self.as_str())
    }
}

impl PathBuf {
    const fn root() -> Self {
        Self {
            bytes: [0; MAX_PATH],
            len: 0,
        }
    }
    pub fn as_str(&self) -> &str {
        core::str::from_utf8(&self.bytes[..self.len]).unwrap_or("")
    }
    fn pop(&mut self) {
        let cut = self.bytes[..self.len]
            .iter()
            .rposition(|&b| b == b'/')
            .unwrap_or(0);
        self.len = cut;
    }
    fn push(&mut self, part: &[u8]) -> Result<(), Errno> {
        let extra = part.len() + usize::from(self.len > 0);
        if self.len + extra > MAX_PATH {
            return Err(Errno::ENAMETOOLONG);
        }
        if self.len > 0 {
            self.bytes[self.len] = b'/';
            self.len += 1;
        }
        self.bytes[self.len..self.len + part.len()].copy_from_slice(part);
        self.len += part.len();
        Ok(())
    }
}

/// Looks `path` up; `follow_last` follows a symbolic link in the last component (`stat`
/// does, `lstat` and `readlink` do not). Returns the entry and its normalised path.
pub fn lookup<'a>(
    fs: &Archive<'a>,
    path: &[u8],
    follow_last: bool,
) -> Result<(Entry<'a>, PathBuf), Errno> {
    if path.is_empty() {
        return Err(Errno::ENOENT);
    }
    if path.len() >= PATH_MAX {
        return Err(Errno::ENAMETOOLONG);
    }
    let mut links = 0;
    resolve(fs, &PathBuf::root(), path, follow_last, &mut links)
}

fn resolve<'a>(
    fs: &Archive<'a>,
    base: &PathBuf,
    path: &[u8],
    follow_last: bool,
    links: &mut usize,
) -> Result<(Entry<'a>, PathBuf), Errno> {
    let mut at = if path.first() == Some(&b'/') {
        PathBuf::root()
    } else {
        *base
    };
    let mut parts = path
        .split(|&b| b == b'/')
        .filter(|p| !p.is_empty())
        .peekable();
    let mut entry = fs.get("/").ok_or(Errno::ENOENT)?;
    let trailing_slash = path.last() == Some(&b'/');
    while let Some(part) = parts.next() {
        if !entry.is_dir() {
            return Err(Errno::ENOTDIR);
        }
        match part {
            b"." => continue,
            b".." => {
                at.pop();
                entry = fs.get(at.as_str()).ok_or(Errno::ENOENT)?;
                continue;
            }
            _ => {}
        }
        let parent = at;
        at.push(part)?;
        entry = fs.get(at.as_str()).ok_or(Errno::ENOENT)?;
        let last = parts.peek().is_none();
        if entry.is_symlink() && (!last || follow_last || trailing_slash) {
            *links += 1;
            if *links > MAX_LINKS {
                return Err(Errno::ELOOP);
            }
            let (target, target_path) = resolve(fs, &parent, entry.data, true, links)?;
            entry = target;
            at = target_path;
        }
    }
    if trailing_slash && !entry.is_dir() {
        return Err(Errno::ENOTDIR);
    }
    Ok((entry, at))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cpio::{S_IFDIR, S_IFLNK, S_IFREG};

    fn fs_bytes() -> Vec<u8> {
        crate::cpio::tests::archive(&[
            (".", S_IFDIR | 0o755, b""),
            ("bin", S_IFDIR | 0o755, b""),
            ("bin/busybox", S_IFREG | 0o755, b"ELF"),
            ("bin/sh", S_IFLNK | 0o777, b"busybox"),
            ("bin/abs", S_IFLNK | 0o777, b"/bin/sh"),
            ("bin/loop", S_IFLNK | 0o777, b"loop"),
            ("sbin", S_IFLNK | 0o777, b"bin"),
            ("etc", S_IFDIR | 0o755, b""),
            ("etc/passwd", S_IFREG | 0o644, b"root"),
        ])
    }

    #[test]
    fn resolves_paths_and_links() {
        let bytes = fs_bytes();
        let fs = Archive::new(&bytes).unwrap();
        let name = |p: &[u8], follow| {
            lookup(&fs, p, follow).map(|(e, at)| (e.name, at.as_str().to_string()))
        };
        assert_eq!(
            name(b"/bin/sh", true),
            Ok(("bin/busybox", "bin/busybox".into()))
        );
        assert_eq!(name(b"/bin/sh", false), Ok(("bin/sh", "bin/sh".into())));
        assert_eq!(name(b"/bin/abs", true).unwrap().0, "bin/busybox");
        assert_eq!(name(b"/sbin/sh", true).unwrap().0, "bin/busybox");
        assert_eq!(name(b"bin/../etc/./passwd", true).unwrap().0, "etc/passwd");
        assert_eq!(name(b"/../../etc/passwd", true).unwrap().0, "etc/passwd");
        assert_eq!(name(b"/", true).unwrap().1, "");
        assert_eq!(name(b"/bin/", true).unwrap().0, "bin");
        assert_eq!(name(b"/etc/passwd/", true), Err(Errno::ENOTDIR));
        assert_eq!(name(b"/etc/passwd/x", true), Err(Errno::ENOTDIR));
        assert_eq!(name(b"/nope", true), Err(Errno::ENOENT));
        assert_eq!(name(b"", true), Err(Errno::ENOENT));
        assert_eq!(name(b"/bin/loop", true), Err(Errno::ELOOP));
        assert_eq!(name(&[b'a'; 5000], true), Err(Errno::ENAMETOOLONG));
    }
}
