//! syssw is a freestanding static executable (no libc, no start files) for the host target:
//! it gets hardware floating point, and the kernel loads it as the root task.
fn main() {
    println!("cargo:rustc-link-arg-bins=-nostartfiles");
    println!("cargo:rustc-link-arg-bins=-nodefaultlibs");
    println!("cargo:rustc-link-arg-bins=-static");
    println!("cargo:rustc-link-arg-bins=-no-pie");
}
