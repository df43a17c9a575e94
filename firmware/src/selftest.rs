//! Boot self-test of the delayed one-pulse (feature `selftest-delayed-pulse`, never in a real
//! image; `SELFTEST=1 scripts/build-firmware.sh` builds `firmware/target/<board>-selftest.elf`).
//! Until the core's hybrid renderer emits delayed pulses (#17), nothing in a release image
//! fires one; this fires one through the port's own `BurstOutput::apply`, with the RF arm still
//! low, before the control loop starts, so the board model (`board-model delayed-pulse`) can
//! measure its rise and on-time against the settings this logs.
use defmt::{info, unwrap};
use saw_core::burst::BurstTimer;
use saw_core::gate::{BurstOutput, Envelope, GateAction};

use crate::rf::BurstGate;

/// The test pulse: rise this long after CEN, µs (inside a sample period, as the renderer's)...
const DELAY_US: u64 = 37;
/// ...and high this long, µs.
const ON_US: u64 = 250;

/// Fires the delayed pulse, waits for the hardware to end it, then asks for the same pulse with
/// a triangular envelope, which the port must refuse (line off, counted), and leaves the gate off.
pub async fn delayed_pulse(burst: &mut BurstGate, timer: &BurstTimer) {
    let clk = timer.clock_hz as u64;
    let s = unwrap!(timer.delayed_pulse(DELAY_US * clk / 1_000_000, ON_US * clk / 1_000_000));
    info!(
        "self-test: delayed pulse psc {=u16} arr {=u32} ccr {=u32}: rise {=u64} clocks after CEN, high {=u64} clocks",
        s.psc,
        s.arr,
        s.ccr,
        s.pulse_delay_clocks(),
        s.on_clocks()
    );
    burst.apply(GateAction::Pulse(s));
    embassy_time::Timer::after_micros(DELAY_US + ON_US + 100).await;
    info!(
        "self-test: delayed pulse over, counter {}",
        if burst.counting() { "still running" } else { "stopped" }
    );
    burst.set_envelope(Envelope::Triangular);
    burst.apply(GateAction::Pulse(s));
    burst.set_envelope(Envelope::Rectangular);
    info!(
        "self-test: delayed triangle -> line {}, refused {=u32}",
        burst.line(),
        burst.stats.delayed_triangles_refused
    );
    burst.off();
}
