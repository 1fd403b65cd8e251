//! Build script shared by every user-mode binary (syssw, partitions, test programs; each
//! names it with `build = "<path to>/user/link.rs"`): a freestanding static executable, no
//! libc, no start files.
//!
//! Built for `x86_64-unknown-none`, rustc links with `rust-lld` directly, which never adds
//! start files or libraries (and does not know the C-driver flags below); built for a
//! hosted target such as `x86_64-unknown-linux-gnu`, the C compiler driver links and must be
//! told to leave them out.
fn main() {
    // The link arguments depend on nothing but this script, whose own changes cargo always
    // tracks; naming the manifest keeps cargo from re-running it (and relinking the binary)
    // on every build, which it does when a script names no file or a missing one.
    println!("cargo:rerun-if-changed=Cargo.toml");
    if std::env::var("CARGO_CFG_TARGET_OS").is_ok_and(|os| os == "none") {
        return;
    }
    println!("cargo:rustc-link-arg-bins=-nostartfiles");
    println!("cargo:rustc-link-arg-bins=-nodefaultlibs");
    println!("cargo:rustc-link-arg-bins=-static");
    println!("cargo:rustc-link-arg-bins=-no-pie");
}
