//! Links against the repository root's `memory.x` (mps2-an386: 4 MiB code at 0x0, 4 MiB RAM at
//! 0x2000_0000) and tracks the golden vectors embedded from `$GOLDEN_DIR`.
use std::{env, path::PathBuf};

fn main() {
    let manifest = PathBuf::from(env::var("CARGO_MANIFEST_DIR").unwrap());
    let root = manifest.join("..").join("..").canonicalize().unwrap();
    println!("cargo:rustc-link-search={}", root.display());
    println!("cargo:rerun-if-changed={}", root.join("memory.x").display());
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=GOLDEN_DIR");
    let golden = env::var("GOLDEN_DIR")
        .expect("set GOLDEN_DIR to the directory holding golden.bin (scripts/emu.sh does)");
    println!("cargo:rerun-if-changed={golden}/golden.bin");
    println!("cargo:rerun-if-changed={golden}/golden2d.bin");
}
