//! Build script shared by every user-mode binary (syssw, partitions, test programs; each
//! names it with `build = ...`): a freestanding static executable, no libc, no start files.
fn main() {
    println!("cargo:rustc-link-arg-bins=-nostartfiles");
    println!("cargo:rustc-link-arg-bins=-nodefaultlibs");
    println!("cargo:rustc-link-arg-bins=-static");
    println!("cargo:rustc-link-arg-bins=-no-pie");
}
