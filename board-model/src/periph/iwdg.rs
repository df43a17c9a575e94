//! Independent watchdog (IWDG, one per chip): the key register, the write-protected prescaler,
//! reload and (G4) window registers with their LSI-domain update delay, the 12-bit down-counter
//! clocked by the LSI in virtual time, and the chip reset at the end of count
//! (RM0390's IWDG chapter for the STM32F446, cited §19 here from memory — a review could not
//! confirm the number; RM0440 Rev 4 §42 for the STM32G474, confirmed).
//!
//! What embassy-stm32 0.6 (`wdg::IndependentWatchdog`) does with it: `new` writes KR = 0x5555,
//! PR, RLR (without waiting for PVU/RVU), `unleash` writes KR = 0xCCCC, `pet` writes
//! KR = 0xAAAA. Nothing reads it.
//!
//! Timing model (all exact in master ticks):
//! - The LSI runs at 32 kHz (`LSI_HZ`, overridable with `set_lsi_hz`); starting the IWDG forces
//!   it on (RM0390 §19.3.1, RM0440 §42.3.1), so the counter never depends on RCC_CSR.LSION.
//! - The counter decrements once every 4·2^PR LSI periods (PR = 7 divides by 256 like PR = 6,
//!   RM0390 §19.4.2 / RM0440 §42.4.2).
//! - Start (0xCCCC) loads 0xFFF, "the reset value", not RLR (RM0390 §19.3.1, RM0440 §42.3.1
//!   "the counter starts counting down from the reset value of 0xFFF"). A reload (0xAAAA) loads
//!   RLR. From a load of value N at time t the reset happens at t + (N + 1) counter periods: the
//!   manuals' timeout tables (RM0390 table 107: RL = 0 gives one period, RL = 0xFFF gives 4096)
//!   count the step from 0 to the reset as a period. The manuals add that the real timeout is
//!   only known to one LSI period (APB/LSI clock phase); the model has no such jitter.
//! - PR/RLR/WINR writes reach the LSI domain after `UPDATE_LSI_CYCLES` LSI periods, during
//!   which SR.PVU/RVU/WVU read 1 (RM0390 §19.4.4: "takes up to 5 RC 40 kHz cycles"; the model
//!   uses 5 periods of its own LSI for both chips — RM0440's count is not certain to the author).
//!   Until then the counter keeps using the old value.

use super::{merge, Peripheral, ResetCause, Signals, Time, Unmodelled, TICKS_PER_S};
use std::any::Any;

/// LSI frequency the counter runs on (both chips' nominal LSI).
pub const LSI_HZ: u64 = 32_000;

/// LSI periods a PR/RLR/WINR write takes to reach the counter's (VDD/LSI) domain.
pub const UPDATE_LSI_CYCLES: u64 = 5;

/// Key values (RM0390 §19.4.1 / RM0440 §42.4.1).
pub const KEY_UNLOCK: u32 = 0x5555;
pub const KEY_RELOAD: u32 = 0xAAAA;
pub const KEY_START: u32 = 0xCCCC;

const OFF_KR: u32 = 0x00;
const OFF_PR: u32 = 0x04;
const OFF_RLR: u32 = 0x08;
const OFF_SR: u32 = 0x0C;
const OFF_WINR: u32 = 0x10;

/// Counter value loaded by the start key, and the reset value of RLR/WINR.
const COUNTER_MAX: u32 = 0xFFF;

/// A register write on its way to the LSI domain: lands at `at` with `value`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Pending {
    at: Time,
    value: u32,
}

/// The independent watchdog.
#[derive(Clone, Debug)]
pub struct Iwdg {
    has_winr: bool,
    lsi_hz: u64,
    /// Last values written over the bus (the base a half-word write merges into).
    pr: u32,
    rlr: u32,
    winr: u32,
    /// Values the counter uses (the LSI-domain copies).
    pr_eff: u32,
    rlr_eff: u32,
    winr_eff: u32,
    pr_pending: Option<Pending>,
    rlr_pending: Option<Pending>,
    winr_pending: Option<Pending>,
    /// KR = 0x5555 opened PR/RLR/WINR for writing; any other key closes them.
    unlocked: bool,
    running: bool,
    /// The counter held `count_at_base` at `base` (valid while running).
    base: Time,
    count_at_base: u32,
    /// Frozen by the debugger (DBGMCU DBG_IWDG_STOP while the core is halted) since this time.
    frozen_since: Option<Time>,
    /// The reset has been signalled; the chip reset will clear it.
    fired: bool,
    /// Writes to PR/RLR/WINR the hardware ignored because access was not unlocked.
    ignored_writes: u32,
}

impl Iwdg {
    /// `has_winr`: the G474's IWDG has the window register (RM0440 §42.4.6); the F446's does
    /// not.
    pub fn new(has_winr: bool) -> Self {
        Iwdg {
            has_winr,
            lsi_hz: LSI_HZ,
            pr: 0,
            rlr: COUNTER_MAX,
            winr: COUNTER_MAX,
            pr_eff: 0,
            rlr_eff: COUNTER_MAX,
            winr_eff: COUNTER_MAX,
            pr_pending: None,
            rlr_pending: None,
            winr_pending: None,
            unlocked: false,
            running: false,
            base: 0,
            count_at_base: COUNTER_MAX,
            frozen_since: None,
            fired: false,
            ignored_writes: 0,
        }
    }

    /// Use another LSI frequency (the real LSI is only specified to a range). It must divide
    /// the master clock (`ticks_per_cycle` rule). Intended before the watchdog starts.
    pub fn set_lsi_hz(&mut self, hz: u64) {
        assert!(
            hz > 0 && TICKS_PER_S.is_multiple_of(hz),
            "LSI {hz} Hz does not divide the master clock"
        );
        self.lsi_hz = hz;
    }

    /// Master ticks of one LSI period.
    pub fn lsi_period_ticks(&self) -> u64 {
        TICKS_PER_S / self.lsi_hz
    }

    /// Master ticks of one counter step for prescaler code `pr` (/4 · 2^pr, 7 = /256).
    pub fn counter_period_ticks(&self, pr: u32) -> u64 {
        let div = 4u64 << pr.min(6);
        div * self.lsi_period_ticks()
    }

    /// The DBGMCU freeze, applied by the board only while the core is halted by a debugger and
    /// DBG_IWDG_STOP is set (RM0390 §33.16.4, RM0440 §46.16.4). The counter keeps its value and
    /// its position within the current step.
    pub fn set_frozen(&mut self, now: Time, frozen: bool) {
        self.settle(now);
        match (frozen, self.frozen_since) {
            (true, None) => self.frozen_since = Some(now),
            (false, Some(since)) => {
                // The counter lost (now - since) of running time: its schedule moves by that.
                self.base += now.saturating_sub(since);
                self.frozen_since = None;
            }
            _ => {}
        }
    }

    /// Started (KR = 0xCCCC) and not yet reset.
    pub fn running(&self) -> bool {
        self.running
    }

    /// Frozen by the debugger hook.
    pub fn frozen(&self) -> bool {
        self.frozen_since.is_some()
    }

    /// Prescaler and reload values the counter currently uses (after the update delay).
    pub fn effective_pr_rlr(&self) -> (u32, u32) {
        (self.pr_eff, self.rlr_eff)
    }

    /// Writes the hardware ignored (PR/RLR/WINR while write access was locked).
    pub fn ignored_writes(&self) -> u32 {
        self.ignored_writes
    }

    /// The counter value at `now` (None if not running). Applies no pending update: call after
    /// the board advanced the model to `now`.
    pub fn counter(&self, now: Time) -> Option<u32> {
        if !self.running {
            return None;
        }
        let t = self.frozen_since.map_or(now, |f| f.min(now));
        let steps = t.saturating_sub(self.base) / self.counter_period_ticks(self.pr_eff);
        Some(
            self.count_at_base
                .saturating_sub(steps.min(u32::MAX as u64) as u32),
        )
    }

    /// When the counter will reset the chip if nobody reloads it, taking pending prescaler
    /// updates into account. None when stopped, frozen or already fired.
    pub fn reset_time(&self) -> Option<Time> {
        if !self.running || self.fired || self.frozen_since.is_some() {
            return None;
        }
        let mut base = self.base;
        let mut count = self.count_at_base;
        let mut period = self.counter_period_ticks(self.pr_eff);
        let mut reset_at = base + (count as u64 + 1) * period;
        if let Some(p) = self.pr_pending {
            if p.at < reset_at && p.value.min(6) != self.pr_eff.min(6) {
                // Same rebase as `apply_pr`: the counter keeps its value, the new period starts
                // at the update.
                let steps = (p.at.saturating_sub(base) / period) as u32;
                count = count.saturating_sub(steps);
                base = p.at;
                period = self.counter_period_ticks(p.value);
                reset_at = base + (count as u64 + 1) * period;
            }
        }
        Some(reset_at)
    }

    /// Apply every register update that has reached the LSI domain by `now`, in time order,
    /// but none that lands after the reset (the chip is reset by then).
    fn settle(&mut self, now: Time) {
        loop {
            let next = [
                self.pr_pending.map(|p| (p.at, 0)),
                self.rlr_pending.map(|p| (p.at, 1)),
                self.winr_pending.map(|p| (p.at, 2)),
            ]
            .into_iter()
            .flatten()
            .filter(|&(at, _)| at <= now)
            .min();
            let Some((at, which)) = next else { break };
            if let Some(r) = self.reset_time() {
                if r <= at {
                    break;
                }
            }
            match which {
                0 => {
                    let p = self.pr_pending.take().expect("pending PR");
                    self.apply_pr(p.at, p.value);
                }
                1 => self.rlr_eff = self.rlr_pending.take().expect("pending RLR").value,
                _ => self.winr_eff = self.winr_pending.take().expect("pending WINR").value,
            }
        }
    }

    /// The prescaler changes at `at`: the counter keeps the value it has then and counts on
    /// with the new period from `at`. What the hardware prescaler does with a partly counted
    /// step is not in the manuals; the partial step is dropped.
    fn apply_pr(&mut self, at: Time, pr: u32) {
        // Same division (rewriting the value, or 6 <-> 7): nothing changes for the counter.
        if self.running && pr.min(6) != self.pr_eff.min(6) {
            let t = self.frozen_since.map_or(at, |f| f.min(at));
            let steps = t.saturating_sub(self.base) / self.counter_period_ticks(self.pr_eff);
            self.count_at_base = self
                .count_at_base
                .saturating_sub(steps.min(u32::MAX as u64) as u32);
            self.base = t;
            if let Some(f) = self.frozen_since.as_mut() {
                // Frozen: the counter resumes from `base` when unfrozen; re-anchor the freeze.
                *f = t;
            }
        }
        self.pr_eff = pr;
    }

    /// Load `value` into the counter at `now`.
    fn load(&mut self, now: Time, value: u32) {
        self.count_at_base = value;
        self.base = now;
        if self.frozen_since.is_some() {
            self.frozen_since = Some(now);
        }
    }

    fn busy(p: &Option<Pending>, now: Time) -> bool {
        p.is_some_and(|p| p.at > now)
    }

    /// A write to PR/RLR/WINR: ignored while locked (RM0390 §19.3.4 "Register access
    /// protection"); a second write while the previous one is still on its way is not covered
    /// by the manuals ("can be updated only when PVU is reset"), so it is reported.
    #[allow(clippy::too_many_arguments)]
    fn protected_write(
        &mut self,
        now: Time,
        offset: u32,
        value: u32,
        mask: u32,
        field_mask: u32,
        reg: &str,
        flag: &str,
    ) -> Result<Option<u32>, Unmodelled> {
        if !self.unlocked {
            self.ignored_writes += 1;
            return Ok(None);
        }
        let (current, pending) = match offset {
            OFF_PR => (self.pr, &self.pr_pending),
            OFF_RLR => (self.rlr, &self.rlr_pending),
            _ => (self.winr, &self.winr_pending),
        };
        if Self::busy(pending, now) {
            return Err(Unmodelled::write(
                offset,
                value,
                format!("IWDG_{reg} written while SR.{flag} = 1 (previous update still in progress); the manual only allows updates with {flag} = 0"),
            ));
        }
        Ok(Some(merge(current, value, mask) & field_mask))
    }
}

impl Peripheral for Iwdg {
    fn name(&self) -> &'static str {
        "IWDG"
    }

    fn read(&mut self, now: Time, offset: u32, _out: &mut Signals) -> Result<u32, Unmodelled> {
        self.settle(now);
        match offset {
            // KR is write-only and reads 0 (RM0390 §19.4.1).
            OFF_KR => Ok(0),
            // PR/RLR/WINR read back the LSI (VDD) domain's copy: "Reading this register returns
            // the reload value from the VDD voltage domain. This value may not be up to date/valid
            // if a write operation to this register is ongoing" (RM0390 §19.4.3). The model
            // returns the old value until the update lands.
            OFF_PR => Ok(self.pr_eff),
            OFF_RLR => Ok(self.rlr_eff),
            OFF_SR => {
                let mut sr = 0;
                if Self::busy(&self.pr_pending, now) {
                    sr |= 1 << 0; // PVU
                }
                if Self::busy(&self.rlr_pending, now) {
                    sr |= 1 << 1; // RVU
                }
                if self.has_winr && Self::busy(&self.winr_pending, now) {
                    sr |= 1 << 2; // WVU (RM0440 §42.4.4)
                }
                Ok(sr)
            }
            OFF_WINR if self.has_winr => Ok(self.winr_eff),
            _ => Err(Unmodelled::read(
                offset,
                format!("IWDG register at offset {offset:#x} does not exist on this chip"),
            )),
        }
    }

    fn write(
        &mut self,
        now: Time,
        offset: u32,
        value: u32,
        mask: u32,
        out: &mut Signals,
    ) -> Result<(), Unmodelled> {
        self.settle(now);
        // RM0390 §19.4 / RM0440 §42.4: half-word or word access only.
        if mask & 0xFFFF != 0xFFFF {
            return Err(Unmodelled::write(
                offset,
                value,
                "IWDG byte write: the registers accept half-word or word accesses only",
            ));
        }
        match offset {
            OFF_KR => {
                let key = value & 0xFFFF;
                // Any key other than 0x5555 closes register access (RM0390 §19.3.4).
                self.unlocked = key == KEY_UNLOCK;
                match key {
                    KEY_START if !self.running => {
                        // RM0390 §19.3.1: starts counting down from 0xFFF.
                        self.running = true;
                        self.fired = false;
                        self.load(now, COUNTER_MAX);
                        out.replan = true;
                    }
                    KEY_RELOAD if self.running && !self.fired => {
                        let count = self.counter(now).unwrap_or(0);
                        if self.has_winr && count > self.winr_eff {
                            // RM0440 §42.3.5: a reload while the counter is above the window
                            // resets the chip.
                            self.fired = true;
                            out.reset = Some(ResetCause::IndependentWatchdog);
                        } else {
                            self.load(now, self.rlr_eff);
                        }
                        out.replan = true;
                    }
                    // Reload before start: the manuals only describe reloading a running
                    // counter; the start still loads 0xFFF. Start while running: no effect.
                    _ => {}
                }
                Ok(())
            }
            OFF_PR => {
                if let Some(v) = self.protected_write(now, offset, value, mask, 0x7, "PR", "PVU")? {
                    self.pr = v;
                    self.pr_pending = Some(Pending {
                        at: now + UPDATE_LSI_CYCLES * self.lsi_period_ticks(),
                        value: v,
                    });
                    out.replan = true;
                }
                Ok(())
            }
            OFF_RLR => {
                if let Some(v) =
                    self.protected_write(now, offset, value, mask, 0xFFF, "RLR", "RVU")?
                {
                    self.rlr = v;
                    self.rlr_pending = Some(Pending {
                        at: now + UPDATE_LSI_CYCLES * self.lsi_period_ticks(),
                        value: v,
                    });
                }
                Ok(())
            }
            OFF_WINR if self.has_winr => {
                if let Some(v) =
                    self.protected_write(now, offset, value, mask, 0xFFF, "WINR", "WVU")?
                {
                    self.winr = v;
                    self.winr_pending = Some(Pending {
                        at: now + UPDATE_LSI_CYCLES * self.lsi_period_ticks(),
                        value: v,
                    });
                    // RM0440 §42.3.5 step 6: writing WINR refreshes the counter with RLR. Done at
                    // the write with the RLR the counter has (when exactly the LSI domain does it
                    // is not specified).
                    if self.running && !self.fired {
                        self.load(now, self.rlr_eff);
                        out.replan = true;
                    }
                }
                Ok(())
            }
            OFF_SR => Err(Unmodelled::write(offset, value, "IWDG_SR is read-only")),
            _ => Err(Unmodelled::write(
                offset,
                value,
                format!("IWDG register at offset {offset:#x} does not exist on this chip"),
            )),
        }
    }

    fn advance(&mut self, now: Time, out: &mut Signals) {
        self.settle(now);
        if let Some(r) = self.reset_time() {
            if r <= now {
                self.fired = true;
                out.reset = Some(ResetCause::IndependentWatchdog);
            }
        }
    }

    fn next_event(&self) -> Option<Time> {
        self.reset_time()
    }

    /// System reset: the watchdog stops and its registers return to their reset values (the
    /// hardware-watchdog option byte, which would start it at reset, is not modelled). The
    /// debugger freeze is the board's to keep or release.
    fn reset(&mut self, _now: Time) {
        let frozen = self.frozen_since;
        let ignored = self.ignored_writes;
        let lsi = self.lsi_hz;
        *self = Iwdg::new(self.has_winr);
        self.lsi_hz = lsi;
        self.ignored_writes = ignored;
        self.frozen_since = frozen;
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: Time = TICKS_PER_S / 1000;
    /// One LSI period at 32 kHz: 3.6 GHz / 32 kHz.
    const LSI: Time = 112_500;

    fn w(i: &mut Iwdg, now: Time, off: u32, v: u32) -> Signals {
        let mut s = Signals::default();
        i.write(now, off, v, 0xFFFF_FFFF, &mut s).unwrap();
        s
    }
    fn r(i: &mut Iwdg, now: Time, off: u32) -> u32 {
        i.read(now, off, &mut Signals::default()).unwrap()
    }

    /// embassy-stm32 0.6 `IndependentWatchdog::new(_, 50_000)` worked by hand:
    /// smallest prescaler with 4096 · psc / 32 kHz ≥ 50 ms is psc = 4 (512 ms) → PR = 0;
    /// RL = 50_000 / 4 · 32_000 / 1_000_000 − 1 = 400 − 1 = 399.
    const PR_50MS: u32 = 0;
    const RL_50MS: u32 = 399;

    /// The firmware's sequence: unlock, PR, RLR at t0, start at t1.
    fn firmware_setup(t0: Time, t1: Time) -> Iwdg {
        let mut i = Iwdg::new(false);
        w(&mut i, t0, OFF_KR, KEY_UNLOCK);
        w(&mut i, t0, OFF_PR, PR_50MS);
        w(&mut i, t0, OFF_RLR, RL_50MS);
        let s = w(&mut i, t1, OFF_KR, KEY_START);
        assert!(s.replan);
        i
    }

    #[test]
    fn counter_period_is_four_lsi_periods_at_pr0() {
        let i = Iwdg::new(false);
        assert_eq!(i.lsi_period_ticks(), LSI);
        // /4 at 32 kHz: 125 µs = 450_000 ticks.
        assert_eq!(i.counter_period_ticks(0), 450_000);
        // /256 for both 6 and 7.
        assert_eq!(i.counter_period_ticks(6), 256 * LSI);
        assert_eq!(i.counter_period_ticks(7), 256 * LSI);
    }

    #[test]
    fn first_timeout_after_start_counts_from_0xfff() {
        let t1 = 10 * MS;
        let i = firmware_setup(0, t1);
        // 4096 steps of 125 µs = 512 ms after the start key.
        assert_eq!(i.reset_time(), Some(t1 + 512 * MS));
        assert_eq!(i.next_event(), Some(t1 + 4096 * 450_000));
    }

    #[test]
    fn fifty_ms_after_each_pet() {
        let t1 = 10 * MS;
        let mut i = firmware_setup(0, t1);
        // Pet 1 ms after start: RLR = 399 → 400 steps of 125 µs = 50 ms exactly.
        let pet = t1 + MS;
        w(&mut i, pet, OFF_KR, KEY_RELOAD);
        assert_eq!(i.reset_time(), Some(pet + 50 * MS));
        assert_eq!(i.reset_time(), Some(pet + 180_000_000));
        // Nothing before the deadline...
        let mut s = Signals::default();
        i.advance(pet + 50 * MS - 1, &mut s);
        assert_eq!(s.reset, None);
        assert_eq!(i.counter(pet + 50 * MS - 1), Some(0));
        // ...the reset exactly at it.
        i.advance(pet + 50 * MS, &mut s);
        assert_eq!(s.reset, Some(ResetCause::IndependentWatchdog));
        assert_eq!(i.next_event(), None);
    }

    #[test]
    fn reload_postpones_the_reset() {
        let mut i = firmware_setup(0, 0);
        let mut t = MS;
        w(&mut i, t, OFF_KR, KEY_RELOAD);
        // Pet every 40 ms for a second: never resets.
        for _ in 0..25 {
            let deadline = i.reset_time().unwrap();
            assert_eq!(deadline, t + 50 * MS);
            let next = t + 40 * MS;
            let mut s = Signals::default();
            i.advance(next, &mut s);
            assert_eq!(s.reset, None);
            w(&mut i, next, OFF_KR, KEY_RELOAD);
            t = next;
        }
        assert_eq!(i.reset_time(), Some(t + 50 * MS));
    }

    #[test]
    fn counter_counts_down_from_rlr() {
        let mut i = firmware_setup(0, 0);
        w(&mut i, MS, OFF_KR, KEY_RELOAD);
        assert_eq!(i.counter(MS), Some(399));
        assert_eq!(i.counter(MS + 450_000 - 1), Some(399));
        assert_eq!(i.counter(MS + 450_000), Some(398));
        assert_eq!(i.counter(MS + 10 * MS), Some(399 - 80));
    }

    #[test]
    fn update_flags_follow_the_lsi_domain_delay() {
        let mut i = Iwdg::new(false);
        w(&mut i, 0, OFF_KR, KEY_UNLOCK);
        w(&mut i, 1000, OFF_PR, 3);
        w(&mut i, 2000, OFF_RLR, 0x123);
        // Both in progress: PVU | RVU.
        assert_eq!(r(&mut i, 2000, OFF_SR), 0b11);
        // Reads give the LSI-domain value: still the old one.
        assert_eq!(r(&mut i, 2000, OFF_PR), 0);
        assert_eq!(i.effective_pr_rlr(), (0, 0xFFF));
        // PVU clears 5 LSI periods after its write, RVU 5 after its own.
        assert_eq!(r(&mut i, 1000 + 5 * LSI - 1, OFF_SR), 0b11);
        assert_eq!(r(&mut i, 1000 + 5 * LSI, OFF_SR), 0b10);
        assert_eq!(r(&mut i, 2000 + 5 * LSI, OFF_SR), 0b00);
        assert_eq!(i.effective_pr_rlr(), (3, 0x123));
        assert_eq!(r(&mut i, 2000 + 5 * LSI, OFF_PR), 3);
        assert_eq!(r(&mut i, 2000 + 5 * LSI, OFF_RLR), 0x123);
    }

    #[test]
    fn pending_prescaler_applies_to_the_running_counter() {
        let mut i = Iwdg::new(false);
        w(&mut i, 0, OFF_KR, KEY_START); // counts 0xFFF at /4 from 0
        w(&mut i, 0, OFF_KR, KEY_UNLOCK);
        w(&mut i, 0, OFF_PR, 1); // /8 from 5 LSI periods on
        let at = 5 * LSI;
        // Steps done at /4 by then: 562_500 / 450_000 = 1 → 0xFFE left, then /8 (900_000).
        assert_eq!(i.reset_time(), Some(at + (0xFFE + 1) * 900_000));
        let mut s = Signals::default();
        i.advance(at, &mut s);
        assert_eq!(i.counter(at), Some(0xFFE));
        assert_eq!(i.reset_time(), Some(at + 0xFFF * 900_000));
    }

    #[test]
    fn locked_registers_ignore_writes() {
        let mut i = Iwdg::new(false);
        w(&mut i, 0, OFF_PR, 5);
        assert_eq!(r(&mut i, 0, OFF_PR), 0);
        w(&mut i, 0, OFF_KR, KEY_UNLOCK);
        w(&mut i, 0, OFF_KR, KEY_RELOAD); // any other key locks again
        w(&mut i, 0, OFF_RLR, 5);
        assert_eq!(r(&mut i, 0, OFF_RLR), 0xFFF);
        assert_eq!(i.ignored_writes(), 2);
    }

    #[test]
    fn write_during_update_is_reported() {
        let mut i = Iwdg::new(false);
        w(&mut i, 0, OFF_KR, KEY_UNLOCK);
        w(&mut i, 0, OFF_PR, 1);
        let e = i
            .write(10, OFF_PR, 2, 0xFFFF_FFFF, &mut Signals::default())
            .unwrap_err();
        assert!(e.why.contains("PVU"), "{}", e.why);
    }

    #[test]
    fn cannot_be_stopped_except_by_reset() {
        let mut i = firmware_setup(0, 0);
        // No key stops it.
        for key in [0x0000, 0x5555, 0x1234, KEY_START] {
            w(&mut i, MS, OFF_KR, key);
            assert!(i.running());
        }
        i.reset(2 * MS);
        assert!(!i.running());
        assert_eq!(i.next_event(), None);
        assert_eq!(r(&mut i, 2 * MS, OFF_RLR), 0xFFF);
        assert_eq!(r(&mut i, 2 * MS, OFF_PR), 0);
    }

    #[test]
    fn debugger_freeze_holds_the_counter() {
        let mut i = firmware_setup(0, 0);
        w(&mut i, MS, OFF_KR, KEY_RELOAD); // deadline 51 ms
        i.set_frozen(11 * MS, true);
        assert_eq!(i.next_event(), None);
        assert_eq!(i.counter(500 * MS), Some(399 - 80));
        let mut s = Signals::default();
        i.advance(500 * MS, &mut s);
        assert_eq!(s.reset, None);
        // Released after 489 ms halted: 40 ms of the period remain.
        i.set_frozen(500 * MS, false);
        assert_eq!(i.reset_time(), Some(540 * MS));
    }

    #[test]
    fn window_violation_resets_on_g4() {
        let mut i = Iwdg::new(true);
        w(&mut i, 0, OFF_KR, KEY_UNLOCK);
        w(&mut i, 0, OFF_RLR, 399);
        w(&mut i, 0, OFF_WINR, 100);
        assert_eq!(r(&mut i, 0, OFF_SR), 0b110); // RVU | WVU
        w(&mut i, 0, OFF_KR, KEY_START);
        // 1 ms later (past the update delay) the counter is 0xFFF - 8 = 4087 > 100: too early.
        let s = w(&mut i, MS, OFF_KR, KEY_RELOAD);
        assert_eq!(s.reset, Some(ResetCause::IndependentWatchdog));
        assert_eq!(i.next_event(), None);
    }

    #[test]
    fn window_open_reload_is_fine_on_g4() {
        let mut i = Iwdg::new(true);
        w(&mut i, 0, OFF_KR, KEY_UNLOCK);
        w(&mut i, 0, OFF_WINR, 0xFFF);
        w(&mut i, 0, OFF_KR, KEY_START);
        let s = w(&mut i, MS, OFF_KR, KEY_RELOAD);
        assert_eq!(s.reset, None);
        // F4 has no WINR.
        let mut f4 = Iwdg::new(false);
        assert!(f4.read(0, OFF_WINR, &mut Signals::default()).is_err());
    }

    #[test]
    fn byte_writes_are_reported() {
        let mut i = Iwdg::new(false);
        assert!(i
            .write(0, OFF_KR, 0x55, 0xFF, &mut Signals::default())
            .is_err());
        // A half-word store is fine.
        i.write(0, OFF_KR, KEY_UNLOCK, 0xFFFF, &mut Signals::default())
            .unwrap();
    }
}
