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
    if env::var_os("CARGO_FEATURE_TOUCH_2D").is_some() {
        touch_plan(board, &manifest, &out);
    }
}

/// The 2D image (feature `touch-2d`, `src/touch2d.rs`): the plate schedule as timer ticks, the
/// ADC channel each phase converts, a calibration from the design's plate figures, and the 2D
/// scene (`SAW_SCENE_2D`, default `scenes/2d-fig12.toml`), checked against this board's frame
/// period exactly as host-sim checks it. Written to `OUT_DIR/touch2d.rs`.
///
/// The frame: the core's `Schedule` (`saw_core::touch::plates`, the default plates and this
/// board's acquisition, `saw_boards::touch::touch_adc`), each phase followed by
/// [`MARGIN_NS`] before the next switches (the software trigger starts up to an interrupt's
/// latency late; the margin keeps the last conversion of a phase before the next phase's pin
/// switch), the frame rounded up to whole µs. Every event is a tick of TIM3 at its kernel clock.
fn touch_plan(board: &str, manifest: &std::path::Path, out: &std::path::Path) {
    use saw_core::touch::plates::{AdcTiming, PlateRc, Schedule};
    /// After each phase's conversions, before the next pin switch, ns: an interrupt held off
    /// longer than this (defmt-rtt's critical section while it encodes a line) pushes a phase's
    /// last conversions past the next switch, and the interrupt then drops the frame (its DMA
    /// count disagrees); 2 µs saw 0.3–1.6 µs of such delay on the board model's optimistic CPU.
    const MARGIN_NS: u64 = 4_000;
    println!("cargo:rerun-if-env-changed=SAW_SCENE_2D");
    let b = saw_boards::by_name(board).unwrap_or_else(|| fail(&format!("unknown board {board}")));
    let pins = saw_boards::touch::touch_pins(b).unwrap_or_else(|| fail(&format!("{board}: no touch pins")));
    // The board's acquisition as saw-boards states it (host-sim's `sim2d::adc_timing` maps the
    // same fields): a discarded conversion after each switch, then the summed ones.
    let t = saw_boards::touch::touch_adc(b);
    let adc = AdcTiming {
        conversion_ns: t.conversion_ns,
        conversions_position: t.conversions_position,
        conversions_pressure: t.conversions_pressure,
        discard: t.discard,
    };
    let max = saw_boards::touch::MAX_RANKS;
    if t.ranks(true) > max || t.ranks(false) > max {
        fail("a touch phase needs more ranks than one regular sequence has (16)");
    }
    let rc = PlateRc::DEFAULT;
    let sched = Schedule::new(&rc, &adc).unwrap_or_else(|e| fail(&format!("touch schedule: {e}")));
    let f_hz = b.adc.trigger_timer_clk_hz as u64;
    if f_hz % 1_000_000 != 0 {
        fail("the trigger timer's clock is not a whole number of MHz");
    }
    let tick = |ns: u64| (ns * f_hz).div_ceil(1_000_000_000);
    // Events: (tick, kind, phase): kind 0 = switch the pins (and the channel) at that tick of
    // the frame, 1 = start the conversions that many ticks after the switch's pin writes, 2 =
    // both (Z2: same drive as Z1, so no settling).
    let mut events: Vec<(u64, u8, u8)> = Vec::new();
    let mut t_ns = MARGIN_NS;
    for (k, slot) in sched.slots.iter().enumerate() {
        if slot.settle_ns == 0 {
            events.push((tick(t_ns), 2, k as u8));
        } else {
            events.push((tick(t_ns), 0, k as u8));
            // A start's tick is counted from the switch as it happened (the interrupt reads CNT
            // after the pin writes): the settling is a floor whatever the switch's latency.
            // The planted defect `plant-touch-no-settle` (never in a real image): the start after
            // a quarter of the settling; the board model's plate-timing check must fail on it.
            let settle = if env::var_os("CARGO_FEATURE_PLANT_TOUCH_NO_SETTLE").is_some() { slot.settle_ns / 4 } else { slot.settle_ns };
            events.push((tick(settle) + 1, 1, k as u8));
        }
        t_ns += slot.settle_ns + slot.convert_ns + MARGIN_NS;
    }
    // The last phase's margin ends the frame; the next frame's first switch is at MARGIN_NS.
    let frame_us = (t_ns - MARGIN_NS).div_ceil(1_000);
    let frame_ticks = frame_us * f_hz / 1_000_000;
    if frame_ticks > 65_536 {
        fail("a touch frame is longer than TIM3's 16 bits at its kernel clock");
    }
    // Frame delivery: at tick 0 of the next frame (after the last phase's margin).
    let channel = |k: usize| {
        let t = sched.slots[k].phase.sensed();
        use saw_core::touch::plates::Terminal::*;
        match t {
            XPlus => pins.x_plus.channel,
            XMinus => pins.x_minus.channel,
            YPlus => pins.y_plus.channel,
            YMinus => pins.y_minus.channel,
        }
    };
    // Calibration from the design's figures (docs/touch.md, "Pressure"): a position phase reads
    // (R_drive + R_plate·u) / (R_plate + 2·R_drive) of full scale; three touches at (0.1, 0.1),
    // (0.9, 0.5), (0.5, 0.9) of the plate, as host-sim calibrates its overlay.
    let name = env::var("SAW_SCENE_2D").ok().filter(|v| !v.is_empty()).unwrap_or_else(|| "scenes/2d-fig12.toml".into());
    let given = PathBuf::from(&name);
    let path = [manifest.join(&given), manifest.join("..").join(&given), given.clone()]
        .into_iter()
        .find(|p| p.is_file())
        .unwrap_or_else(|| fail(&format!("SAW_SCENE_2D={}: no such file (relative to firmware/ or the repository)", given.display())));
    println!("cargo:rerun-if-changed={}", path.display());
    let text = fs::read_to_string(&path).unwrap_or_else(|e| fail(&format!("SAW_SCENE_2D={}: {e}", given.display())));
    let file = given.display().to_string();
    let (w_um, h_um) = saw_core::scene_file::plate_um_of(&file, &text).unwrap_or_else(|e| fail(&format!("SAW_SCENE_2D: {e}")));
    let code = |r_plate: u32, u: f64| {
        let (rp, rd) = (r_plate as f64, rc.r_drive_ohm as f64);
        (65_536.0 * (rd + rp * u) / (rp + 2.0 * rd)).round() as u16
    };
    let cal: Vec<String> = [(0.1, 0.1), (0.9, 0.5), (0.5, 0.9)]
        .iter()
        .map(|&(x, y)| {
            format!(
                "CalPoint {{ x_code: {}, y_code: {}, x_um: {}, y_um: {} }}",
                code(rc.r_x_plate_ohm, x),
                code(rc.r_y_plate_ohm, y),
                (x * w_um as f64).round() as i32,
                (y * h_um as f64).round() as i32
            )
        })
        .collect();
    let timer = saw_core::burst::BurstTimer {
        clock_hz: b.burst_timer_clk_hz,
        counter_bits: b.burst_timer_bits,
        max_burst_hz: b.max_burst_hz,
    };
    let config = saw_core::scene_file::load_2d_for_board(&file, &text, timer, frame_us as u32)
        .unwrap_or_else(|e| fail(&format!("SAW_SCENE_2D: {e}")));
    let bytes = postcard::to_allocvec(&config).unwrap_or_else(|e| fail(&format!("SAW_SCENE_2D: {e}")));
    let ranks: Vec<u8> = sched.slots.iter().map(|s| t.ranks(s.phase.is_position()) as u8).collect();
    let discard = t.discard;
    let ev: Vec<String> = events.iter().map(|(t, k, p)| format!("Event {{ tick: {t}, kind: {k}, slot: {p} }}")).collect();
    let code = format!(
        "/// TIM3 ticks per µs (its kernel clock).\npub const TICKS_PER_US: u32 = {};\n\
         /// One frame, µs (the controller's reading period) and TIM3 ticks.\npub const FRAME_US: u32 = {frame_us};\npub const FRAME_TICKS: u32 = {frame_ticks};\n\
         /// After each phase's conversions, before the next switch, ns.\npub const MARGIN_NS: u32 = {MARGIN_NS};\n\
         /// The frame's events in time order.\npub const EVENTS: [Event; {}] = [{}];\n\
         /// The ADC channel each slot converts (X, Y, Z1, Z2).\npub const CHANNELS: [u8; 4] = [{}, {}, {}, {}];\n\
         /// Each slot's regular sequence: ranks (one DMA word each), the first DISCARD thrown away.\npub const RANKS: [u8; 4] = {ranks:?};\npub const DISCARD: u8 = {discard};\n\
         /// Three touches from the design's plate figures.\npub const CAL: [CalPoint; 3] = [{}];\n\
         /// The 2D scene, postcard.\npub const SCENE_2D: &[u8] = &{bytes:?};\npub const SCENE_2D_FILE: &str = {file:?};\n",
        f_hz / 1_000_000,
        events.len(),
        ev.join(", "),
        channel(0),
        channel(1),
        channel(2),
        channel(3),
        cal.join(", "),
    );
    fs::write(out.join("touch2d.rs"), code).unwrap_or_else(|e| fail(&format!("touch2d.rs: {e}")));
    // The overlay's touch area for the link (`src/link2d.rs`, `Session::new_2d`): the built-in
    // scene's plate, which the calibration above maps the codes onto.
    let plate = format!("/// The overlay's touch area, µm (the built-in scene's plate).\npub const PLATE_UM: (u32, u32) = ({w_um}, {h_um});\n");
    fs::write(out.join("plate2d.rs"), plate).unwrap_or_else(|e| fail(&format!("plate2d.rs: {e}")));
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
