//! What a user reads when a scene file is refused: one line, `file:line:column: `field`: ` and
//! then a sentence naming the value and the rule in the file's units (mm, Hz, %, ms). One or
//! more whole-message checks per section of the file (substrate, limits, regions and their
//! textures, lines), each run through the same path host-sim takes (`load_for_board`).
//! Expected messages are written out by hand.

use saw_core::burst::BurstTimer;
use saw_core::scene_file::load_for_board;

/// A 90 MHz 32-bit burst timer with a 5 kHz top f_b (the F446's TIM2).
const TIMER: BurstTimer = BurstTimer {
    clock_hz: 90_000_000,
    counter_bits: 32,
    max_burst_hz: 5_000,
};

/// A 180 MHz 16-bit burst timer (no board's: a 16-bit counter on a 180 MHz bus): its lowest f_b
/// is 42 mHz.
const T16: BurstTimer = BurstTimer {
    clock_hz: 180_000_000,
    counter_bits: 16,
    max_burst_hz: 5_000,
};

/// The refusal of `text` (named `file`) on [`TIMER`] sampled every `period_us`, as displayed.
fn refusal(file: &str, text: &str, period_us: u32) -> String {
    refusal_on(TIMER, file, text, period_us)
}

fn refusal_on(timer: BurstTimer, file: &str, text: &str, period_us: u32) -> String {
    let e = load_for_board(file, text, timer, period_us).expect_err("the file must be refused");
    let shown = e.to_string();
    assert!(!shown.contains('\n'), "{shown}");
    shown
}

#[test]
fn substrate_calibration_refusal_reads_as_a_sentence() {
    let text = "[substrate]\nlength_mm = 63\ncode_at_start = 3000\ncode_at_end = 100\n\n\
                [[region]]\nkind = \"off\"\n";
    assert_eq!(
        refusal("cal.toml", text, 100),
        "cal.toml:4:15: `substrate.code_at_end`: code_at_end 100 must be above code_at_start 3000"
    );
}

/// The stale limit is checked against the board's sample period: 1 ms is under two periods of
/// a 1 kHz board.
#[test]
fn limits_refusal_reads_as_a_sentence() {
    let text = "[limits]\nstale_after_ms = 1\n\n[[region]]\nkind = \"off\"\n";
    assert_eq!(
        refusal("limits.toml", text, 1_000),
        "limits.toml:2:18: `limits.stale_after_ms`: stale limit 1 ms must be at least two sample \
         periods (2 ms) and at most 1000 ms"
    );
}

#[test]
fn region_layout_refusals_read_as_sentences() {
    let unsorted = "[[region]]\nkind = \"off\"\nuntil_mm = 30\n\n\
                    [[region]]\nkind = \"off\"\nuntil_mm = 20\n\n\
                    [[region]]\nkind = \"off\"\n";
    assert_eq!(
        refusal("regions.toml", unsorted, 100),
        "regions.toml:7:12: `region[1].until_mm`: region 1 ends at 20 mm, not after region 0 \
         (30 mm)"
    );
    let at_end = "[[region]]\nkind = \"off\"\nuntil_mm = 63\n\n[[region]]\nkind = \"off\"\n";
    assert_eq!(
        refusal("end.toml", at_end, 100),
        "end.toml:3:12: `region[0].until_mm`: region 0 ends at 63 mm, not strictly between 0 mm \
         and the substrate's end at 63 mm"
    );
    let narrow = "hysteresis_mm = 0.5\n\n\
                  [[region]]\nkind = \"off\"\nuntil_mm = 20\n\n\
                  [[region]]\nkind = \"off\"\nuntil_mm = 20.6\n\n\
                  [[region]]\nkind = \"off\"\n";
    assert_eq!(
        refusal("narrow.toml", narrow, 100),
        "narrow.toml:9:12: `region[1].until_mm`: region 1 is 0.6 mm wide, narrower than twice the \
         hysteresis (1 mm)"
    );
}

#[test]
fn texture_refusals_read_as_sentences() {
    let above = "[[region]]\nkind = \"constant\"\nuntil_mm = 20\nf_b_hz = 80\n\n\
                 [[region]]\nkind = \"constant\"\nf_b_hz = 9000\n";
    assert_eq!(
        refusal("f_b.toml", above, 100),
        "f_b.toml:8:10: `region[1].f_b_hz`: f_b 9000 Hz is above this board's limit of 5000 Hz"
    );
    let below = "[[region]]\nkind = \"constant\"\nf_b_hz = 0.041\n";
    assert_eq!(
        refusal_on(T16, "low.toml", below, 100),
        "low.toml:3:10: `region[0].f_b_hz`: f_b 0.041 Hz is below the lowest the burst timer \
         reaches, 0.042 Hz"
    );
    let wide = "[[region]]\nkind = \"grating\"\nridge_mm = 40\ngroove_mm = 40\n";
    assert_eq!(
        refusal("grating.toml", wide, 100),
        "grating.toml:3:12: `region[0].ridge_mm`: wavelength 80 mm must be above 0 mm and at most \
         the substrate's length, 63 mm"
    );
}

#[test]
fn lines_refusals_read_as_sentences() {
    let unsorted = "[[region]]\nkind = \"off\"\n\n[lines]\npositions_mm = [30, 20]\n";
    assert_eq!(
        refusal("lines.toml", unsorted, 100),
        "lines.toml:5:21: `lines.positions_mm[1]`: line 1 at 20 mm must be after line 0 (30 mm)"
    );
    let outside = "[[region]]\nkind = \"off\"\n\n[lines]\npositions_mm = [30, 70]\n";
    assert_eq!(
        refusal("lines.toml", outside, 100),
        "lines.toml:5:21: `lines.positions_mm[1]`: line 1 at 70 mm must be strictly between 0 mm \
         and the substrate's end at 63 mm"
    );
    let long = "[[region]]\nkind = \"off\"\n\n[lines]\npositions_mm = [30]\npulse_ms = 60\n";
    assert_eq!(
        refusal("pulse.toml", long, 100),
        "pulse.toml:6:12: `lines.pulse_ms`: line pulse 60 ms must be above 0 ms and at most the \
         on-time cap of 50 ms"
    );
}

/// A number out of its range names its unit, taken from the field's name, on the value and on
/// both ends of the range; a value that is no number at all (TOML's `nan`, `inf`) says so.
#[test]
fn range_refusals_name_the_unit() {
    let cases = [
        (
            "[[region]]\nkind = \"constant\"\nf_b_hz = 50\nduty_percent = 120\n",
            "duty.toml:4:16: `region[0].duty_percent`: 120 % is outside the allowed 0.1 % to 100 %",
        ),
        (
            "[[region]]\nkind = \"grating\"\nwavelength_mm = -1\n",
            "neg.toml:3:17: `region[0].wavelength_mm`: -1 mm is outside the allowed 0.001 mm to \
             63 mm",
        ),
        (
            "[[region]]\nkind = \"grating\"\nwavelength_mm = 1\nrender = \"velocity\"\n\
             min_speed_mm_s = 5000\n",
            "speed.toml:5:18: `region[0].min_speed_mm_s`: 5000 mm/s is outside the allowed 0 mm/s \
             to 1000 mm/s",
        ),
        (
            "[limits]\nmax_on_time_ms = nan\n\n[[region]]\nkind = \"off\"\n",
            "nan.toml:2:18: `limits.max_on_time_ms`: NaN is not a number; it must be from 0.001 ms \
             to 1000 ms",
        ),
        (
            "[[region]]\nkind = \"material\"\ne_object_pa = 2e9\nnu_object = 0.3\n\
             e_skin_pa = 1e6\nnu_skin = 0.5\nsigma_um = 0\n",
            "sigma.toml:7:12: `region[0].sigma_um`: 0 µm is outside the allowed 0.001 µm to \
             10000 µm",
        ),
        (
            "[[region]]\nkind = \"material\"\ndelta_mu = inf\n",
            "mu.toml:3:12: `region[0].delta_mu`: inf is not a number; it must be from 0 to 100",
        ),
    ];
    for (text, expected) in cases {
        let file = expected.split(':').next().unwrap();
        assert_eq!(refusal(file, text, 100), expected);
    }
}

/// The board's checks (the controller's dry run) point at the value they refuse, as the
/// reader's do: line and column of the value, the field with its region (issue #33).
#[test]
fn board_refusals_point_at_the_value() {
    let cases = [
        (
            "[limits]\nmax_duty_percent = 30\n\n[[region]]\nkind = \"constant\"\nf_b_hz = 80\n\
             duty_percent = 40\n",
            "duty.toml:7:16: `region[0].duty_percent`: duty 40 % is above the carrier's cap of 30 %",
        ),
        (
            "[limits]\nmax_level_percent = 50\n\n[[region]]\nkind = \"random\"\nf_b_hz = 80\n\
             amplitude_percent = 80\n",
            "level.toml:7:21: `region[0].amplitude_percent`: amplitude 80 % is above the level cap \
             of 50 % (limits.max_level_percent)",
        ),
        // The last region, too narrow, starts at the `until_mm` before it.
        (
            "hysteresis_mm = 0.5\n[[region]]\nkind = \"off\"\nuntil_mm = 62.5\n[[region]]\n\
             kind = \"off\"\n",
            "narrow.toml:4:12: `region[0].until_mm`: region 1 is 0.5 mm wide, narrower than twice \
             the hysteresis (1 mm)",
        ),
        (
            "[substrate]\nlength_mm = 63\ncode_at_start = 100\ncode_at_end = 60000\n\n\
             [[region]]\nkind = \"off\"\n",
            "rail.toml:3:17: `substrate.code_at_start`: code_at_start 100 is inside the low rail \
             band (at or below 655)",
        ),
    ];
    for (text, expected) in cases {
        let file = expected.split(':').next().unwrap();
        assert_eq!(refusal(file, text, 100), expected);
    }
}

/// A key no table takes: the nearest key when it is a slip (edit distance, or the unit left
/// off), else a short list — the table's keys, or the region's kind's — never all 25 region keys.
/// A value none of a choice's: the same.
#[test]
fn unknown_keys_and_values_name_the_nearest_or_a_short_list() {
    let cases = [
        (
            "[[region]]\nkind = \"constant\"\nf_b_hx = 80\n",
            "typo.toml:3:1: `region[0].f_b_hx`: unknown key `f_b_hx`: did you mean `f_b_hz`?",
        ),
        (
            "hysteresis = 0.1\n\n[[region]]\nkind = \"off\"\n",
            "unit.toml:1:1: `hysteresis`: unknown key `hysteresis`: did you mean `hysteresis_mm`?",
        ),
        (
            "[limits]\nmax_duty = 30\n\n[[region]]\nkind = \"off\"\n",
            "cap.toml:2:1: `limits.max_duty`: unknown key `max_duty`: did you mean `max_duty_percent`?",
        ),
        (
            "[[region]]\nkind = \"constant\"\nf_b_hz = 80\ncolour = \"red\"\n",
            "colour.toml:4:1: `region[0].colour`: unknown key `colour`: a `constant` region takes `kind`, \
             `until_mm`, `f_b_hz` and `duty_percent` (docs/scenes.md lists every kind's keys)",
        ),
        (
            "[[region]]\nkind = \"off\"\ncolour = \"red\"\n",
            "off.toml:3:1: `region[0].colour`: unknown key `colour`: an `off` region takes `kind` and \
             `until_mm` (docs/scenes.md lists every kind's keys)",
        ),
        // A 2D scene without `[sensor]` is read as 1D: its tables are named as 2D ones.
        (
            "[screen]\nsize_mm = [95, 54]\n\n[[window]]\nrect_mm = [5, 5, 30, 49]\nkind = \"off\"\n",
            "nosensor.toml:1:2: `screen`: unknown key `screen`: `screen` is a 2D scene's table, and a \
             file without `[sensor]` is a 1D scene for the rheostat: add `[sensor] kind = \"4-wire\"` \
             for the touch overlay",
        ),
        (
            "[limits]\nzzz = 30\n\n[[region]]\nkind = \"off\"\n",
            "limits.toml:2:1: `limits.zzz`: unknown key `zzz`: [limits] takes `max_duty_percent`, \
             `max_level_percent`, `max_on_time_ms` and `stale_after_ms`",
        ),
        // A key in [lines] after a region is judged by the lines' keys, not the region's.
        (
            "[[region]]\nkind = \"constant\"\nf_b_hz = 80\n\n[lines]\npositions_mm = [10]\n\
             duty = 1\n",
            "lines.toml:7:1: `lines.duty`: unknown key `duty`: [lines] takes `positions_mm`, `pulse_ms`, \
             `envelope`, `amplitude_percent` and `rearm_mm`",
        ),
        // A table no file takes: named by its name, its comment left off.
        (
            "[limits]\nmax_duty_percent = 30\n\n[[regin]]  # [[region]]\nkind = \"off\"\n",
            "table.toml:4:3: `regin`: unknown key `regin`: did you mean `region`?",
        ),
        // Comments do not open tables; the second region's key is the second region's.
        (
            "[[region]] # [limits]\nkind = \"off\"\nuntil_mm = 10\n[[region]]\nkind = \"off\"\n\
             foo = 1\n",
            "second.toml:6:1: `region[1].foo`: unknown key `foo`: an `off` region takes `kind` and \
             `until_mm` (docs/scenes.md lists every kind's keys)",
        ),
        (
            "[[region]]\nkind = \"grating\"\nwavelength_mm = 1\nrender = \"hybird\"\n",
            "render.toml:4:10: `region[0].render`: unknown value `hybird`: did you mean `hybrid`?",
        ),
        (
            "[[region]]\nkind = \"grating\"\nwavelength_mm = 1\nrender = \"phase\"\n",
            "phase.toml:4:10: `region[0].render`: unknown value `phase`: it must be `position`, `hybrid` or \
             `velocity`",
        ),
    ];
    for (text, expected) in cases {
        let file = expected.split(':').next().unwrap();
        assert_eq!(refusal(file, text, 100), expected);
    }
}
