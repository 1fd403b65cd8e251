//! Starting a program in a new process: look the executable up in the initramfs, plan its
//! layout ([`crate::elf`]), back and fill its segments, map the stack and lay out `argv`,
//! `envp` and the auxiliary vector on it ([`crate::stack`]). What it returns is everything
//! the partition program needs to create the process's thread: entry and stack pointer.

use crate::elf::{ElfError, LoadPlan};
use crate::frames::MAX_IMAGE_ID;
use crate::linux::Errno;
use crate::memory::{AreaError, STACK_TOP};
use crate::process::Process;
use crate::stack::{self, AuxInfo, StackError};
use crate::syscall::Host;
use crate::vfs::{self, Fs, Node};

/// Bytes at the top of the stack the initial stack may take (arguments, environment,
/// auxiliary vector).
pub const ARG_MAX: usize = 16 * 1024;

/// Why a program cannot start.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExecError {
    /// Looking the executable up failed (`ENOENT`, `ENOTDIR`, `ELOOP` ...).
    Lookup(Errno),
    /// It is not a regular file.
    NotAFile,
    /// No execute permission bit.
    NotExecutable,
    Elf(ElfError),
    /// Too many areas, or an area outside user space.
    Layout(AreaError),
    Stack(StackError),
    /// Its memory cannot be mapped: `ENOMEM` (the guest is out of memory), `EACCES` (a
    /// segment both writable and executable, which the guest never maps).
    Memory(Errno),
    /// `guest.init` is empty (or its initramfs lacks `/etc/guest/init`).
    NoArguments,
}

impl core::fmt::Display for ExecError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Lookup(e) => write!(f, "{} (errno {})", e.describe(), e.0),
            Self::NotAFile => write!(f, "not a regular file"),
            Self::NotExecutable => write!(f, "no execute permission"),
            Self::Elf(e) => write!(f, "{e}"),
            Self::Layout(e) => write!(f, "its memory layout does not fit: {e:?}"),
            Self::Stack(e) => write!(f, "its arguments do not fit the stack: {e:?}"),
            Self::Memory(Errno::EACCES) => {
                write!(f, "a segment is writable and executable (never mapped)")
            }
            Self::Memory(_) => write!(f, "the guest is out of memory"),
            Self::NoArguments => write!(f, "no program given (guest.init)"),
        }
    }
}

/// A loaded program, ready to run: the thread starts at `entry` with `rsp = sp`.
#[derive(Debug)]
pub struct Loaded {
    pub process: Process,
    pub entry: u64,
    pub sp: u64,
}

/// Loads `argv[0]` from `fs` as process `pid` (parent `ppid`) with `argv` and `envp`,
/// mapping its memory through `host`. `hwcap` is what the CPU offers (`AT_HWCAP`). On an
/// error, pages already mapped are the caller's to release (with the task).
pub fn load(
    fs: &Fs,
    host: &mut impl Host,
    pid: u32,
    ppid: u32,
    argv: &[&[u8]],
    envp: &[&[u8]],
    hwcap: u64,
) -> Result<Loaded, ExecError> {
    let path = *argv.first().ok_or(ExecError::NoArguments)?;
    let root = Node::Inode(vfs::ROOT);
    load_file(fs, host, (pid, ppid), root, path, argv, envp, hwcap)
}

/// An executable found: its bytes, its absolute path, and the id its loaded pages may be
/// cached under (the file's, while it still holds the initramfs's bytes; else one the
/// cache never keeps: a file written since may change).
pub struct Found<'f> {
    pub bytes: &'f [u8],
    pub exe: vfs::PathBuf,
    pub image: u32,
}

/// The executable at `path` (relative to `cwd`), checked: a regular file with an execute
/// bit (what `execve` checks before it drops the old image). `pid` is the caller's
/// (`/proc/self`).
pub fn find<'f>(fs: &'f Fs, pid: u32, cwd: Node, path: &[u8]) -> Result<Found<'f>, ExecError> {
    let procs = vfs::proc::Procs::alone(pid);
    let node = fs
        .lookup(&procs, cwd, path, true)
        .map_err(ExecError::Lookup)?;
    let data = fs.file_bytes(node).ok_or(ExecError::NotAFile)?;
    if fs.mode(node) & 0o111 == 0 {
        return Err(ExecError::NotExecutable);
    }
    let exe = fs.path_of(node).map_err(ExecError::Lookup)?;
    let image = fs
        .archive_ino(node)
        .filter(|&ino| ino < MAX_IMAGE_ID)
        .unwrap_or(MAX_IMAGE_ID);
    Ok(Found {
        bytes: data,
        exe,
        image,
    })
}

/// [`load`] with the executable's `path` (relative to `cwd`) apart from `argv`
/// (`execve`); `ids` are the process's pid and parent pid.
#[allow(clippy::too_many_arguments)] // what a program starts with
pub fn load_file(
    fs: &Fs,
    host: &mut impl Host,
    (pid, ppid): (u32, u32),
    cwd: Node,
    path: &[u8],
    argv: &[&[u8]],
    envp: &[&[u8]],
    hwcap: u64,
) -> Result<Loaded, ExecError> {
    let Found {
        bytes: elf,
        exe,
        image,
    } = find(fs, pid, cwd, path)?;
    let plan = LoadPlan::new(elf).map_err(ExecError::Elf)?;
    let mut process = Process::new(pid, ppid, exe);
    process.cwd = cwd;
    process.set_cmdline(argv);
    let (runs, n) = plan.page_runs();
    process
        .set_image(&runs[..n], plan.brk_start)
        .map_err(ExecError::Layout)?;
    // Each page is written once, straight into the frame that backs it (or shared with
    // the processes that run the same unchanged initramfs file).
    for run in &runs[..n] {
        host.map_image(run.start, run.pages, run.rights, image, &mut |at, page| {
            plan.fill(elf, at, page)
        })
        .map_err(ExecError::Memory)?;
    }
    // The stack's pages are backed when touched: the strings below fill its top ones.
    process.add_stack().map_err(ExecError::Layout)?;
    let mut aux = AuxInfo {
        phdr: plan.phdr,
        phnum: plan.phnum,
        phent: plan.phent,
        entry: plan.entry,
        hwcap,
        ..AuxInfo::default()
    };
    host.random(&mut aux.random);
    let mut top = [0u8; ARG_MAX];
    let built =
        stack::build(&mut top, STACK_TOP, argv, envp, path, &aux).map_err(ExecError::Stack)?;
    host.write_user(STACK_TOP - built.used as u64, &top[ARG_MAX - built.used..])
        .map_err(ExecError::Memory)?;
    Ok(Loaded {
        process,
        entry: plan.entry,
        sp: built.sp,
    })
}
