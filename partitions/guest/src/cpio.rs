//! Reader of the initramfs: a cpio archive in the "newc" format (`070701`), as Linux's
//! `gen_init_cpio` and `cpio -H newc` write it and `cargo xtask` builds it.
//!
//! Each entry is a 110-byte ASCII header (magic and thirteen 8-digit hex fields), the name
//! (with its NUL, counted in `namesize`) padded to a multiple of 4 from the start of the
//! header, then `filesize` bytes of data padded to 4. The entry named `TRAILER!!!` ends the
//! archive. A symbolic link's data is its target.
//!
//! The archive is data from the system image: every length and offset is checked, so a
//! truncated or hostile archive yields an [`Error`], never a panic or an out-of-bounds read.
//! Names are stored without a leading `/` or `./` (`bin/busybox`); lookups take absolute
//! paths.

/// The newc magic.
const MAGIC: &[u8; 6] = b"070701";
const HEADER_LEN: usize = 110;
const TRAILER: &[u8] = b"TRAILER!!!";

/// File type bits of `mode` (as in Linux's `stat`).
pub const S_IFMT: u32 = 0o170000;
pub const S_IFREG: u32 = 0o100000;
pub const S_IFDIR: u32 = 0o040000;
pub const S_IFLNK: u32 = 0o120000;
pub const S_IFCHR: u32 = 0o020000;
pub const S_IFBLK: u32 = 0o060000;

/// Why an archive cannot be read, and at which byte offset.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Error {
    /// No `070701` magic at this offset.
    BadMagic(usize),
    /// A header field at this offset is not 8 hex digits.
    BadField(usize),
    /// The header, name or data of the entry at this offset runs past the end.
    Truncated(usize),
    /// The name of the entry at this offset is empty, lacks its NUL or is not UTF-8.
    BadName(usize),
    /// The archive ends without a `TRAILER!!!` entry.
    NoTrailer,
}

impl core::fmt::Display for Error {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::BadMagic(at) => write!(f, "no newc magic 070701 at byte {at}"),
            Self::BadField(at) => write!(f, "header field at byte {at} is not 8 hex digits"),
            Self::Truncated(at) => write!(f, "entry at byte {at} runs past the end"),
            Self::BadName(at) => write!(f, "entry at byte {at} has a bad name"),
            Self::NoTrailer => write!(f, "the archive has no TRAILER!!! entry"),
        }
    }
}

/// One entry of the archive.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Entry<'a> {
    /// Without a leading `/` (`"bin/busybox"`; `"."` or `""` for the root).
    pub name: &'a str,
    pub ino: u32,
    pub mode: u32,
    pub uid: u32,
    pub gid: u32,
    pub nlink: u32,
    pub mtime: u32,
    /// The file's bytes (a symbolic link's target).
    pub data: &'a [u8],
}

impl<'a> Entry<'a> {
    /// The normalised path without the leading `/`: `""` for the root (stored as `.`), no
    /// trailing `/`.
    pub fn path(&self) -> &'a str {
        let name = self.name.trim_end_matches('/');
        if name == "." { "" } else { name }
    }

    pub fn file_type(&self) -> u32 {
        self.mode & S_IFMT
    }
    pub fn is_dir(&self) -> bool {
        self.file_type() == S_IFDIR
    }
    pub fn is_symlink(&self) -> bool {
        self.file_type() == S_IFLNK
    }
    pub fn is_file(&self) -> bool {
        self.file_type() == S_IFREG
    }
}

/// A checked archive: [`Archive::new`] walks it once, so iterating and looking up never
/// fail afterwards.
#[derive(Clone, Copy, Debug)]
pub struct Archive<'a> {
    bytes: &'a [u8],
    entries: usize,
}

fn align4(n: usize) -> Option<usize> {
    n.checked_add(3).map(|n| n & !3)
}

/// Parses the entry at `at`: `Ok(None)` at the trailer, else the entry and the next offset.
fn parse_at(bytes: &[u8], at: usize) -> Result<Option<(Entry<'_>, usize)>, Error> {
    let header = bytes
        .get(at..at.checked_add(HEADER_LEN).ok_or(Error::Truncated(at))?)
        .ok_or(Error::Truncated(at))?;
    if &header[..6] != MAGIC {
        return Err(Error::BadMagic(at));
    }
    let field = |i: usize| -> Result<u32, Error> {
        let start = 6 + 8 * i;
        let text = &header[start..start + 8];
        let mut value = 0u32;
        for &c in text {
            let digit = (c as char)
                .to_digit(16)
                .ok_or(Error::BadField(at + start))?;
            value = value << 4 | digit;
        }
        Ok(value)
    };
    // Fields: ino mode uid gid nlink mtime filesize devmajor devminor rdevmajor rdevminor
    // namesize check.
    let (ino, mode, uid, gid, nlink, mtime) = (
        field(0)?,
        field(1)?,
        field(2)?,
        field(3)?,
        field(4)?,
        field(5)?,
    );
    let file_size = field(6)? as usize;
    let name_size = field(11)? as usize;
    let name_start = at + HEADER_LEN;
    let name_end = name_start
        .checked_add(name_size)
        .ok_or(Error::Truncated(at))?;
    let raw_name = bytes
        .get(name_start..name_end)
        .ok_or(Error::Truncated(at))?;
    let Some((&0, name)) = raw_name.split_last() else {
        return Err(Error::BadName(at));
    };
    if name.contains(&0) {
        return Err(Error::BadName(at));
    }
    let name = core::str::from_utf8(name).map_err(|_| Error::BadName(at))?;
    if name.as_bytes() == TRAILER {
        return Ok(None);
    }
    let data_start = align4(name_end).ok_or(Error::Truncated(at))?;
    let data_end = data_start
        .checked_add(file_size)
        .ok_or(Error::Truncated(at))?;
    let data = bytes
        .get(data_start..data_end)
        .ok_or(Error::Truncated(at))?;
    let next = align4(data_end).ok_or(Error::Truncated(at))?;
    let name = name.strip_prefix("./").unwrap_or(name);
    let name = name.trim_start_matches('/');
    Ok(Some((
        Entry {
            name,
            ino,
            mode,
            uid,
            gid,
            nlink,
            mtime,
            data,
        },
        next,
    )))
}

impl<'a> Archive<'a> {
    /// Checks the whole archive (up to its trailer; bytes after it are ignored, as the
    /// kernel ignores the padding of an initramfs).
    pub fn new(bytes: &'a [u8]) -> Result<Self, Error> {
        let mut at = 0;
        let mut entries = 0;
        loop {
            if at >= bytes.len() {
                return Err(Error::NoTrailer);
            }
            match parse_at(bytes, at)? {
                None => return Ok(Self { bytes, entries }),
                Some((_, next)) => {
                    entries += 1;
                    at = next;
                }
            }
        }
    }

    pub fn len(&self) -> usize {
        self.entries
    }

    pub fn is_empty(&self) -> bool {
        self.entries == 0
    }

    pub fn entries(&self) -> Entries<'a> {
        Entries {
            bytes: self.bytes,
            at: 0,
        }
    }

    /// The entry named by the absolute or relative `path` exactly (no `..`, no symbolic
    /// links followed: that is [`crate::vfs`]'s job). `/` is the root directory.
    pub fn get(&self, path: &str) -> Option<Entry<'a>> {
        let path = path.trim_start_matches('/').trim_end_matches('/');
        self.entries().find(|e| e.path() == path)
    }

    /// The entries directly inside the directory whose [`Entry::path`] is `dir` (`""` is
    /// the root), in archive order.
    pub fn children<'d>(&self, dir: &'d str) -> impl Iterator<Item = Entry<'a>> + 'd
    where
        'a: 'd,
    {
        self.entries()
            .filter(move |e| !e.path().is_empty() && parent(e.path()) == dir)
    }
}

/// The directory part of a normalised path (`"bin/sh"` -> `"bin"`, `"etc"` -> `""`).
pub fn parent(path: &str) -> &str {
    path.rfind('/').map_or("", |at| &path[..at])
}

/// The entries of a checked archive, in order.
#[derive(Clone, Debug)]
pub struct Entries<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Iterator for Entries<'a> {
    type Item = Entry<'a>;

    fn next(&mut self) -> Option<Entry<'a>> {
        // Checked by `Archive::new`: an error cannot happen here; stop if it did anyway.
        match parse_at(self.bytes, self.at) {
            Ok(Some((entry, next))) => {
                self.at = next;
                Some(entry)
            }
            _ => None,
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use std::io::Cursor;

    /// An archive written by the `cpio` crate (the writer `cargo xtask` uses).
    pub(crate) fn archive(files: &[(&str, u32, &[u8])]) -> Vec<u8> {
        let inputs = files.iter().enumerate().map(|(i, (name, mode, data))| {
            (
                cpio::newc::Builder::new(name)
                    .ino(i as u32 + 1)
                    .mode(*mode)
                    .nlink(1),
                Cursor::new(data.to_vec()),
            )
        });
        cpio::write_cpio(inputs, Cursor::new(Vec::new()))
            .unwrap()
            .into_inner()
    }

    #[test]
    fn reads_what_the_writer_wrote() {
        let bytes = archive(&[
            ("bin", S_IFDIR | 0o755, b""),
            ("bin/busybox", S_IFREG | 0o755, b"\x7fELF..."),
            ("bin/sh", S_IFLNK | 0o777, b"busybox"),
            (
                "etc/passwd",
                S_IFREG | 0o644,
                b"root:x:0:0:root:/root:/bin/sh\n",
            ),
        ]);
        let a = Archive::new(&bytes).unwrap();
        assert_eq!(a.len(), 4);
        let names: Vec<&str> = a.entries().map(|e| e.name).collect();
        assert_eq!(names, ["bin", "bin/busybox", "bin/sh", "etc/passwd"]);
        let sh = a.get("/bin/sh").unwrap();
        assert!(sh.is_symlink());
        assert_eq!(sh.data, b"busybox");
        let bb = a.get("bin/busybox").unwrap();
        assert!(bb.is_file());
        assert_eq!((bb.data, bb.mode & 0o777), (&b"\x7fELF..."[..], 0o755));
        assert!(a.get("/bin").unwrap().is_dir());
        assert!(a.get("/nothing").is_none());
        let children: Vec<&str> = a.children("bin").map(|e| e.name).collect();
        assert_eq!(children, ["bin/busybox", "bin/sh"]);
        let top: Vec<&str> = a.children("").map(|e| e.name).collect();
        assert_eq!(
            top,
            ["bin"],
            "etc/passwd has no etc entry: not a child of the root"
        );
        assert_eq!(
            (parent("bin/sh"), parent("etc"), parent("")),
            ("bin", "", "")
        );
    }

    #[test]
    fn names_lose_leading_dot_slash() {
        let bytes = archive(&[("./init", S_IFREG | 0o755, b"x"), ("/etc", S_IFDIR, b"")]);
        let a = Archive::new(&bytes).unwrap();
        assert_eq!(a.get("/init").unwrap().data, b"x");
        assert!(a.get("/etc").unwrap().is_dir());
    }

    #[test]
    fn hostile_archives_are_errors() {
        let good = archive(&[("a", S_IFREG, b"hello")]);
        assert_eq!(Archive::new(&[]).unwrap_err(), Error::NoTrailer);
        assert_eq!(
            Archive::new(b"070707xxxx").unwrap_err(),
            Error::Truncated(0)
        );
        let mut bad = good.clone();
        bad[0] = b'1';
        assert_eq!(Archive::new(&bad).unwrap_err(), Error::BadMagic(0));
        let mut bad = good.clone();
        bad[6 + 8 * 6] = b'z'; // filesize
        assert_eq!(Archive::new(&bad).unwrap_err(), Error::BadField(6 + 48));
        let mut bad = good.clone();
        bad[6 + 8 * 6..6 + 8 * 7].copy_from_slice(b"ffffffff"); // huge filesize
        assert_eq!(Archive::new(&bad).unwrap_err(), Error::Truncated(0));
        // No trailer: cut right after the first entry.
        let first_len = 112 + 8; // header + "a\0" padded, then "hello" padded
        assert_eq!(
            Archive::new(&good[..first_len]).unwrap_err(),
            Error::NoTrailer
        );
    }

    /// Every prefix and every single-byte change of an archive parses or fails cleanly.
    #[test]
    fn truncations_and_bit_flips_never_panic() {
        let good = archive(&[
            ("bin/busybox", S_IFREG | 0o755, &[7u8; 37]),
            ("bin/sh", S_IFLNK | 0o777, b"busybox"),
        ]);
        for cut in 0..good.len() {
            let _ = Archive::new(&good[..cut]).map(|a| a.entries().count());
        }
        for i in 0..good.len() {
            for flip in [1u8, 0x80, 0xff] {
                let mut bad = good.clone();
                bad[i] ^= flip;
                if let Ok(a) = Archive::new(&bad) {
                    for e in a.entries() {
                        let _ = (e.name, e.data.len());
                    }
                    let _ = a.get("/bin/sh");
                }
            }
        }
    }
}
