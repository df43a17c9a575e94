//! Copies the selected board's `memory.x` (from `../boards/<board>/memory.x`) into OUT_DIR and puts
//! OUT_DIR on the linker search path, so cortex-m-rt's `link.x` picks it up; and embeds the scene
//! named by `SAW_SCENE` (a scene file, relative to `firmware/` or the repository), read and checked
//! against this board on the host exactly as host-sim reads it: a bad file stops the build with
//! its `file:line:col: field: sentence`.
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
    embed_scene(board, &manifest, &out);
}

fn embed_scene(board: &str, manifest: &std::path::Path, out: &std::path::Path) {
    println!("cargo:rerun-if-env-changed=SAW_SCENE");
    let code = match env::var_os("SAW_SCENE").filter(|v| !v.is_empty()) {
        None => "pub const EMBEDDED_SCENE: Option<&[u8]> = None;\npub const EMBEDDED_SCENE_FILE: &str = \"\";\n".to_string(),
        Some(name) => {
            let given = PathBuf::from(&name);
            let path = [manifest.join(&given), manifest.join("..").join(&given), given.clone()]
                .into_iter()
                .find(|p| p.is_file())
                .unwrap_or_else(|| fail(&format!("SAW_SCENE={}: no such file (relative to firmware/ or the repository)", given.display())));
            println!("cargo:rerun-if-changed={}", path.display());
            let text = fs::read_to_string(&path).unwrap_or_else(|e| fail(&format!("SAW_SCENE={}: {e}", given.display())));
            let b = saw_boards::by_name(board).unwrap_or_else(|| fail(&format!("unknown board {board}")));
            let timer = saw_core::burst::BurstTimer {
                clock_hz: b.burst_timer_clk_hz,
                counter_bits: b.burst_timer_bits,
                max_burst_hz: b.max_burst_hz,
            };
            let config = saw_core::scene_file::load_for_board(
                &given.display().to_string(),
                &text,
                timer,
                1_000_000 / b.sample_rate_hz,
            )
            .unwrap_or_else(|e| fail(&format!("SAW_SCENE: {e}")));
            let bytes = postcard::to_allocvec(&config).unwrap_or_else(|e| fail(&format!("SAW_SCENE: {e}")));
            format!(
                "pub const EMBEDDED_SCENE: Option<&[u8]> = Some(&{bytes:?});\npub const EMBEDDED_SCENE_FILE: &str = {:?};\n",
                given.display().to_string()
            )
        }
    };
    fs::write(out.join("scene.rs"), code).unwrap_or_else(|e| fail(&format!("scene.rs: {e}")));
}

/// Stops the build with one line (cargo shows a build script's stderr when it fails).
fn fail(message: &str) -> ! {
    eprintln!("error: {message}");
    std::process::exit(1)
}
