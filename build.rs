//! Build script: tells the binary which Cargo profile built it.
//!
//! `annotrace bench` prints the profile beside every figure, and `debug_assertions` can only tell a
//! debug build from an optimised one: the `dist` profile (release with LTO across crates, see
//! Cargo.toml) would read as `release`. Cargo gives a build script its output folder,
//! `<target>/<profile folder>/build/<package>-<hash>/out`, and the profile folder is the profile's name
//! (`debug` for dev and test, `release` for release and bench, `dist`), so that name is passed on as
//! `ANNOTRACE_PROFILE`. Nothing else is generated.

use std::path::Path;

fn main() {
    println!("cargo::rerun-if-changed=build.rs");
    let out = std::env::var("OUT_DIR").unwrap_or_default();
    let profile = Path::new(&out)
        .ancestors()
        .nth(3)
        .and_then(|folder| folder.file_name())
        .and_then(|name| name.to_str())
        .filter(|name| !name.is_empty())
        .unwrap_or("unknown");
    println!("cargo::rustc-env=ANNOTRACE_PROFILE={profile}");
}
