//! Builds a stand-alone Cargo workspace around generated modules (for the differential tests
//! and the benchmark, which run translated programs on the host): writes its manifests and
//! sources under a directory of `target/`, only rewriting files whose contents changed (so
//! an unchanged set of programs is not compiled again), runs `cargo build` and says where
//! the binary is and how long the build took. Generated programs can be spread over several
//! library crates, which cargo compiles in parallel.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// A dependency of a member.
pub enum Dependency {
    /// A crate of this repository: `(name, directory, features)`.
    Path(String, PathBuf, Vec<String>),
    /// Another member of the workspace, by name.
    Member(String),
}

/// A crate of the workspace.
pub struct Member {
    pub name: String,
    /// `src/main.rs` of a binary, or `src/lib.rs` of a library.
    pub root: Root,
    pub dependencies: Vec<Dependency>,
    /// Further files under `src/` (`(file name, contents)`).
    pub files: Vec<(String, String)>,
}

/// A member's crate root.
pub enum Root {
    Bin(String),
    Lib(String),
}

/// A workspace to build.
pub struct Workspace {
    /// Where it lives (created if missing); its target directory is `dir/target`.
    pub dir: PathBuf,
    /// The release profile's `opt-level`.
    pub opt_level: u8,
    pub members: Vec<Member>,
}

/// A finished build.
pub struct Built {
    pub binary: PathBuf,
    /// Wall time of `cargo build` (seconds; near 0 when nothing changed).
    pub seconds: f64,
}

/// The directory of a crate of this repository (`partitions/softplc/<name>`).
pub fn softplc_crate(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("partitions/softplc")
        .join(name)
}

/// The repository's `target/` directory (honours CARGO_TARGET_DIR).
pub fn target_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../..")
                .join("target")
        })
}

fn write_if_changed(path: &Path, contents: &[u8]) -> std::io::Result<()> {
    if std::fs::read(path).is_ok_and(|old| old == contents) {
        return Ok(());
    }
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent)?;
    }
    std::fs::write(path, contents)
}

/// Writes `contents` to `path` unless it holds them already (an unchanged file keeps its
/// time stamp, so cargo does not rebuild).
pub fn write_file(path: &Path, contents: &[u8]) -> Result<(), String> {
    write_if_changed(path, contents).map_err(|e| format!("{}: {e}", path.display()))
}

impl Member {
    fn manifest(&self) -> String {
        let mut m = format!(
            "[package]\nname = \"{}\"\nversion = \"0.0.0\"\nedition = \"2024\"\npublish = false\n\n[dependencies]\n",
            self.name
        );
        for dependency in &self.dependencies {
            match dependency {
                Dependency::Path(name, path, features) => {
                    let features: Vec<String> =
                        features.iter().map(|f| format!("\"{f}\"")).collect();
                    m.push_str(&format!(
                        "{name} = {{ path = \"{}\", features = [{}] }}\n",
                        path.display(),
                        features.join(", ")
                    ));
                }
                Dependency::Member(name) => {
                    m.push_str(&format!("{name} = {{ path = \"../{name}\" }}\n"));
                }
            }
        }
        m
    }
}

impl Workspace {
    fn manifest(&self) -> String {
        let members: Vec<String> = self
            .members
            .iter()
            .map(|m| format!("\"{}\"", m.name))
            .collect();
        format!(
            "# Stand-alone: not a member of the repository's workspace.\n[workspace]\nresolver = \"3\"\nmembers = [{}]\n\n\
             [profile.release]\nopt-level = {}\ndebug = false\nincremental = false\n",
            members.join(", "),
            self.opt_level
        )
    }

    /// Writes the workspace and builds member `bin` (release profile; for a library member
    /// the returned path names no binary).
    pub fn build(&self, bin: &str) -> Result<Built, String> {
        write_file(&self.dir.join("Cargo.toml"), self.manifest().as_bytes())?;
        for member in &self.members {
            let dir = self.dir.join(&member.name);
            write_file(&dir.join("Cargo.toml"), member.manifest().as_bytes())?;
            let (file, root) = match &member.root {
                Root::Bin(source) => ("main.rs", source),
                Root::Lib(source) => ("lib.rs", source),
            };
            write_file(&dir.join("src").join(file), root.as_bytes())?;
            for (file, contents) in &member.files {
                write_file(&dir.join("src").join(file), contents.as_bytes())?;
            }
        }
        let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
        let started = Instant::now();
        let out = Command::new(cargo)
            .args(["build", "--release", "--quiet", "--offline", "-p", bin])
            .arg("--manifest-path")
            .arg(self.dir.join("Cargo.toml"))
            .arg("--target-dir")
            .arg(self.dir.join("target"))
            // The outer build's flags (coverage, another target) are not this workspace's.
            .env_remove("RUSTFLAGS")
            .env_remove("CARGO_ENCODED_RUSTFLAGS")
            .env_remove("CARGO_BUILD_TARGET")
            .output()
            .map_err(|e| format!("cannot run cargo: {e}"))?;
        let seconds = started.elapsed().as_secs_f64();
        if !out.status.success() {
            return Err(format!(
                "building {} failed:\n{}",
                self.dir.display(),
                String::from_utf8_lossy(&out.stderr)
            ));
        }
        Ok(Built {
            binary: self.dir.join("target/release").join(bin),
            seconds,
        })
    }
}
