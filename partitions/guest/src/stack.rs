//! The initial stack of a Linux process, as the x86-64 SysV ABI and Linux's `execve` lay it
//! out. From the top (highest address) down:
//!
//! ```text
//! 16 random bytes (AT_RANDOM), the executable's name (AT_EXECFN), "x86_64" (AT_PLATFORM)
//! environment strings, argument strings            (each NUL-terminated)
//! padding so that the stack pointer ends 16-byte aligned
//! auxiliary vector: (type, value) pairs ending with AT_NULL
//! envp[0..n], NULL
//! argv[0..argc], NULL
//! argc                                              <- rsp, 16-byte aligned
//! ```
//!
//! [`build`] writes it into a buffer standing for the memory just below `top`, so it is
//! tested on the host and copied into the process's stack pages by the partition program.

/// Auxiliary-vector types (Linux's `AT_*`).
pub const AT_NULL: u64 = 0;
pub const AT_PHDR: u64 = 3;
pub const AT_PHENT: u64 = 4;
pub const AT_PHNUM: u64 = 5;
pub const AT_PAGESZ: u64 = 6;
pub const AT_BASE: u64 = 7;
pub const AT_FLAGS: u64 = 8;
pub const AT_ENTRY: u64 = 9;
pub const AT_UID: u64 = 11;
pub const AT_EUID: u64 = 12;
pub const AT_GID: u64 = 13;
pub const AT_EGID: u64 = 14;
pub const AT_PLATFORM: u64 = 15;
pub const AT_HWCAP: u64 = 16;
pub const AT_CLKTCK: u64 = 17;
pub const AT_SECURE: u64 = 23;
pub const AT_RANDOM: u64 = 25;
pub const AT_HWCAP2: u64 = 26;
pub const AT_EXECFN: u64 = 31;

/// Most arguments plus environment strings.
pub const MAX_STRINGS: usize = 64;

/// What the auxiliary vector tells the process about itself and the system.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AuxInfo {
    pub phdr: u64,
    pub phnum: u64,
    pub phent: u64,
    pub entry: u64,
    /// CPUID leaf 1's EDX (what Linux reports as `AT_HWCAP` on x86-64).
    pub hwcap: u64,
    pub uid: u32,
    pub gid: u32,
    /// The bytes `AT_RANDOM` points to (the C library seeds its stack protector with them).
    pub random: [u8; 16],
}

/// Why the stack cannot be built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StackError {
    /// The strings and vectors need more than the buffer.
    TooBig,
    /// More than [`MAX_STRINGS`] arguments and environment strings.
    TooManyStrings,
}

/// The built stack: the initial `rsp` and how many bytes below `top` it uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct InitialStack {
    pub sp: u64,
    pub used: usize,
}

/// Writes from the top of `buf` down.
struct Writer<'a> {
    buf: &'a mut [u8],
    /// Offset in `buf` of the lowest byte written.
    at: usize,
    top: u64,
}

impl Writer<'_> {
    fn address(&self) -> u64 {
        self.top - (self.buf.len() - self.at) as u64
    }
    fn push(&mut self, bytes: &[u8]) -> Result<u64, StackError> {
        self.at = self.at.checked_sub(bytes.len()).ok_or(StackError::TooBig)?;
        self.buf[self.at..self.at + bytes.len()].copy_from_slice(bytes);
        Ok(self.address())
    }
    fn push_str(&mut self, s: &[u8]) -> Result<u64, StackError> {
        self.push(&[0])?;
        self.push(s)
    }
    fn align_down(&mut self, to: u64) -> Result<(), StackError> {
        let pad = (self.address() % to) as usize;
        self.at = self.at.checked_sub(pad).ok_or(StackError::TooBig)?;
        self.buf[self.at..self.at + pad].fill(0);
        Ok(())
    }
}

/// Lays out the initial stack for `argv` and `envp` in `buf`, which stands for the memory
/// `top - buf.len() .. top` (`top` 16-byte aligned). `execfn` is the path that was executed.
pub fn build(
    buf: &mut [u8],
    top: u64,
    argv: &[&[u8]],
    envp: &[&[u8]],
    execfn: &[u8],
    aux: &AuxInfo,
) -> Result<InitialStack, StackError> {
    if argv.len() + envp.len() > MAX_STRINGS {
        return Err(StackError::TooManyStrings);
    }
    if !top.is_multiple_of(16) || (buf.len() as u64) > top {
        return Err(StackError::TooBig);
    }
    let mut w = Writer {
        at: buf.len(),
        buf,
        top,
    };
    let random = w.push(&aux.random)?;
    let execfn_at = w.push_str(execfn)?;
    let platform = w.push_str(b"x86_64")?;
    let mut env_at = [0u64; MAX_STRINGS];
    for (slot, s) in env_at.iter_mut().zip(envp).rev() {
        *slot = w.push_str(s)?;
    }
    let mut arg_at = [0u64; MAX_STRINGS];
    for (slot, s) in arg_at.iter_mut().zip(argv).rev() {
        *slot = w.push_str(s)?;
    }
    let auxv: [(u64, u64); 18] = [
        (AT_PHDR, aux.phdr),
        (AT_PHENT, aux.phent),
        (AT_PHNUM, aux.phnum),
        (AT_PAGESZ, 4096),
        (AT_BASE, 0),
        (AT_FLAGS, 0),
        (AT_ENTRY, aux.entry),
        (AT_UID, aux.uid as u64),
        (AT_EUID, aux.uid as u64),
        (AT_GID, aux.gid as u64),
        (AT_EGID, aux.gid as u64),
        (AT_SECURE, 0),
        (AT_RANDOM, random),
        (AT_HWCAP, aux.hwcap),
        (AT_HWCAP2, 0),
        (AT_CLKTCK, 100),
        (AT_PLATFORM, platform),
        (AT_EXECFN, execfn_at),
    ];
    // Words below the strings: argc, argv + NULL, envp + NULL, auxv + AT_NULL.
    let words = 1 + argv.len() + 1 + envp.len() + 1 + 2 * (auxv.len() + 1);
    w.align_down(16)?;
    if words % 2 == 1 {
        w.push(&[0; 8])?;
    }
    w.push(&0u64.to_le_bytes())?;
    w.push(&AT_NULL.to_le_bytes())?;
    for (kind, value) in auxv.iter().rev() {
        w.push(&value.to_le_bytes())?;
        w.push(&kind.to_le_bytes())?;
    }
    w.push(&0u64.to_le_bytes())?;
    for at in env_at[..envp.len()].iter().rev() {
        w.push(&at.to_le_bytes())?;
    }
    w.push(&0u64.to_le_bytes())?;
    for at in arg_at[..argv.len()].iter().rev() {
        w.push(&at.to_le_bytes())?;
    }
    let sp = w.push(&(argv.len() as u64).to_le_bytes())?;
    debug_assert_eq!(sp % 16, 0);
    Ok(InitialStack {
        sp,
        used: (top - sp) as usize,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const TOP: u64 = 0x7fff_0000_0000;

    fn word(buf: &[u8], address: u64) -> u64 {
        let at = buf.len() - (TOP - address) as usize;
        u64::from_le_bytes(buf[at..at + 8].try_into().unwrap())
    }

    fn string(buf: &[u8], address: u64) -> Vec<u8> {
        let at = buf.len() - (TOP - address) as usize;
        buf[at..].iter().take_while(|&&b| b != 0).copied().collect()
    }

    fn aux() -> AuxInfo {
        AuxInfo {
            phdr: 0x40_0040,
            phnum: 10,
            phent: 56,
            entry: 0x40_ebf0,
            hwcap: 0x178b_fbff,
            uid: 0,
            gid: 0,
            random: *b"0123456789abcdef",
        }
    }

    type Strings = Vec<Vec<u8>>;

    /// Walks the stack as the C library's start code does.
    fn walk(buf: &[u8], sp: u64) -> (Strings, Strings, Vec<(u64, u64)>) {
        let argc = word(buf, sp);
        let mut at = sp + 8;
        let mut argv = Vec::new();
        for _ in 0..argc {
            argv.push(string(buf, word(buf, at)));
            at += 8;
        }
        assert_eq!(word(buf, at), 0, "argv ends with NULL");
        at += 8;
        let mut envp = Vec::new();
        while word(buf, at) != 0 {
            envp.push(string(buf, word(buf, at)));
            at += 8;
        }
        at += 8;
        let mut auxv = Vec::new();
        loop {
            let (k, v) = (word(buf, at), word(buf, at + 8));
            auxv.push((k, v));
            at += 16;
            if k == AT_NULL {
                break;
            }
        }
        (argv, envp, auxv)
    }

    #[test]
    fn lays_out_argv_envp_and_auxv_aligned() {
        for argc in 1..4 {
            for envc in 0..3 {
                let args: Vec<Vec<u8>> =
                    (0..argc).map(|i| format!("arg{i}").into_bytes()).collect();
                let envs: Vec<Vec<u8>> =
                    (0..envc).map(|i| format!("E{i}=x").into_bytes()).collect();
                let argv: Vec<&[u8]> = args.iter().map(|a| &a[..]).collect();
                let envp: Vec<&[u8]> = envs.iter().map(|e| &e[..]).collect();
                let mut buf = vec![0u8; 4096];
                let s = build(&mut buf, TOP, &argv, &envp, b"/bin/busybox", &aux()).unwrap();
                assert_eq!(s.sp % 16, 0, "argc={argc} envc={envc}");
                assert_eq!(s.used as u64, TOP - s.sp);
                let (a, e, auxv) = walk(&buf, s.sp);
                assert_eq!(a, args);
                assert_eq!(e, envs);
                let get = |k| auxv.iter().find(|(kk, _)| *kk == k).map(|(_, v)| *v);
                assert_eq!(get(AT_PHDR), Some(0x40_0040));
                assert_eq!(get(AT_PHNUM), Some(10));
                assert_eq!(get(AT_PHENT), Some(56));
                assert_eq!(get(AT_PAGESZ), Some(4096));
                assert_eq!(get(AT_ENTRY), Some(0x40_ebf0));
                assert_eq!(get(AT_HWCAP), Some(0x178b_fbff));
                assert_eq!(get(AT_SECURE), Some(0));
                assert_eq!(get(AT_UID), Some(0));
                let random = get(AT_RANDOM).unwrap();
                let at = buf.len() - (TOP - random) as usize;
                assert_eq!(&buf[at..at + 16], b"0123456789abcdef");
                assert_eq!(string(&buf, get(AT_EXECFN).unwrap()), b"/bin/busybox");
                assert_eq!(string(&buf, get(AT_PLATFORM).unwrap()), b"x86_64");
                assert_eq!(auxv.last(), Some(&(AT_NULL, 0)));
            }
        }
    }

    #[test]
    fn too_little_room_is_an_error() {
        let long = vec![b'x'; 5000];
        let mut buf = vec![0u8; 4096];
        assert_eq!(
            build(&mut buf, TOP, &[&long], &[], b"/x", &aux()),
            Err(StackError::TooBig)
        );
        let mut small = vec![0u8; 300];
        assert_eq!(
            build(&mut small, TOP, &[b"a"], &[], b"/x", &aux()),
            Err(StackError::TooBig)
        );
        let many = vec![&b"a"[..]; MAX_STRINGS + 1];
        assert_eq!(
            build(&mut buf, TOP, &many, &[], b"/x", &aux()),
            Err(StackError::TooManyStrings)
        );
        assert_eq!(
            build(&mut buf, TOP + 8, &[b"a"], &[], b"/x", &aux()),
            Err(StackError::TooBig)
        );
    }
}
