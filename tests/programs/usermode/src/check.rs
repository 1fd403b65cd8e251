//! Check reporting: every check prints `check ok: <what>` or `check FAILED: <what>...`; the
//! first failure ends the run with the failure outcome, so later checks never see a broken
//! state. Test harnesses match the `check ok:` lines literally.

use core::fmt::Debug;
use user_rt::abi::syscall::Error;
use user_rt::{println, sys};

/// Reports a failed check (with details) and ends the run as failed.
pub fn fail(what: &str, detail: core::fmt::Arguments) -> ! {
    println!("check FAILED: {what}{detail}");
    let _ = sys::system_halt(false);
    // Only reached if the caller may not halt (never in the root task).
    sys::thread_exit()
}

pub fn expect(what: &str, ok: bool) {
    if ok {
        println!("check ok: {what}");
    } else {
        fail(what, format_args!(""));
    }
}

/// Checks `got == want`; a failure prints both.
pub fn expect_eq<T: PartialEq + Debug>(what: &str, got: T, want: T) {
    if got == want {
        println!("check ok: {what}");
    } else {
        fail(what, format_args!(": got {got:?}, expected {want:?}"));
    }
}

/// Checks that `got` is the error `want`.
pub fn expect_err<T: Debug>(what: &str, got: Result<T, Error>, want: Error) {
    match got {
        Err(e) if e == want => println!("check ok: {what}"),
        other => fail(
            what,
            format_args!(": got {other:?}, expected Err({want:?})"),
        ),
    }
}

/// Checks that `got` succeeded and returns its value.
pub fn expect_ok<T: Debug>(what: &str, got: Result<T, Error>) -> T {
    match got {
        Ok(v) => {
            println!("check ok: {what}");
            v
        }
        Err(e) => fail(what, format_args!(": got Err({e:?}), expected success")),
    }
}

/// A precondition of later checks (no `check ok` line): returns the value or fails the run.
pub fn must<T, E: Debug>(what: &str, got: Result<T, E>) -> T {
    match got {
        Ok(v) => v,
        Err(e) => fail(what, format_args!(": {e:?}")),
    }
}

/// A result as the raw `rax` code (0 = success), for reporting through shared memory.
pub fn code<T>(result: &Result<T, Error>) -> u64 {
    match result {
        Ok(_) => 0,
        Err(e) => *e as u64,
    }
}

/// A raw `rax` code back as a result.
pub fn status(code: u64) -> Result<(), Error> {
    sys::status(code)
}
