//! Copies the selected board's `memory.x` (from `../boards/<board>/memory.x`) into OUT_DIR and puts
//! OUT_DIR on the linker search path, so cortex-m-rt's `link.x` picks it up.
use std::{env, fs, path::PathBuf};

fn main() {
    let f446 = env::var_os("CARGO_FEATURE_NUCLEO_F446RE").is_some();
    let g474 = env::var_os("CARGO_FEATURE_NUCLEO_G474RE").is_some();
    let board = match (f446, g474) {
        (true, false) => "nucleo-f446re",
        (false, true) => "nucleo-g474re",
        (true, true) => panic!("select exactly one board feature: use --no-default-features --features nucleo-g474re for the G474"),
        (false, false) => panic!("select a board feature: nucleo-f446re (default) or nucleo-g474re"),
    };
    let manifest = PathBuf::from(env::var("CARGO_MANIFEST_DIR").unwrap());
    let src = manifest.join("..").join("boards").join(board).join("memory.x");
    let out = PathBuf::from(env::var("OUT_DIR").unwrap());
    fs::copy(&src, out.join("memory.x")).unwrap_or_else(|e| panic!("copy {}: {e}", src.display()));
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={}", src.display());
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rustc-env=SAW_BOARD={board}");
}
