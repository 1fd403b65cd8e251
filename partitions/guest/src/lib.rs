//! The paravirtualized guest: a Linux-ABI personality that runs unmodified static Linux
//! executables (Debian's `busybox-static`) as tasks of the microkernel. Each Linux process
//! is a child task of the guest partition created without `native_syscalls`, its thread
//! has the guest as exception handler, so its `syscall`s and faults reach the guest as
//! exception messages with the full register context; the guest serves them and replies
//! with the edited registers.
//!
//! This library is the personality itself, host-tested: the initramfs reader ([`cpio`]),
//! the file system ([`vfs`]: the initramfs's contents, writable, in memory, with `/dev`
//! and `/proc`, and the open file descriptions), the executable loader ([`elf`],
//! [`exec`]) and initial stack ([`stack`]), the address-space bookkeeping and fault
//! decisions ([`memory`]), page pool ([`pool`]), which pool page backs which process page
//! ([`backing`]) and the demand paging and copy-on-write sharing of those pages
//! ([`frames`]), the process state ([`process`]), the system calls of one process
//! ([`syscall`]; the file calls in [`syscall::file`], the signal and timer calls in
//! [`sigcalls`]), the signals' numbers, actions and frame ([`signal`]), the pipes
//! ([`pipe`]), the process table with fork, exec, wait, signal delivery, process groups,
//! timers and the deferred replies of waiting calls ([`system`]), the scheduling policy
//! that says at which of three priorities each process's thread runs ([`sched`]), the
//! console's terminal line discipline ([`tty`]), the sockets and their TCP/IP stack
//! ([`net`], the calls in [`syscall::socket`]) and the partition's ARINC ports as the devices
//! `/dev/arinc/<port>` ([`arinc`]: their table, messages, `EMSGSIZE`, validity ioctl), the
//! block device `/dev/vda` on the partition's virtual disk ([`disk`]: offsets onto sectors,
//! the sector cache, the block ioctls); the
//! partition program (`main.rs`) only moves messages, creates tasks, maps pages, drives
//! COM2 (`com2.rs`), moves port messages through syssw (`ports.rs`), writes the log and
//! gives the library its heap (a part of the memory pool: the file system's data and tables
//! live there, within the byte limit [`vfs::Fs::new`] gets).
//!
//! # The console
//!
//! Every process starts with the console on descriptors 0, 1 and 2 (a
//! [`process::File::Console`], the file a device node such as `/dev/tty` is to open). With
//! `guest.console = "com2"` in the configuration ([`CONSOLE_PATH`] in the initramfs) it is
//! a terminal: COM2's input goes through the line discipline ([`tty::Tty`]: echo, line
//! editing, the control characters' signals for the foreground process group, sent with
//! [`system::System::signal_group`]), a `read` waits for it as a deferred reply, output
//! goes through the terminal to COM2, and the terminal ioctls and `poll` answer. Without it
//! the console is the log: output lines are logged ([`console`]), reading gives end of
//! file, and the terminal ioctls answer `ENOTTY`.
//!
//! # Log lines (COM1, each prefixed `[<partition>] ` by the kernel)
//!
//! - `guest: process <pid> (<name>) started: <argv>` when a process starts (the first one,
//!   or one that `execve`s), or `guest: cannot start <path>: <why>` (the first),
//!   `guest: process <pid> cannot execute <path>: <why>` (an `execve` that failed after the
//!   old image was dropped: the process dies with SIGSEGV);
//! - `guest: process <pid> (<name>) forked from <ppid>: <n> pages shared in <t> us` (the
//!   pages the child got, shared copy-on-write or the few a fork foresees copied
//!   ([`frames::ForkWrites`]), and how long the `fork` took);
//! - `guest: process <pid> <stdout|stderr>: <text>` for each line it writes ([`console`]),
//!   when the console is the log;
//! - `guest: process <pid> exited with status <n>` (`exit`, `exit_group`);
//! - `guest: process <pid> (<name>) killed by signal <n> (<NAME>): vector ... rip ...`
//!   when a fault kills it (`SIGBUS` when the guest is out of memory for a page it
//!   touches), `guest: process <pid> (<name>) killed by signal <n> (<NAME>)`
//!   when a signal it does not catch ends it (`kill`, `SIGPIPE`, an alarm), with
//!   `: no room for the frame ...` or `: rt_sigreturn without a readable signal frame`
//!   when a handler's frame could not be written or read back;
//! - `guest: console: cannot start the COM2 reader: <error>` or `guest: console: cannot
//!   attach interrupt line 3: <error>` (the console then has no input), `guest: console:
//!   no UART at COM2's ports, the console is the log`;
//! - `guest: process <pid> (<name>): unsupported system call <n> (<name>), returning
//!   ENOSYS` (the call's Linux name, `unknown` beyond the 64-bit ABI), once per call number
//!   and guest (a loop starting processes that make it adds no line);
//! - `guest: eth0 <mac> <address>/<prefix> through ports <rx> and <tx>` at start with
//!   `guest.net` ([`net`]), or `guest: /etc/guest/net line <n>: <why>; no eth0`,
//!   `guest: /etc/guest/net: no port <rx> or <tx>; no eth0` (the guest then has `lo` only);
//! - `guest: /dev/vda <n> sectors through ports <request> and <response>` at start with
//!   `guest.disk` ([`disk`]), or `guest: /etc/guest/disk line <n>: <why>; no /dev/vda`,
//!   `guest: /etc/guest/disk: no port <request> or <response>; no /dev/vda`;
//!   `guest: /dev/vda: <read|write|flush> of sector <n> failed: <why>` for a failed request
//!   (the call fails with `EIO`; at most [`disk::MAX_LOGGED`] lines);
//! - `guest: port <name>: cannot create it: <ARINC code, or no answer>` (its device
//!   answers `ENXIO`),
//!   `guest: /etc/guest/ports line <n>: <why>; no ports`, `guest: no room for the port
//!   devices: <errno>`;
//! - `guest: fork by <pid> (<name>) refused: no task, thread or slot left (<n> processes
//!   and threads)` when a `fork` fails with `EAGAIN` (the first
//!   [`system::REFUSALS_LOGGED`]; the last of them adds `; further refusals are not
//!   logged`);
//! - `guest: init ended with <n> other processes left` (zombies included), the first 16
//!   of them each as `guest: left: <pid> (<name>) <running | forked, never ran | waiting in
//!   system call <number> | waiting on exception <vector> | vforked <pid> | zombie
//!   <wait status>>`, then
//!   `guest: init exited with status <n>` or `guest: init killed by signal <n>` (also the
//!   detail of the health report).
#![cfg_attr(not(test), no_std)]

extern crate alloc;

pub mod arinc;
pub mod backing;
pub mod console;
pub mod cpio;
pub mod disk;
pub mod elf;
pub mod events;
pub mod exec;
pub mod frames;
pub mod info;
pub mod linux;
pub mod memory;
pub mod net;
pub mod pipe;
pub mod poll;
pub mod pool;
pub mod process;
pub mod sched;
pub mod sigcalls;
pub mod signal;
pub mod stack;
pub mod syscall;
pub mod system;
pub mod tty;
pub mod vfs;

/// Where the guest's command line is in the initramfs: `argv` of the first process, each
/// argument NUL-terminated (written by `cargo xtask` from the partition's `guest.init`).
pub const INIT_ARGS_PATH: &str = "/etc/guest/init";
/// Its environment, in the same form (from `guest.env`).
pub const INIT_ENV_PATH: &str = "/etc/guest/env";
/// The console's device, `com2` (from `guest.console`); without the file the console is
/// the log.
pub const CONSOLE_PATH: &str = "/etc/guest/console";

/// The NUL-terminated strings of `bytes` (a trailing piece without NUL counts too; empty
/// strings are kept), at most `out.len()`; returns how many.
pub fn split_nul<'a>(bytes: &'a [u8], out: &mut [&'a [u8]]) -> usize {
    let mut n = 0;
    for s in bytes.split_inclusive(|&b| b == 0) {
        if n == out.len() {
            break;
        }
        out[n] = s.strip_suffix(&[0]).unwrap_or(s);
        n += 1;
    }
    n
}

/// The `key=value` lines of a settings file under `/etc/guest` (`net`, `disk`): each with
/// its line number, blank lines skipped; a line without `=` is an error naming its line.
pub fn settings(
    text: &str,
) -> impl Iterator<Item = Result<(usize, &str, &str), (usize, &'static str)>> {
    text.lines()
        .enumerate()
        .map(|(n, line)| (n + 1, line.trim()))
        .filter(|(_, line)| !line.is_empty())
        .map(|(at, line)| match line.split_once('=') {
            Some((key, value)) => Ok((at, key, value)),
            None => Err((at, "expected key=value")),
        })
}

#[cfg(test)]
mod tests;
