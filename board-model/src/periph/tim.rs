//! General-purpose and advanced timers (TIM1/TIM8: RM0390 §16, RM0440 §28; TIM2–TIM5: RM0390 §17,
//! RM0440 §29): the up-counting time base with its preload/shadow registers, four output-compare
//! channels, TRGO, and the update and capture/compare interrupts. The counter is not ticked: it is
//! computed from virtual time, and only steps that change something (a compare match, an overflow)
//! are visited.
//!
//! What the firmware and embassy-stm32 0.6 use, and so what is modelled:
//! - `timer/low_level.rs`: CR1 (CEN, UDIS, URS, OPM, ARPE), CR2.MMS, DIER (UIE, CCxIE), SR, EGR.UG,
//!   CCMR1/2 output modes and OCxPE, CCER (CCxE, CCxP), CNT, PSC, ARR, CCR1–4, BDTR.MOE.
//! - `time_driver/gp16.rs` (TIM4, 1 MHz): PSC, ARR = 0xFFFF, UG under URS, CCR1 = 0x8000 (half
//!   period) and CCR2 (alarm) compare interrupts, SR cleared by writing `!sr`.
//! - `firmware/src/rf.rs`: TIM1 15 MHz PWM carrier (MOE), TIM2 burst gate in PWM mode 1 (ARR/CCR
//!   preload, force-inactive → PWM1 starts) and one-pulse PWM mode 2; `board/*.rs`: TIM3 TRGO on
//!   update (MMS = 010) for the ADC.
//!
//! - `firmware/src/rf.rs` (RF level, docs/rf-level.md): TIM2 CR2.MMS = 001 (enable) as well as
//!   010; TIM8 as a slave of TIM2 (SMCR.TS = ITR1, SMS = 100 reset or 101 gated) with its
//!   TRGO on update for the DAC, and DIER.CC1DE: a DMA request at each CC1 match.
//!
//! Slave mode (RM0390 §16.3.19–§16.3.20 / §17.3.15 "Timers and external trigger
//! synchronization", SMCR §16.4.3 / §17.4.3; RM0440 §28.3 / §29.3 the same): only TS = ITR1 from
//! the timer `TimerConfig::itr1` names, with SMS = 000 (off), 100 (reset: a rising edge of TRGI
//! re-initialises the counter and the prescaler and generates an update, as EGR.UG does, and
//! sets TIF) and 101 (gated: the counter clock runs while TRGI is high and CEN = 1; TIF at each
//! start and stop). The trigger acts at the master's TRGO time; in gated mode the counter starts
//! on the next kernel clock edge (as for CEN). The manual's resynchronisation of TRGI (a few
//! CK_INT cycles, not quantified for the internal triggers) is not modelled: an approximation of
//! at most a few kernel clocks. Gated mode follows a TRGO *level* (master mode enable, MMS =
//! 001); a master in update or reset mode gives one-clock pulses, which open the gate for no
//! whole clock here. MSM (master/slave delay) is refused.
//!
//! DMA requests (RM0390 §17.4.4 DIER CCxDE; CR2.CCDS = 0, the only value accepted): a compare
//! match on channel x with CCxDE = 1 raises `Request::TimCc` at the match. CCxG (EGR) sets CCxIF
//! but raises no DMA request here (the manual says it does; the firmware does not use it).
//!
//! Everything else (down/center-aligned counting, input capture, the other slave modes and
//! triggers, update/trigger/COM DMA requests and DMA bursts, complementary outputs, break, dead
//! time, the G474's extended OCxM modes, dithering, UIF remapping) is refused with
//! `Unmodelled`.
//!
//! Time: the kernel clock (CK_INT, here = CK_PSC: internal clock, no slave mode) has edges on a
//! grid of `ticks_per_cycle(f)` master ticks that starts where the clock was last set. The
//! prescaler counts those edges; the counter changes on the edge where the prescaler wraps, and
//! every effect of a counter change (flag, OCxREF edge, TRGO, OPM stop) carries that edge's time.
//!
//! Section numbers are given for RM0390 (F446) and, where the G474 behaves the same, RM0440's
//! chapter; they were taken from the manuals' published structure, not re-read here.

use std::any::Any;

use super::{
    merge, ticks_per_cycle, ChannelLevel, ClockDomain, Clocks, Event, Peripheral, Signals, Time,
    Unmodelled, TICKS_PER_S,
};

/// Which timer this is and where it is wired.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TimerConfig {
    /// Timer number, 1 = TIM1.
    pub number: u8,
    /// Counter width: 16 or 32 (TIM2/TIM5).
    pub bits: u8,
    /// Advanced-control timer (TIM1/TIM8): RCR, BDTR.MOE.
    pub advanced: bool,
    /// `ClockDomain::TimApb1` or `ClockDomain::TimApb2`.
    pub clock: ClockDomain,
    pub name: &'static str,
    /// NVIC line of the update interrupt.
    pub irq_up: u16,
    /// NVIC line of the capture/compare interrupt (the same as `irq_up` for TIM2–TIM5).
    pub irq_cc: u16,
    /// The timer whose TRGO is this timer's internal trigger ITR1 (SMCR.TS = 001), if the board
    /// wires one the model knows: TIM8's ITR1 is TIM2 on both chips (RM0390 §16.4.3 table 86
    /// "TIMx internal trigger connection"; RM0440 §28 TIM8 internal trigger table, ITR1 =
    /// TIM2_TRGO). Table numbers from the manuals' published structure, not re-read here.
    pub itr1: Option<u8>,
}

// Register offsets (RM0390 §16.4.21 / §17.4.21 register maps; RM0440 §28.6 / §29.5 agree up to
// 0x44). RCR (0x30) and BDTR (0x44) exist on advanced timers only.
const CR1: u32 = 0x00;
const CR2: u32 = 0x04;
const SMCR: u32 = 0x08;
const DIER: u32 = 0x0C;
const SR: u32 = 0x10;
const EGR: u32 = 0x14;
const CCMR1: u32 = 0x18;
const CCMR2: u32 = 0x1C;
const CCER: u32 = 0x20;
const CNT: u32 = 0x24;
const PSC: u32 = 0x28;
const ARR: u32 = 0x2C;
const RCR: u32 = 0x30;
const CCR1: u32 = 0x34;
const CCR4: u32 = 0x40;
const BDTR: u32 = 0x44;
/// F446 DCR/DMAR; on the G474 these offsets hold CCR5/CCR6 (advanced) and DCR/DMAR moved to
/// 0x3DC/0x3E0. Neither is modelled.
const DCR_F4: u32 = 0x48;
const DMAR_F4: u32 = 0x4C;

// CR1 (RM0390 §17.4.1, §16.4.1).
const CR1_CEN: u32 = 1 << 0;
const CR1_UDIS: u32 = 1 << 1;
const CR1_URS: u32 = 1 << 2;
const CR1_OPM: u32 = 1 << 3;
const CR1_DIR: u32 = 1 << 4;
const CR1_CMS: u32 = 3 << 5;
const CR1_ARPE: u32 = 1 << 7;
/// Clock division for the digital filters and dead time: no effect on what is modelled.
const CR1_CKD: u32 = 3 << 8;
/// G474 only (RM0440): UIF copied into CNT bit 31.
const CR1_UIFREMAP: u32 = 1 << 11;
/// G474 only (RM0440): dithering.
const CR1_DITHEN: u32 = 1 << 12;
const CR1_KEPT: u32 = CR1_CEN | CR1_UDIS | CR1_URS | CR1_OPM | CR1_ARPE | CR1_CKD;

// CR2: MMS in bits 6:4 (RM0390 §17.4.2); the G474 adds MMS[3] at bit 25 (RM0440).
const CR2_MMS: u32 = 7 << 4;
const CR2_MMS3: u32 = 1 << 25;

// SR / EGR (RM0390 §17.4.5–§17.4.6); DIER enables sit at the same bits as the SR flags.
const SR_UIF: u32 = 1 << 0;
/// Trigger interrupt flag (set by the slave mode controller; its interrupt, TIE, is refused).
const SR_TIF: u32 = 1 << 6;
const EGR_UG: u32 = 1 << 0;
/// DIER.CC1DE..CC4DE (RM0390 §17.4.4): DMA requests on compare matches.
const DIER_CCDE: u32 = 0xF << 9;
// SMCR (RM0390 §17.4.3; RM0440 adds SMS[3] at bit 16 and TS[4:3] at bits 21:20).
const SMCR_SMS: u32 = 7;
const SMCR_TS: u32 = 7 << 4;
const SMS_RESET: u32 = 0b100;
const SMS_GATED: u32 = 0b101;
/// UIF and CC1IF..CC4IF: the only flags this model ever sets, and the only enables it accepts.
const FLAGS_MODELLED: u32 = 0x1F;

const BDTR_MOE: u32 = 1 << 15;

/// Output-compare mode OCxM[2:0] (RM0390 §17.4.7 CCMR1 output mode).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum OcMode {
    Frozen,
    ActiveOnMatch,
    InactiveOnMatch,
    Toggle,
    ForceInactive,
    ForceActive,
    Pwm1,
    Pwm2,
}

impl OcMode {
    fn from_bits(bits: u32) -> Self {
        match bits & 7 {
            0 => OcMode::Frozen,
            1 => OcMode::ActiveOnMatch,
            2 => OcMode::InactiveOnMatch,
            3 => OcMode::Toggle,
            4 => OcMode::ForceInactive,
            5 => OcMode::ForceActive,
            6 => OcMode::Pwm1,
            _ => OcMode::Pwm2,
        }
    }
    fn is_pwm(self) -> bool {
        matches!(self, OcMode::Pwm1 | OcMode::Pwm2)
    }
}

/// Everything that evolves: registers as software sees them, the shadow (active) registers, the
/// counter and prescaler counter, and the channel references and output levels. `PartialEq` is
/// what finds a steady cycle: two overflows with equal `Core`s repeat for ever.
#[derive(Clone, Debug, PartialEq, Eq)]
struct Core {
    cr1: u32,
    cr2: u32,
    smcr: u32,
    /// TRGI's level as the master last signalled it (`Event::TrgoLevel`), kept whatever SMCR
    /// holds so a slave mode chosen later starts from the right level.
    trgi_high: bool,
    dier: u32,
    sr: u32,
    ccmr: [u32; 2],
    ccer: u32,
    /// Preload registers (what software reads and writes).
    psc: u32,
    arr: u32,
    rcr: u32,
    ccr: [u32; 4],
    bdtr: u32,
    /// Shadow registers: what the counter and comparators use.
    psc_sh: u32,
    arr_sh: u32,
    ccr_sh: [u32; 4],
    /// Repetition down-counter (advanced timers, RM0390 §16.3.3).
    rep: u32,
    /// Counter and prescaler counter as of the edge `State::at`.
    cnt: u32,
    psc_cnt: u32,
    /// OCxREF of each channel.
    ocref: [bool; 4],
    /// OCx output level after CCxE, CCxP and MOE.
    level: [bool; 4],
}

impl Core {
    /// Reset values (RM0390 §17.4 / §16.4: all zero except ARR). ARR resets to all ones:
    /// 0xFFFF (16-bit) or 0xFFFF_FFFF (TIM2/TIM5) per RM0440 §29.5; some RM0390 revisions print
    /// 0x0000_0000 for the 32-bit timers. The firmware and embassy write ARR before counting.
    fn reset(modulus: u64) -> Self {
        let arr = (modulus - 1) as u32;
        Core {
            cr1: 0,
            cr2: 0,
            smcr: 0,
            trgi_high: false,
            dier: 0,
            sr: 0,
            ccmr: [0; 2],
            ccer: 0,
            psc: 0,
            arr,
            rcr: 0,
            ccr: [0; 4],
            bdtr: 0,
            psc_sh: 0,
            arr_sh: arr,
            ccr_sh: [0; 4],
            rep: 0,
            cnt: 0,
            psc_cnt: 0,
            ocref: [false; 4],
            level: [false; 4],
        }
    }

    fn mode(&self, ch: usize) -> OcMode {
        OcMode::from_bits(self.ccmr[ch / 2] >> (8 * (ch % 2) + 4))
    }
    /// OCxPE: CCRx preloaded (RM0390 §17.4.7).
    fn ocpe(&self, ch: usize) -> bool {
        self.ccmr[ch / 2] & (1 << (8 * (ch % 2) + 3)) != 0
    }
    fn cce(&self, ch: usize) -> bool {
        self.ccer & (1 << (4 * ch)) != 0
    }
    fn ccp(&self, ch: usize) -> bool {
        self.ccer & (1 << (4 * ch + 1)) != 0
    }
    fn mms(&self) -> u32 {
        (self.cr2 & CR2_MMS) >> 4
    }
    fn sms(&self) -> u32 {
        self.smcr & SMCR_SMS
    }
    /// Gated mode with TRGI low: the counter clock is stopped.
    fn gated_off(&self) -> bool {
        self.sms() == SMS_GATED && !self.trgi_high
    }
}

/// The simulated part of a timer: `Core` plus its place in time. Cloned to look ahead.
#[derive(Clone, Debug)]
struct State {
    core: Core,
    /// While counting: the kernel-clock edge at which `core.cnt`/`core.psc_cnt` hold (may lie up
    /// to one cycle after the present when the counter was just started or re-initialised).
    at: Time,
    /// Master ticks per kernel-clock cycle; 0 while the clock is unknown or not representable.
    tick: u64,
    /// An edge of the kernel clock grid: where it was last (re)set.
    origin: Time,
    recording: [bool; 4],
    number: u8,
    advanced: bool,
    /// 2^bits.
    modulus: u64,
    /// Planted defect: CCxDE raises no DMA request (`Timer::plant_no_cc_dma`).
    no_cc_dma: bool,
}

/// Look-ahead budget of `next_event` (steps). Only reached with a huge repetition counter.
const LOOKAHEAD_STEPS: u32 = 1_000_000;

impl State {
    /// The counter advances: CEN set, a clock, and ARR ≠ 0 ("the counter is blocked while the
    /// auto-reload value is null", RM0390 §17.4.12).
    fn counting(&self) -> bool {
        self.core.cr1 & CR1_CEN != 0
            && self.tick > 0
            && self.core.arr_sh != 0
            && !self.core.gated_off()
    }

    /// First kernel-clock edge at or after `t`.
    fn align_up(&self, t: Time) -> Time {
        if self.tick == 0 || t <= self.origin {
            return t.max(self.origin);
        }
        self.origin + (t - self.origin).div_ceil(self.tick) * self.tick
    }

    fn irq_bits(&self) -> u32 {
        self.core.sr & self.core.dier & FLAGS_MODELLED
    }

    /// The PWM comparison of each channel, up-counting: CNT < CCRx (RM0390 §17.3.9).
    fn results(&self) -> [bool; 4] {
        std::array::from_fn(|ch| self.core.cnt < self.core.ccr_sh[ch])
    }

    fn modes(&self) -> [OcMode; 4] {
        std::array::from_fn(|ch| self.core.mode(ch))
    }

    /// PWM mode (RM0390 §17.3.9, §16.3.10; RM0440 §29.3 "PWM mode"): CNT and CCRx are always
    /// compared, but OCxREF is asserted "only when the result of the comparison changes, or when
    /// the output compare mode switches from the frozen configuration to one of the PWM modes".
    /// Applied here to both directions: OCxREF follows the comparison only at a change of its
    /// result (counter step, overflow, shadow load, CNT or unbuffered CCR write) or on
    /// frozen → PWM. A channel switched from force-inactive to PWM mode 1 at CNT = 0 < CCR
    /// therefore stays low until the comparison next changes, i.e. the next period.
    /// `old_modes` is Some when the modes may just have been written.
    fn track_pwm(&mut self, before: [bool; 4], old_modes: Option<[OcMode; 4]>) {
        let now = self.results();
        for ch in 0..4 {
            let mode = self.core.mode(ch);
            if !mode.is_pwm() {
                continue;
            }
            let from_frozen = old_modes.is_some_and(|m| m[ch] == OcMode::Frozen);
            if from_frozen || now[ch] != before[ch] {
                self.core.ocref[ch] = if mode == OcMode::Pwm1 {
                    now[ch]
                } else {
                    !now[ch]
                };
            }
        }
    }

    /// Output of channel `ch` (RM0390 §17.4.9 table "Output control bit for standard OCx
    /// channels": CCxE = 0 → OCx = 0; CCxE = 1 → OCxREF + polarity CCxP). Advanced timers also
    /// need BDTR.MOE (RM0390 §16.4.18): with MOE = 0 and OSSI = 0 (the only OSSI modelled) the
    /// output is not driven, shown here as low.
    fn output(&self, ch: usize) -> bool {
        let enabled = self.core.cce(ch) && (!self.advanced || self.core.bdtr & BDTR_MOE != 0);
        enabled && (self.core.ocref[ch] ^ self.core.ccp(ch))
    }

    /// Recompute the outputs; a change on a recorded channel is an edge at `t`.
    fn update_levels(&mut self, t: Time, out: &mut Signals) {
        for ch in 0..4 {
            let high = self.output(ch);
            if high != self.core.level[ch] {
                self.core.level[ch] = high;
                if self.recording[ch] {
                    out.levels.push(ChannelLevel {
                        at: t,
                        timer: self.number,
                        channel: ch as u8 + 1,
                        high,
                    });
                }
            }
        }
    }

    fn trgo(&self, t: Time, out: &mut Signals) {
        out.events.push((t, Event::Trgo { timer: self.number }));
    }

    /// TRGO as a level in master mode enable (MMS = 001): CNT_EN = CEN here (no slave mode on
    /// a master in this model's boards). A rising edge is also a `Trgo` pulse.
    fn trgo_level(&self, t: Time, high: bool, out: &mut Signals) {
        if high {
            self.trgo(t, out);
        }
        out.events.push((
            t,
            Event::TrgoLevel {
                timer: self.number,
                high,
            },
        ));
    }

    /// Update event (UEV) at `t`, from an overflow (`by_ug` false) or from EGR.UG.
    fn update_event(&mut self, t: Time, out: &mut Signals, by_ug: bool) {
        let c = &mut self.core;
        // Shadow loads at UEV: PSC always buffered (RM0390 §17.3.1 "the new prescaler ratio is
        // taken into account at the next update event"), ARR when ARPE (§17.3.1, §17.4.1),
        // CCRx when OCxPE (§17.3.8, §17.4.7). Unbuffered registers are already equal.
        c.psc_sh = c.psc;
        if c.cr1 & CR1_ARPE != 0 {
            c.arr_sh = c.arr;
        }
        for ch in 0..4 {
            if c.ocpe(ch) {
                c.ccr_sh[ch] = c.ccr[ch];
            }
        }
        // The repetition counter is reloaded from RCR at every UEV, UG included (RM0390 §16.3.3).
        if self.advanced {
            c.rep = c.rcr;
        }
        // URS = 1: only overflow sets UIF; a UG-generated update does not (RM0390 §17.4.1).
        if !by_ug || c.cr1 & CR1_URS == 0 {
            c.sr |= SR_UIF;
        }
        // TRGO (RM0390 §17.4.2 MMS): 000 reset — the UG bit is the trigger output; 010 update —
        // every update event. URS restricts interrupts/DMA only, so a UG under URS still pulses
        // TRGO in update mode.
        let mms = c.mms();
        // One-pulse mode: "counter stops counting at the next update event (clearing the bit
        // CEN)" (RM0390 §17.4.1, §17.3.10). Whether a UG-generated update also clears CEN is not
        // stated; it is taken as one (the firmware only issues UG with the counter stopped).
        let stopped = c.cr1 & CR1_OPM != 0 && c.cr1 & CR1_CEN != 0;
        if c.cr1 & CR1_OPM != 0 {
            c.cr1 &= !CR1_CEN;
        }
        if mms == 2 || (by_ug && mms == 0) {
            self.trgo(t, out);
        }
        if stopped && mms == 1 {
            self.trgo_level(t, false, out);
        }
    }

    /// The counter wrapped from ARR to 0 at `t`.
    fn overflow(&mut self, t: Time, out: &mut Signals) {
        // UDIS = 1: no UEV; shadows keep their values, the counter wraps all the same
        // (RM0390 §17.4.1). Whether the repetition counter still counts down under UDIS is not
        // stated; here it holds.
        if self.core.cr1 & CR1_UDIS != 0 {
            return;
        }
        // UEV only when the repetition counter has reached zero; otherwise it counts down
        // (RM0390 §16.3.3).
        if self.advanced && self.core.rep > 0 {
            self.core.rep -= 1;
            return;
        }
        self.update_event(t, out, false);
    }

    /// CNT just became the value it now holds by counting: compare matches (RM0390 §17.3.8):
    /// CCxIF is set, and the match modes act on OCxREF. Matches are counted on counter steps
    /// only, not on CNT or CCRx writes nor on UG. The later manuals' "CCxIF goes high at overflow
    /// when CCRx > ARR" (RM0440 SR) is not modelled.
    fn compare_match(&mut self, t: Time, out: &mut Signals) {
        for ch in 0..4 {
            if self.core.cnt != self.core.ccr_sh[ch] {
                continue;
            }
            self.core.sr |= 1 << (ch + 1);
            if self.core.dier & (1 << (9 + ch)) != 0 && !self.no_cc_dma {
                out.events.push((
                    t,
                    Event::DmaRequest(super::Request::TimCc {
                        timer: self.number,
                        channel: ch as u8 + 1,
                    }),
                ));
            }
            match self.core.mode(ch) {
                OcMode::ActiveOnMatch => self.core.ocref[ch] = true,
                OcMode::InactiveOnMatch => self.core.ocref[ch] = false,
                OcMode::Toggle => self.core.ocref[ch] = !self.core.ocref[ch],
                _ => {}
            }
        }
    }

    /// The next counter step that changes anything: (its time, how many counter increments away).
    fn next_step(&self) -> Option<(Time, u64)> {
        if !self.counting() {
            return None;
        }
        let c = self.core.cnt as u64;
        let a = self.core.arr_sh as u64;
        // Up-counting overflows after CNT = ARR (RM0390 §17.3.2). A counter left above ARR (an
        // unbuffered ARR written below it) runs on to the end of its range and wraps to 0; no
        // UEV is generated there, as the manual describes the overflow only at ARR (not verified
        // on silicon).
        let (mut s, last) = if c <= a {
            (a - c + 1, a)
        } else {
            (self.modulus - c, self.modulus - 1)
        };
        for &v in &self.core.ccr_sh {
            let v = v as u64;
            if v > c && v <= last {
                s = s.min(v - c);
            }
        }
        let p1 = self.core.psc_sh as u128 + 1;
        // The counter increments on the edge where the prescaler counter wraps (RM0390 §17.3.1).
        let first = p1 - self.core.psc_cnt as u128;
        let edges = first + (s as u128 - 1) * p1;
        let t = self.at as u128 + edges * self.tick as u128;
        Some((t.min(u64::MAX as u128) as Time, s))
    }

    /// Carry out the step found by `next_step`. Returns whether it was an overflow (ARR → 0).
    fn apply_step(&mut self, t: Time, s: u64, out: &mut Signals) -> bool {
        #[cfg(test)]
        tests::STEPS.with(|n| n.set(n.get() + 1));
        let before = self.results();
        let c = self.core.cnt as u64;
        let a = self.core.arr_sh as u64;
        let overflow = c <= a && c + s == a + 1;
        let wrap = overflow || c + s == self.modulus;
        self.at = t;
        self.core.psc_cnt = 0;
        self.core.cnt = if wrap { 0 } else { (c + s) as u32 };
        if overflow {
            self.overflow(t, out);
        }
        // After the shadow load, so a CCRx = 0 loaded at this update matches at CNT = 0.
        self.compare_match(t, out);
        self.track_pwm(before, None);
        self.update_levels(t, out);
        overflow
    }

    /// Bring counter and prescaler to the last kernel edge ≤ `now`, where no step remains.
    fn normalize(&mut self, now: Time) {
        if !self.counting() || now <= self.at {
            return;
        }
        let edges = (now - self.at) / self.tick;
        if edges == 0 {
            return;
        }
        let p1 = self.core.psc_sh as u64 + 1;
        let total = self.core.psc_cnt as u64 + edges;
        // Every step up to `now` was processed, so these increments cross no interesting value.
        self.core.cnt = (self.core.cnt as u64 + total / p1) as u32;
        self.core.psc_cnt = (total % p1) as u32;
        self.at += edges * self.tick;
    }

    /// Overflows after which the state must have come round again once the shadows are loaded:
    /// the repetition counter's cycle times two for toggle mode, plus the first periods.
    fn cycle_bound(&self) -> u64 {
        2 * (self.core.rcr as u64 + 1) + 2
    }

    /// Everything that happens up to and including `now`, in time order. Whole cycles in which
    /// nothing is emitted and after which the state is the same are skipped arithmetically, so an
    /// unrecorded carrier costs a few steps whatever the span.
    fn run(&mut self, now: Time, out: &mut Signals) {
        let bound = self.cycle_bound();
        // (state at an overflow, its time, outputs emitted by then, overflows since)
        let mut reference: Option<(Core, Time, usize, u64)> = None;
        while let Some((t, s)) = self.next_step() {
            if t > now {
                break;
            }
            if !self.apply_step(t, s, out) {
                continue;
            }
            let emitted = out.levels.len() + out.events.len();
            if let Some((core, t_ref, emitted_ref, _)) = &reference {
                if *core == self.core && *emitted_ref == emitted {
                    let cycle = t - *t_ref;
                    self.at += (now - t) / cycle * cycle;
                    reference = None;
                    continue;
                }
            }
            let keep = match &mut reference {
                Some((_, _, _, n)) if *n < bound => {
                    *n += 1;
                    true
                }
                _ => false,
            };
            if !keep {
                reference = Some((self.core.clone(), t, emitted, 0));
            }
        }
        self.normalize(now);
    }

    /// The time of the next step others can see: an edge of a recorded channel, a TRGO, or an
    /// interrupt line rising. None if the timer settles into a cycle where none happens.
    fn next_observable(&self) -> Option<Time> {
        let mut sim = self.clone();
        let mut scratch = Signals::default();
        let bound = sim.cycle_bound();
        let mut reference: Option<(Core, u64)> = None;
        for _ in 0..LOOKAHEAD_STEPS {
            let (t, s) = sim.next_step()?;
            let irq_before = sim.irq_bits();
            let overflow = sim.apply_step(t, s, &mut scratch);
            if !scratch.levels.is_empty()
                || !scratch.events.is_empty()
                || sim.irq_bits() & !irq_before != 0
            {
                return Some(t);
            }
            if !overflow {
                continue;
            }
            if matches!(&reference, Some((core, _)) if *core == sim.core) {
                return None;
            }
            let keep = match &mut reference {
                Some((_, n)) if *n < bound => {
                    *n += 1;
                    true
                }
                _ => false,
            };
            if !keep {
                reference = Some((sim.core.clone(), 0));
            }
        }
        // Budget spent without an answer: ask to be woken at the next step and look again.
        sim.next_step().map(|(t, _)| t)
    }

    /// EGR.UG at `now` (RM0390 §17.4.6): re-initialise the counter and the prescaler counter and
    /// generate an update (shadow loads, UIF unless URS, TRGO). With UDIS = 1 only the counter
    /// and prescaler are re-initialised (RM0390 §17.4.1 UDIS); TRGO in reset mode (MMS = 000) is
    /// the UG bit itself and is emitted either way.
    fn ug(&mut self, now: Time, out: &mut Signals) {
        let before = self.results();
        self.core.cnt = 0;
        self.core.psc_cnt = 0;
        if self.counting() {
            // The cleared prescaler restarts on the next kernel edge.
            self.at = self.align_up(now);
        }
        if self.core.cr1 & CR1_UDIS != 0 {
            if self.core.mms() == 0 {
                self.trgo(now, out);
            }
        } else {
            self.update_event(now, out, true);
        }
        self.track_pwm(before, None);
        self.update_levels(now, out);
    }
}

/// One STM32 TIMx register block.
pub struct Timer {
    cfg: TimerConfig,
    st: State,
    /// Kernel clock.
    hz: u64,
    /// A kernel clock that does not divide the master clock: every access fails with this.
    clock_error: Option<String>,
    /// Signals produced where the interface gives no `Signals` (a clock change, a reset): handed
    /// out with the next access or `advance`.
    pending: Signals,
    /// Planted defects (`BOARD_MODEL_PLANT`, to show a check fails): gated mode ignores TRGI
    /// (the counter runs whenever CEN = 1); EGR.UG makes no TRGO; CCxDE raises no DMA request.
    pub plant_gate_ignored: bool,
    pub plant_ug_no_trgo: bool,
}

impl Timer {
    pub fn new(cfg: TimerConfig) -> Self {
        assert!(
            cfg.bits == 16 || cfg.bits == 32,
            "{}: a timer counter has 16 or 32 bits",
            cfg.name
        );
        let modulus = 1u64 << cfg.bits;
        Timer {
            st: State {
                core: Core::reset(modulus),
                at: 0,
                tick: 0,
                origin: 0,
                recording: [false; 4],
                number: cfg.number,
                advanced: cfg.advanced,
                modulus,
                no_cc_dma: false,
            },
            cfg,
            hz: 0,
            clock_error: None,
            pending: Signals::default(),
            plant_gate_ignored: false,
            plant_ug_no_trgo: false,
        }
    }

    /// Emit `ChannelLevel` edges for `channel` (1..=4), or stop, from the moment the timer was
    /// last brought to (the last access, `advance` or clock change). Exact only when that moment
    /// is the present: before the run starts, or right after `advance(now)`. A timer left behind
    /// (nothing observable, so nothing advanced it) would otherwise emit the edges since then, in
    /// the past: use `record_channel_at` while running.
    pub fn record_channel(&mut self, channel: u8, on: bool) {
        assert!(
            (1..=4).contains(&channel),
            "{}: channel {channel} is not 1..=4",
            self.cfg.name
        );
        self.st.recording[channel as usize - 1] = on;
    }

    /// `record_channel` at `now`: first catch up to `now` (whatever happens until then, with the
    /// recording as it was, goes to `out`), then switch. Edges are emitted only for output changes
    /// after `now`; the level at `now` is `channel_level`. Sets `out.replan` (the next event moves).
    pub fn record_channel_at(&mut self, now: Time, channel: u8, on: bool, out: &mut Signals) {
        self.flush_pending(out);
        self.st.run(now, out);
        self.record_channel(channel, on);
        out.replan = true;
    }

    /// The output level of `channel` (1..=4) as of the last access or `advance`.
    pub fn channel_level(&self, channel: u8) -> bool {
        assert!(
            (1..=4).contains(&channel),
            "{}: channel {channel} is not 1..=4",
            self.cfg.name
        );
        self.st.core.level[channel as usize - 1]
    }

    /// Planted defect: CCxDE raises no DMA request.
    pub fn plant_no_cc_dma(&mut self) {
        self.st.no_cc_dma = true;
    }

    /// Planted defect: the gate starts open (see `plant_gate_ignored`).
    pub fn plant_gate_open(&mut self) {
        self.st.core.trgi_high = true;
    }

    /// Kernel clock (CK_INT) in Hz; 0 before the first `set_clocks`.
    pub fn frequency_hz(&self) -> u64 {
        self.hz
    }

    fn flush_pending(&mut self, out: &mut Signals) {
        out.levels.append(&mut self.pending.levels);
        out.events.append(&mut self.pending.events);
    }

    fn clock_check(&self, offset: u32, write: Option<u32>) -> Result<(), Unmodelled> {
        match &self.clock_error {
            Some(why) => Err(Unmodelled {
                offset,
                write,
                why: why.clone(),
            }),
            None => Ok(()),
        }
    }

    fn unmodelled(&self, offset: u32, value: u32, why: String) -> Result<(), Unmodelled> {
        Err(Unmodelled::write(
            offset,
            value,
            format!("{}_{why}", self.cfg.name),
        ))
    }

    fn write_reg(
        &mut self,
        now: Time,
        offset: u32,
        value: u32,
        mask: u32,
        out: &mut Signals,
    ) -> Result<(), Unmodelled> {
        let ctr_mask = (self.st.modulus - 1) as u32;
        match offset {
            CR1 => {
                let v = merge(self.st.core.cr1, value, mask);
                for (bit, why) in [
                    (CR1_DIR, "CR1.DIR=1 (down-counting) is not modelled"),
                    (CR1_CMS, "CR1.CMS (center-aligned counting) is not modelled"),
                    (
                        CR1_UIFREMAP,
                        "CR1.UIFREMAP (UIF copy in CNT bit 31) is not modelled",
                    ),
                    (CR1_DITHEN, "CR1.DITHEN (dithering) is not modelled"),
                ] {
                    if v & bit != 0 {
                        return self.unmodelled(offset, value, why.into());
                    }
                }
                let c = &mut self.st.core;
                let old = c.cr1;
                c.cr1 = v & CR1_KEPT;
                // ARPE = 0: "TIMx_ARR register is not buffered" (RM0390 §17.4.1): a preload
                // still pending when buffering is turned off is taken as active at once.
                if old & CR1_ARPE != 0 && v & CR1_ARPE == 0 {
                    c.arr_sh = c.arr;
                }
                // MMS = 001 enable: TRGO is CNT_EN, a level; its rising edge is emitted as a
                // pulse (what an edge-triggered ADC sees). The falling edge is not an event.
                if (old ^ v) & CR1_CEN != 0 && c.mms() == 1 {
                    let high = v & CR1_CEN != 0;
                    self.st.trgo_level(now, high, out);
                }
            }
            CR2 => {
                let v = merge(self.st.core.cr2, value, mask);
                let mms = (v & CR2_MMS) >> 4;
                if v & CR2_MMS3 != 0 {
                    return self.unmodelled(
                        offset,
                        value,
                        "CR2.MMS[3] (G474 extended master modes) is not modelled".into(),
                    );
                }
                if v & !CR2_MMS != 0 {
                    return self.unmodelled(
                        offset,
                        value,
                        format!(
                            "CR2 bits {:#x} (CCPC/CCUS/CCDS/TI1S/OISx/MMS2) are not modelled",
                            v & !CR2_MMS
                        ),
                    );
                }
                if mms > 2 {
                    return self.unmodelled(
                        offset,
                        value,
                        format!("CR2.MMS={mms:03b} (only reset, enable, update are modelled)"),
                    );
                }
                let old_mms = self.st.core.mms();
                self.st.core.cr2 = v;
                if (mms == 1) != (old_mms == 1) && self.st.core.cr1 & CR1_CEN != 0 {
                    self.st.trgo_level(now, mms == 1, out);
                }
            }
            SMCR => {
                let v = merge(self.st.core.smcr, value, mask);
                let sms = v & SMCR_SMS;
                let ts = (v & SMCR_TS) >> 4;
                if v & !(SMCR_SMS | SMCR_TS) != 0 {
                    return self.unmodelled(
                        offset,
                        value,
                        format!(
                            "SMCR={v:#x}: MSM, external trigger/clock and the G474's SMS[3]/TS[4:3] are not modelled"
                        ),
                    );
                }
                if sms != 0 && !(sms == SMS_RESET || sms == SMS_GATED) {
                    return self.unmodelled(
                        offset,
                        value,
                        format!("SMCR.SMS={sms:03b}: only 000, 100 (reset) and 101 (gated) are modelled"),
                    );
                }
                if sms != 0 && (ts != 1 || self.cfg.itr1.is_none()) {
                    return self.unmodelled(
                        offset,
                        value,
                        format!(
                            "SMCR.TS={ts:03b}: only ITR1 from a modelled master is modelled ({})",
                            match self.cfg.itr1 {
                                Some(m) => format!("ITR1 = TIM{m}"),
                                None => "this timer has none".into(),
                            }
                        ),
                    );
                }
                let was = self.st.counting();
                self.st.core.smcr = v;
                if self.st.counting() && !was {
                    self.st.at = self.st.align_up(now);
                }
            }
            DIER => {
                let v = merge(self.st.core.dier, value, mask);
                if v & !(FLAGS_MODELLED | DIER_CCDE) != 0 {
                    return self.unmodelled(
                        offset,
                        value,
                        format!(
                            "DIER bits {:#x} (update/trigger/COM DMA requests, trigger/COM/break interrupts) are not modelled",
                            v & !(FLAGS_MODELLED | DIER_CCDE)
                        ),
                    );
                }
                self.st.core.dier = v;
            }
            SR => {
                // rc_w0: writing 0 clears a flag, writing 1 leaves it (RM0390 §17.4.5); lanes
                // outside `mask` are not written.
                self.st.core.sr &= value | !mask;
            }
            EGR => {
                let v = value & mask;
                if v & !FLAGS_MODELLED != 0 {
                    return self.unmodelled(
                        offset,
                        value,
                        format!(
                            "EGR bits {:#x} (TG/COMG/BG/B2G) are not modelled",
                            v & !FLAGS_MODELLED
                        ),
                    );
                }
                // CCxG on an output channel sets CCxIF (RM0390 §17.4.6).
                self.st.core.sr |= v & !EGR_UG & FLAGS_MODELLED;
                if v & EGR_UG != 0 {
                    let n = out.events.len();
                    self.st.ug(now, out);
                    if self.plant_ug_no_trgo {
                        let me = self.cfg.number;
                        let mut k = 0;
                        out.events.retain(|e| {
                            k += 1;
                            k <= n || e.1 != Event::Trgo { timer: me }
                        });
                    }
                }
            }
            CCMR1 | CCMR2 => {
                let i = ((offset - CCMR1) / 4) as usize;
                let v = merge(self.st.core.ccmr[i], value, mask);
                for h in 0..2 {
                    let ch = 2 * i + h;
                    let byte = (v >> (8 * h)) & 0xFF;
                    if byte & 3 != 0 {
                        return self.unmodelled(
                            offset,
                            value,
                            format!(
                                "CCMR{}.CC{}S={} (input capture) is not modelled",
                                i + 1,
                                ch + 1,
                                byte & 3
                            ),
                        );
                    }
                    if byte & 0x80 != 0 {
                        return self.unmodelled(
                            offset,
                            value,
                            format!("CCMR{}.OC{}CE (OCREF clear) is not modelled", i + 1, ch + 1),
                        );
                    }
                    if v & (1 << (16 + 8 * h)) != 0 {
                        return self.unmodelled(
                            offset,
                            value,
                            format!(
                                "CCMR{}.OC{}M[3] (G474 extended output compare modes) is not modelled",
                                i + 1,
                                ch + 1
                            ),
                        );
                    }
                    let old = self.st.core.mode(ch);
                    let new = OcMode::from_bits(byte >> 4);
                    if old.is_pwm() && new.is_pwm() && old != new {
                        return self.unmodelled(
                            offset,
                            value,
                            format!(
                                "CCMR{}.OC{}M: a direct switch between PWM modes 1 and 2 is not modelled (the manual does not say what OCxREF does)",
                                i + 1,
                                ch + 1
                            ),
                        );
                    }
                }
                let before = self.st.results();
                let old_modes = self.st.modes();
                let c = &mut self.st.core;
                let old_pe = [c.ocpe(2 * i), c.ocpe(2 * i + 1)];
                c.ccmr[i] = v & 0xFFFF;
                for (h, &was_preloaded) in old_pe.iter().enumerate() {
                    let ch = 2 * i + h;
                    // OCxPE = 0: CCRx is not buffered (RM0390 §17.4.7); a pending preload becomes
                    // active at once.
                    if was_preloaded && !c.ocpe(ch) {
                        c.ccr_sh[ch] = c.ccr[ch];
                    }
                    // Forced modes act on OCxREF immediately: OCxM is not preloaded
                    // (RM0390 §17.3.7 "Forced output mode").
                    match c.mode(ch) {
                        OcMode::ForceInactive => c.ocref[ch] = false,
                        OcMode::ForceActive => c.ocref[ch] = true,
                        _ => {}
                    }
                }
                self.st.track_pwm(before, Some(old_modes));
                self.st.update_levels(now, out);
            }
            CCER => {
                let v = merge(self.st.core.ccer, value, mask);
                for ch in 0..4 {
                    if v & (1 << (4 * ch + 2)) != 0 {
                        return self.unmodelled(
                            offset,
                            value,
                            format!("CCER.CC{}NE (complementary output) is not modelled", ch + 1),
                        );
                    }
                    if v & (1 << (4 * ch + 3)) != 0 {
                        return self.unmodelled(
                            offset,
                            value,
                            format!("CCER.CC{}NP is not modelled", ch + 1),
                        );
                    }
                }
                if v & 0xFFFF_0000 != 0 {
                    return self.unmodelled(
                        offset,
                        value,
                        "CCER channels 5/6 are not modelled".into(),
                    );
                }
                self.st.core.ccer = v;
                self.st.update_levels(now, out);
            }
            CNT => {
                // A CNT write changes the counter only; the prescaler counter runs on.
                let before = self.st.results();
                self.st.core.cnt = merge(self.st.core.cnt, value, mask) & ctr_mask;
                self.st.track_pwm(before, None);
                self.st.update_levels(now, out);
            }
            PSC => {
                // Always buffered: takes effect at the next update event (RM0390 §17.3.1).
                self.st.core.psc = merge(self.st.core.psc, value, mask) & 0xFFFF;
            }
            ARR => {
                let c = &mut self.st.core;
                c.arr = merge(c.arr, value, mask) & ctr_mask;
                // ARPE = 0: written straight to the shadow (RM0390 §17.3.1, fig. "ARPE=0").
                if c.cr1 & CR1_ARPE == 0 {
                    c.arr_sh = c.arr;
                }
            }
            RCR if self.cfg.advanced => {
                // Buffered; loaded into the repetition counter at the next UEV (RM0390 §16.3.3).
                // REP is 8 bits on the F446, 16 on the G474.
                self.st.core.rcr = merge(self.st.core.rcr, value, mask) & 0xFFFF;
            }
            CCR1..=CCR4 if offset.is_multiple_of(4) => {
                let ch = ((offset - CCR1) / 4) as usize;
                let before = self.st.results();
                let c = &mut self.st.core;
                c.ccr[ch] = merge(c.ccr[ch], value, mask) & ctr_mask;
                // OCxPE = 0: the active register is written at once (RM0390 §17.3.8).
                if !c.ocpe(ch) {
                    c.ccr_sh[ch] = c.ccr[ch];
                    self.st.track_pwm(before, None);
                    self.st.update_levels(now, out);
                }
            }
            BDTR if self.cfg.advanced => {
                let v = merge(self.st.core.bdtr, value, mask);
                if v & !BDTR_MOE != 0 {
                    return self.unmodelled(
                        offset,
                        value,
                        format!(
                            "BDTR bits {:#x} (dead time, lock, OSSI/OSSR, break, AOE) are not modelled",
                            v & !BDTR_MOE
                        ),
                    );
                }
                self.st.core.bdtr = v;
                self.st.update_levels(now, out);
            }
            DCR_F4 | DMAR_F4 => {
                return self.unmodelled(
                    offset,
                    value,
                    "DCR/DMAR (DMA burst) is not modelled".into(),
                )
            }
            _ => {
                let why = format!(
                    "{} register at offset {offset:#x} is not modelled",
                    self.cfg.name
                );
                return Err(Unmodelled::write(offset, value, why));
            }
        }
        Ok(())
    }
}

impl Peripheral for Timer {
    fn name(&self) -> &'static str {
        self.cfg.name
    }

    fn read(&mut self, now: Time, offset: u32, out: &mut Signals) -> Result<u32, Unmodelled> {
        self.clock_check(offset, None)?;
        self.flush_pending(out);
        self.st.run(now, out);
        let c = &self.st.core;
        Ok(match offset {
            CR1 => c.cr1,
            CR2 => c.cr2,
            SMCR => c.smcr,
            DIER => c.dier,
            SR => c.sr,
            // Write-only.
            EGR => 0,
            CCMR1 => c.ccmr[0],
            CCMR2 => c.ccmr[1],
            CCER => c.ccer,
            // As of `now` (RM0390 §17.4.10); bit 31 is UIFCPY only under UIFREMAP (refused).
            CNT => c.cnt,
            // PSC, ARR, RCR, CCRx read the preload registers (RM0390 §17.4.11–§17.4.16).
            PSC => c.psc,
            ARR => c.arr,
            RCR if self.cfg.advanced => c.rcr,
            CCR1..=CCR4 if offset.is_multiple_of(4) => c.ccr[((offset - CCR1) / 4) as usize],
            BDTR if self.cfg.advanced => c.bdtr,
            DCR_F4 | DMAR_F4 => {
                return Err(Unmodelled::read(
                    offset,
                    format!("{}_DCR/DMAR (DMA burst) is not modelled", self.cfg.name),
                ))
            }
            _ => {
                return Err(Unmodelled::read(
                    offset,
                    format!(
                        "{} register at offset {offset:#x} is not modelled",
                        self.cfg.name
                    ),
                ))
            }
        })
    }

    fn write(
        &mut self,
        now: Time,
        offset: u32,
        value: u32,
        mask: u32,
        out: &mut Signals,
    ) -> Result<(), Unmodelled> {
        self.clock_check(offset, Some(value))?;
        self.flush_pending(out);
        self.st.run(now, out);
        let next_before = self.next_event();
        let irq_before = self.st.irq_bits();
        let was_counting = self.st.counting();
        let emitted = out.levels.len() + out.events.len();
        self.write_reg(now, offset, value, mask, out)?;
        if self.st.counting() && !was_counting {
            // Counting starts on the next kernel edge (RM0390 §17.3.2: CNT_EN follows CEN by a
            // clock); the prescaler counter resumes where it stopped.
            self.st.at = self.st.align_up(now);
        }
        let control = matches!(offset, CR1 | CR2 | DIER | SR | EGR);
        if control
            || self.st.irq_bits() != irq_before
            || out.levels.len() + out.events.len() != emitted
            || self.next_event() != next_before
        {
            out.replan = true;
        }
        Ok(())
    }

    fn advance(&mut self, now: Time, out: &mut Signals) {
        self.flush_pending(out);
        self.st.run(now, out);
    }

    /// The master's TRGO on ITR1 (see the module doc, "Slave mode").
    fn on_event(&mut self, now: Time, event: Event, out: &mut Signals) {
        let Some(master) = self.cfg.itr1 else {
            return;
        };
        let selected = (self.st.core.smcr & SMCR_TS) >> 4 == 1;
        match event {
            Event::TrgoLevel { timer, high } if timer == master => {
                if self.clock_error.is_some() {
                    return;
                }
                self.flush_pending(out);
                self.st.run(now, out);
                let was = self.st.counting();
                let changed = self.st.core.trgi_high != high;
                self.st.core.trgi_high = high || self.plant_gate_ignored;
                if selected && self.st.core.sms() == SMS_GATED && changed {
                    // TIF at each start and stop of the gated counter.
                    self.st.core.sr |= SR_TIF;
                    if self.st.counting() && !was {
                        self.st.at = self.st.align_up(now);
                    }
                    out.replan = true;
                }
            }
            Event::Trgo { timer }
                if timer == master
                    && selected
                    && self.st.core.sms() == SMS_RESET
                    && self.clock_error.is_none() =>
            {
                self.flush_pending(out);
                self.st.run(now, out);
                self.st.core.sr |= SR_TIF;
                // Counter and prescaler re-initialised, an update generated (URS counts it
                // as UG: RM0390 §17.4.1 URS "update generation through the slave mode
                // controller").
                self.st.ug(now, out);
                out.replan = true;
            }
            _ => {}
        }
    }

    fn next_event(&self) -> Option<Time> {
        let pending = self
            .pending
            .levels
            .iter()
            .map(|l| l.at)
            .chain(self.pending.events.iter().map(|e| e.0))
            .min();
        if pending.is_some() {
            return pending;
        }
        self.st.next_observable()
    }

    fn set_clocks(&mut self, now: Time, clocks: &Clocks) {
        let hz = self.cfg.clock.hz(clocks);
        if hz == self.hz {
            return;
        }
        // Finish with the old clock up to `now`; the new clock's edges start at `now`, and the
        // prescaler counter keeps its count.
        let mut pending = std::mem::take(&mut self.pending);
        self.st.run(now, &mut pending);
        self.pending = pending;
        self.hz = hz;
        self.clock_error = None;
        self.st.tick = if hz == 0 {
            0
        } else if !TICKS_PER_S.is_multiple_of(hz) {
            self.clock_error = Some(format!(
                "{} kernel clock {hz} Hz does not divide the 3.6 GHz master clock",
                self.cfg.name
            ));
            0
        } else {
            ticks_per_cycle(hz)
        };
        self.st.origin = now;
        self.st.at = now;
    }

    fn irq_lines(&self, raise: &mut dyn FnMut(u16)) {
        let bits = self.st.irq_bits();
        let up = bits & SR_UIF != 0;
        let cc = bits & !SR_UIF != 0;
        if up {
            raise(self.cfg.irq_up);
        }
        if cc && !(up && self.cfg.irq_cc == self.cfg.irq_up) {
            raise(self.cfg.irq_cc);
        }
    }

    fn reset(&mut self, now: Time) {
        let mut pending = std::mem::take(&mut self.pending);
        self.st.run(now, &mut pending);
        let (level, trgi) = (self.st.core.level, self.st.core.trgi_high);
        self.st.core = Core::reset(self.st.modulus);
        self.st.core.level = level;
        self.st.core.trgi_high = trgi;
        // Outputs fall with the reset; recorded channels show it.
        self.st.update_levels(now, &mut pending);
        self.pending = pending;
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
    //! Expected times are worked out by hand from the manual's timing rules: the counter changes
    //! (PSC + 1) kernel cycles after the previous change, wraps to 0 after ARR (UEV there), and a
    //! kernel cycle is 3.6 GHz / f master ticks: 40 at 90 MHz, 20 at 180 MHz, 80 at 45 MHz.
    use super::*;

    thread_local! {
        /// Counter steps carried out (`apply_step`), real or looked ahead: the cost measure.
        pub(super) static STEPS: std::cell::Cell<u64> = const { std::cell::Cell::new(0) };
    }
    fn steps() -> u64 {
        STEPS.with(|n| n.replace(0))
    }

    const ALL: u32 = 0xFFFF_FFFF;
    const MHZ: u64 = 1_000_000;
    /// Master ticks per microsecond.
    const US: u64 = 3600;

    // CCMR channel-byte values (RM0390 §17.4.7): OCxM in bits 6:4, OCxPE bit 3.
    const FROZEN: u32 = 0x00;
    const TOGGLE: u32 = 0x30;
    const FORCE_INACTIVE: u32 = 0x40;
    const PWM1: u32 = 0x60;
    const PWM2: u32 = 0x70;
    const OCPE: u32 = 0x08;
    const DIER_UIE: u32 = 1 << 0;

    /// A timer with its log of everything it signalled.
    struct H {
        t: Timer,
        log: Signals,
    }

    impl H {
        fn new(number: u8, hz: u64) -> Self {
            let (bits, advanced, clock, irq_up, irq_cc, name) = match number {
                1 => (16, true, ClockDomain::TimApb2, 25, 27, "TIM1"),
                2 => (32, false, ClockDomain::TimApb1, 28, 28, "TIM2"),
                3 => (16, false, ClockDomain::TimApb1, 29, 29, "TIM3"),
                4 => (16, false, ClockDomain::TimApb1, 30, 30, "TIM4"),
                8 => (16, true, ClockDomain::TimApb2, 44, 46, "TIM8"),
                _ => unreachable!(),
            };
            let mut t = Timer::new(TimerConfig {
                number,
                bits,
                advanced,
                clock,
                name,
                irq_up,
                irq_cc,
                itr1: (number == 8).then_some(2),
            });
            t.set_clocks(
                0,
                &Clocks {
                    tim_apb1_hz: hz,
                    tim_apb2_hz: hz,
                    ..Default::default()
                },
            );
            H {
                t,
                log: Signals::default(),
            }
        }
        /// Full-word write; returns whether it asked for a re-plan.
        fn w(&mut self, now: Time, off: u32, v: u32) -> bool {
            let mut s = Signals::default();
            self.t.write(now, off, v, ALL, &mut s).unwrap();
            self.take(s)
        }
        fn r(&mut self, now: Time, off: u32) -> u32 {
            let mut s = Signals::default();
            let v = self.t.read(now, off, &mut s).unwrap();
            self.take(s);
            v
        }
        fn adv(&mut self, now: Time) {
            let mut s = Signals::default();
            self.t.advance(now, &mut s);
            self.take(s);
        }
        fn take(&mut self, mut s: Signals) -> bool {
            self.log.levels.append(&mut s.levels);
            self.log.events.append(&mut s.events);
            s.replan
        }
        /// Edges of `channel` logged so far, then forget them.
        fn edges(&mut self, channel: u8) -> Vec<(Time, bool)> {
            let e = self
                .log
                .levels
                .iter()
                .filter(|l| l.channel == channel)
                .map(|l| (l.at, l.high))
                .collect();
            self.log.levels.retain(|l| l.channel != channel);
            e
        }
        fn trgos(&mut self) -> Vec<Time> {
            let timer = self.t.cfg.number;
            let e = self
                .log
                .events
                .iter()
                .filter(|e| e.1 == Event::Trgo { timer })
                .map(|e| e.0)
                .collect();
            self.log.events.clear();
            e
        }
        fn irqs(&self) -> Vec<u16> {
            let mut v = Vec::new();
            self.t.irq_lines(&mut |n| v.push(n));
            v
        }
        fn write_err(&mut self, now: Time, off: u32, v: u32) -> Unmodelled {
            let mut s = Signals::default();
            self.t.write(now, off, v, ALL, &mut s).unwrap_err()
        }
    }

    /// `BurstGate::new` (firmware/src/rf.rs): both lines force-inactive, preloaded, enabled; ARPE.
    fn burst_gate_new(h: &mut H) {
        h.w(0, CR1, 0);
        h.w(0, CCMR1, FORCE_INACTIVE | OCPE);
        h.w(0, CCMR2, FORCE_INACTIVE | OCPE);
        h.w(0, CCER, 0x101);
        h.w(0, CR1, CR1_ARPE);
    }

    /// `BurstGate::start` / `pulse` register sequence up to (not including) the final mode/CEN.
    fn burst_load(h: &mut H, now: Time, opm: bool, psc: u32, arr: u32, ccr: u32) {
        let opm = if opm { CR1_OPM } else { 0 };
        h.w(now, CR1, CR1_ARPE); // stop
        h.w(now, CCMR1, FORCE_INACTIVE | OCPE);
        h.w(now, CCMR2, FORCE_INACTIVE | OCPE);
        h.w(now, CR1, CR1_ARPE | opm);
        h.w(now, PSC, psc);
        h.w(now, ARR, arr);
        h.w(now, CCR1, ccr);
        h.w(now, CCR1 + 8, ccr);
        h.w(now, CNT, 0);
        h.w(now, CR1, CR1_ARPE | opm | CR1_URS); // generate_update_event
        h.w(now, EGR, EGR_UG);
        h.w(now, CR1, CR1_ARPE | opm);
    }

    #[test]
    fn pwm_edges_land_on_the_counter_changes() {
        // TIM2 at 90 MHz (40 ticks), PSC = 2 → CNT changes every 120 ticks; ARR = 4 → period 600;
        // CCR1 = 2, PWM mode 1: high for CNT 0..1, low from CNT = 2 (t = 240) to the wrap (600).
        let mut h = H::new(2, 90 * MHZ);
        h.t.record_channel(1, true);
        h.w(0, PSC, 2);
        h.w(0, ARR, 4);
        h.w(0, CCR1, 2);
        h.w(0, EGR, EGR_UG); // PSC is always preloaded
        h.w(0, SR, 0);
        h.w(0, CCMR1, PWM1); // frozen → PWM1: OC1REF = (0 < 2) at once
        h.w(0, CCER, 1);
        assert_eq!(h.edges(1), vec![(0, true)]);
        h.w(0, CR1, CR1_CEN);
        h.adv(1500);
        assert_eq!(
            h.edges(1),
            vec![
                (240, false),
                (600, true),
                (840, false),
                (1200, true),
                (1440, false)
            ]
        );
        // CNT: 12 changes by t = 1440 → 12 mod 5 = 2; the 13th at 1560.
        assert_eq!(h.r(1500, CNT), 2);
        assert_eq!(h.r(1559, CNT), 2);
        assert_eq!(h.r(1560, CNT), 3);
        // CC1IF at each CNT = 2, UIF at each wrap; channels 2–4 are output channels (CCxS = 00)
        // with CCR = 0, so they match at every wrap to 0 and set CC2IF–CC4IF too.
        assert_eq!(h.r(1560, SR), 0b1_1111);
    }

    #[test]
    fn preloaded_arr_and_ccr_wait_for_the_update() {
        // ARPE and OC1PE: PSC 0, ARR 9, CCR1 5 → period 400 ticks, low from 200.
        let mut h = H::new(2, 90 * MHZ);
        h.t.record_channel(1, true);
        h.w(0, CR1, CR1_ARPE);
        h.w(0, CCMR1, PWM1 | OCPE);
        h.w(0, ARR, 9);
        h.w(0, CCR1, 5);
        h.w(0, EGR, EGR_UG);
        h.w(0, CCER, 1);
        h.w(0, CR1, CR1_ARPE | CR1_CEN);
        // Mid second period (CNT = 12 mod 10 = 2): new ARR 19, CCR1 15.
        h.w(500, ARR, 19);
        h.w(500, CCR1, 15);
        assert_eq!(h.r(700, ARR), 19, "reads return the preload register");
        assert_eq!(h.r(700, CNT), 7, "the running period still wraps at 9");
        h.adv(1700);
        // Old period finishes (low at CNT 5 = 600, wrap at 800); then 20-cycle period, low at 15.
        assert_eq!(
            h.edges(1),
            vec![
                (0, true),
                (200, false),
                (400, true),
                (600, false),
                (800, true),
                (1400, false),
                (1600, true)
            ]
        );
    }

    #[test]
    fn unbuffered_arr_write_acts_at_once() {
        // ARPE = 0: at t = 200 (CNT = 5) ARR 9 → 6: the wrap comes after CNT = 6, at 280.
        let mut h = H::new(2, 90 * MHZ);
        h.w(0, ARR, 9);
        h.w(0, DIER, DIER_UIE);
        h.w(0, CR1, CR1_CEN);
        h.w(200, ARR, 6);
        assert_eq!(h.t.next_event(), Some(280));
    }

    #[test]
    fn a_pending_preload_moves_the_next_compare() {
        // ARR 9 (400-tick period); CCR1 = 20 > ARR never matches, so with CC1IE alone nothing
        // will happen. A preloaded CCR1 = 5 written at 100 loads at the wrap (400) and matches
        // 5 changes later: 400 + 5 × 40 = 600. The write of a mere preload register re-plans.
        let mut h = H::new(2, 90 * MHZ);
        h.w(0, CCMR1, FROZEN | OCPE);
        h.w(0, ARR, 9);
        h.w(0, CCR1, 20);
        h.w(0, EGR, EGR_UG);
        h.w(0, DIER, 0b10);
        h.w(0, SR, 0);
        h.w(0, CR1, CR1_CEN);
        assert_eq!(h.t.next_event(), None);
        assert!(h.w(100, CCR1, 5));
        assert_eq!(h.t.next_event(), Some(600));
        h.adv(600);
        assert_eq!(h.irqs(), vec![28]);
    }

    #[test]
    fn udis_bracket_holds_the_shadows() {
        let mut h = H::new(2, 90 * MHZ);
        h.t.record_channel(1, true);
        h.w(0, CR1, CR1_ARPE);
        h.w(0, CCMR1, PWM1 | OCPE);
        h.w(0, ARR, 9);
        h.w(0, CCR1, 5);
        h.w(0, EGR, EGR_UG);
        h.w(0, SR, 0);
        h.w(0, CCER, 1);
        h.w(0, CR1, CR1_ARPE | CR1_CEN);
        h.w(100, CR1, CR1_ARPE | CR1_CEN | CR1_UDIS);
        h.w(100, ARR, 19);
        h.w(100, CCR1, 15);
        h.adv(2100);
        // Wraps at 400, 800, … keep the old period: no UEV, so no shadow load and no UIF.
        h.w(2100, CR1, CR1_ARPE | CR1_CEN);
        assert_eq!(h.r(2300, SR) & SR_UIF, 0);
        assert_eq!(
            h.r(2400, SR) & SR_UIF,
            1,
            "first wrap after UDIS cleared is an update"
        );
        h.adv(3300);
        let mut expect = vec![(0, true)];
        for k in 0..5 {
            expect.push((200 + 400 * k, false));
            expect.push((400 + 400 * k, true));
        }
        expect.extend([(2200, false), (2400, true), (3000, false), (3200, true)]);
        assert_eq!(h.edges(1), expect);
    }

    #[test]
    fn force_inactive_to_pwm1_skips_the_first_period() {
        // The firmware's BurstGate::start: force-inactive, UG at CNT = 0, then PWM mode 1.
        // 0 < CCR already holds, so the comparison does not change and OC1REF stays low until the
        // wrap (RM0390 §17.3.9): the first period's pulse is lost.
        let mut h = H::new(2, 90 * MHZ);
        h.t.record_channel(1, true);
        h.t.record_channel(3, true);
        burst_gate_new(&mut h);
        burst_load(&mut h, 0, false, 0, 9, 4);
        assert_eq!(h.r(0, SR), 0, "UG under URS sets no UIF");
        h.w(0, CCMR1, PWM1 | OCPE);
        h.w(0, CCMR2, PWM1 | OCPE);
        h.w(0, CR1, CR1_ARPE | CR1_CEN);
        h.adv(1000);
        let expect = vec![(400, true), (560, false), (800, true), (960, false)];
        assert_eq!(h.edges(1), expect);
        assert_eq!(h.edges(3), expect);
    }

    #[test]
    fn frozen_to_pwm1_starts_at_once() {
        // Same load, but from frozen: the switch itself sets OC1REF = (0 < 4).
        let mut h = H::new(2, 90 * MHZ);
        h.t.record_channel(1, true);
        burst_gate_new(&mut h);
        burst_load(&mut h, 0, false, 0, 9, 4);
        h.w(0, CCMR1, FROZEN | OCPE);
        h.w(0, CCMR1, PWM1 | OCPE);
        h.w(0, CR1, CR1_ARPE | CR1_CEN);
        h.adv(1000);
        assert_eq!(
            h.edges(1),
            vec![
                (0, true),
                (160, false),
                (400, true),
                (560, false),
                (800, true),
                (960, false)
            ]
        );
    }

    #[test]
    fn one_pulse_pwm2_with_delay_ends_low_and_stops() {
        // BurstGate::pulse(psc 2, ccr 5): ARR = 5, CCR = 1, PWM mode 2, OPM. CNT changes every
        // 120 ticks: high from CNT = 1 (120) through CNT = 5, low at the wrap (720) where the
        // update clears CEN: 5 counter ticks high.
        let mut h = H::new(2, 90 * MHZ);
        h.t.record_channel(1, true);
        burst_gate_new(&mut h);
        burst_load(&mut h, 0, true, 2, 5, 1);
        h.w(0, CCMR1, PWM2 | OCPE);
        h.w(0, CCMR2, PWM2 | OCPE);
        h.w(0, CR1, CR1_ARPE | CR1_OPM | CR1_CEN);
        assert_eq!(h.t.next_event(), Some(120));
        h.adv(10_000);
        assert_eq!(h.edges(1), vec![(120, true), (720, false)]);
        assert_eq!(h.r(10_000, CR1) & CR1_CEN, 0);
        assert_eq!(h.r(10_000, CNT), 0);
        assert_eq!(h.r(10_000, SR) & SR_UIF, 1, "the overflow update sets UIF");
        assert_eq!(h.t.next_event(), None);
        assert!(!h.t.channel_level(1));
    }

    /// A delayed one-pulse as `BurstGate::pulse` writes it since #17 (RM0390 §17.3.10 One-pulse
    /// mode: "tDELAY is defined by the value written in TIMx_CCR1", the pulse lasts
    /// ARR − CCR1 + 1; PWM mode 2, §17.3.9: OCxREF low while CNT < CCRx, high from CCRx):
    /// settings arr 9, ccr 4 → ARR = 9, CCR = arr + 1 − ccr = 6. The line is low for CNT = 0..=5
    /// (6 ticks), high for CNT = 6..=9 (4 ticks), low at the wrap where the update event clears
    /// CEN; TRGO in enable mode is high from CEN to that update. At PSC 0 and PSC 2 (a tick of
    /// 40 and 120 master ticks), and CCR anywhere in 1..=ARR: high for exactly the last
    /// ARR + 1 − CCR ticks.
    #[test]
    fn one_pulse_pwm2_rises_at_ccr_anywhere_in_the_count() {
        for (psc, arr, ccr_reg) in [
            (0u32, 9u32, 6u32),
            (2, 9, 6),
            (0, 9, 1),
            (0, 9, 9),
            (1, 40_499, 4_500),
        ] {
            let tick = 40 * (psc as u64 + 1);
            let mut h = H::new(2, 90 * MHZ);
            h.t.record_channel(1, true);
            h.t.record_channel(3, true);
            burst_gate_new(&mut h);
            h.w(0, CR2, 0b001 << 4);
            burst_load(&mut h, 0, true, psc, arr, ccr_reg);
            h.w(0, CCMR1, PWM2 | OCPE);
            h.w(0, CCMR2, PWM2 | OCPE);
            h.log.events.clear();
            h.w(0, CR1, CR1_ARPE | CR1_OPM | CR1_CEN);
            h.adv(tick * (arr as u64 + 10));
            let rise = tick * ccr_reg as u64;
            let fall = tick * (arr as u64 + 1);
            let want = vec![(rise, true), (fall, false)];
            assert_eq!(h.edges(1), want, "psc {psc} arr {arr} ccr {ccr_reg}");
            assert_eq!(h.edges(3), want, "CH3 the same");
            let lv: Vec<(Time, bool)> = h
                .log
                .events
                .iter()
                .filter_map(|e| match e.1 {
                    Event::TrgoLevel { timer: 2, high } => Some((e.0, high)),
                    _ => None,
                })
                .collect();
            assert_eq!(lv, vec![(0, true), (fall, false)], "TRGO = CNT_EN");
            assert_eq!(h.r(fall + 1, CR1) & CR1_CEN, 0, "stopped at the update");
            assert_eq!(h.r(fall + 1, CNT), 0);
            assert!(!h.t.channel_level(1));
        }
    }

    /// `set_drive` during a delayed pulse: CH3 switched from force-inactive to PWM mode 2 while
    /// CNT < CCR rises with CH1 at CNT = CCR (the comparison changes there); switched after the
    /// rise it stays low (the next change is the update event, to low) — RM0390 §17.3.9's rule.
    #[test]
    fn one_pulse_pwm2_channel_switched_on_mid_count() {
        for (switch_at, want3) in [(120, vec![(240, true), (400, false)]), (280, vec![])] {
            let mut h = H::new(2, 90 * MHZ);
            h.t.record_channel(1, true);
            h.t.record_channel(3, true);
            burst_gate_new(&mut h);
            burst_load(&mut h, 0, true, 0, 9, 6);
            h.w(0, CCMR1, PWM2 | OCPE);
            h.w(0, CR1, CR1_ARPE | CR1_OPM | CR1_CEN);
            h.adv(switch_at);
            h.w(switch_at, CCMR2, PWM2 | OCPE);
            h.adv(10_000);
            assert_eq!(h.edges(1), vec![(240, true), (400, false)]);
            assert_eq!(h.edges(3), want3, "CH3 switched on at {switch_at}");
        }
    }

    #[test]
    fn trgo_on_update_at_10_khz() {
        // The boards' ADC trigger: TIM3 at 90 MHz, PSC 0, ARR 8999 → 9000 cycles = 360 000 ticks
        // (100 µs). CEN at 1010 starts on the next kernel edge, 1040.
        let mut h = H::new(3, 90 * MHZ);
        h.w(0, PSC, 0);
        h.w(0, ARR, 8999);
        h.w(0, CR1, CR1_URS);
        h.w(0, EGR, EGR_UG);
        h.w(0, CR1, 0);
        h.w(0, CR2, 0b010 << 4);
        h.trgos();
        assert!(h.w(1010, CR1, CR1_CEN), "starting the counter re-plans");
        assert_eq!(h.t.next_event(), Some(1040 + 360_000));
        h.adv(1040 + 10 * 360_000);
        assert_eq!(
            h.trgos(),
            (1..=10).map(|k| 1040 + k * 360_000).collect::<Vec<_>>()
        );
        assert!(h.irqs().is_empty(), "UIE = 0");
    }

    #[test]
    fn ug_in_reset_master_mode_pulses_trgo() {
        // MMS = 000: the UG bit is TRGO (RM0390 §17.4.2) — set_max_compare_value's UG on TIM3
        // before set_master_mode(UPDATE) does this.
        let mut h = H::new(3, 90 * MHZ);
        h.w(500, CR1, CR1_URS);
        h.w(500, EGR, EGR_UG);
        assert_eq!(h.trgos(), vec![500]);
        // Update mode: a UG is an update; with UDIS no update, so no TRGO.
        h.w(600, CR2, 0b010 << 4);
        h.w(600, EGR, EGR_UG);
        assert_eq!(h.trgos(), vec![600]);
        h.w(700, CR1, CR1_UDIS);
        h.w(700, EGR, EGR_UG);
        assert_eq!(h.trgos(), Vec::<Time>::new());
    }

    #[test]
    fn ug_sets_uif_unless_urs() {
        let mut h = H::new(3, 90 * MHZ);
        h.w(0, EGR, EGR_UG);
        assert_eq!(h.r(0, SR), SR_UIF);
        h.w(0, SR, 0);
        h.w(0, CR1, CR1_URS);
        h.w(0, EGR, EGR_UG);
        assert_eq!(h.r(0, SR), 0);
    }

    /// embassy-stm32 time_driver/gp16.rs init on TIM4: 1 MHz counter, ARR 0xFFFF, CCR1 0x8000.
    fn time_driver_init(h: &mut H) {
        h.w(0, CR1, 0);
        h.w(0, CNT, 0);
        h.w(0, PSC, 89);
        h.w(0, ARR, 0xFFFF);
        h.w(0, CR1, CR1_URS);
        h.w(0, EGR, EGR_UG);
        h.w(0, CR1, 0);
        h.w(0, CCR1, 0x8000);
        h.w(0, DIER, 0b011);
        h.w(0, CR1, CR1_CEN);
    }

    #[test]
    fn cnt_reads_follow_virtual_time() {
        // 90 MHz / 90 = 1 MHz: CNT = whole µs since start, mod 2^16.
        let mut h = H::new(4, 90 * MHZ);
        time_driver_init(&mut h);
        assert_eq!(h.r(0, SR), 0);
        assert_eq!(h.r(12_345 * US + 3599, CNT), 12_345);
        assert_eq!(h.r(12_346 * US, CNT), 12_346);
        assert_eq!(h.r(70_000 * US, CNT), 70_000 - 65_536);
        // Half-period compare at 32 768 µs and the overflow at 65 536 µs both happened (and the
        // unused channels' CCR = 0 matched at the wrap; CC2IE–CC4IE are off).
        assert_eq!(h.r(70_000 * US, SR), 0b1_1111);
        assert_eq!(h.irqs(), vec![30]);
    }

    #[test]
    fn time_driver_alarm_fires_at_its_count() {
        let mut h = H::new(4, 90 * MHZ);
        time_driver_init(&mut h);
        assert_eq!(h.t.next_event(), Some(0x8000 * US));
        // set_alarm at 1000 µs for 1500: CCR2 (unbuffered), CC2IE.
        h.w(1000 * US, CCR1 + 4, 1500);
        assert!(h.w(1000 * US, DIER, 0b111));
        assert_eq!(h.t.next_event(), Some(1500 * US));
        h.adv(1500 * US - 1);
        assert_eq!(h.r(1500 * US - 1, SR), 0);
        h.adv(1500 * US);
        assert_eq!(h.r(1500 * US, SR), 0b100);
        assert_eq!(h.irqs(), vec![30]);
        // on_interrupt: SR = !sr clears exactly the flags it saw.
        h.w(1500 * US, SR, !0b100);
        assert!(h.irqs().is_empty());
        assert_eq!(h.t.next_event(), Some(0x8000 * US));
    }

    /// firmware Carrier::start on TIM1 at 180 MHz: PSC 0, ARR 11, CCR1 6 → 15 MHz, 50 %.
    fn carrier_start(h: &mut H, moe: bool) {
        carrier_start_at(h, 0, moe);
    }

    /// The same at `now`: ends with CR1 = 0x81, CCMR1 = 0x68, CCER = 0x1, BDTR = 0x8000 (MOE).
    fn carrier_start_at(h: &mut H, now: Time, moe: bool) {
        h.w(now, PSC, 0);
        h.w(now, CR1, CR1_ARPE);
        h.w(now, CCMR1, PWM1);
        h.w(now, CCMR1, PWM1 | OCPE);
        h.w(now, CCR1, 6);
        h.w(now, ARR, 11);
        h.w(now, CR1, CR1_ARPE | CR1_URS);
        h.w(now, EGR, EGR_UG);
        h.w(now, CR1, CR1_ARPE);
        h.w(now, CCER, 1);
        if moe {
            h.w(now, BDTR, BDTR_MOE);
        }
        h.w(now, CR1, CR1_ARPE | CR1_CEN);
    }

    /// Drives the timer as the board does: to each `next_event` up to `end`, then to `end`.
    /// Returns the number of `advance` calls.
    fn board_advance(h: &mut H, end: Time) -> u64 {
        let mut calls = 1;
        while let Some(n) = h.t.next_event().filter(|&n| n <= end) {
            h.adv(n);
            calls += 1;
        }
        h.adv(end);
        calls
    }

    #[test]
    fn recording_switched_on_late_starts_at_the_present() {
        // The board's carrier window: TIM1 started long before and never advanced (nothing
        // observable), recording switched on at 10 ms = 36 000 000 ticks. The kernel edges are
        // 20 ticks apart; CEN at 1 234 570 counts from the next edge, 1 234 580. CNT(t) =
        // ⌊(t − 1 234 580) / 20⌋ mod 12: at 36 000 000 that is 1 738 271 changes, the last exactly
        // then, 1 738 271 mod 12 = 11 ≥ CCR1 = 6 → low. Then CNT 0 at +20 (high), CNT 6 at +140
        // (low), … an edge every 120 ticks. With `record_channel` the timer, caught up only at the
        // next advance, emitted its edges since 1 234 580 — in the past.
        let mut h = H::new(1, 180 * MHZ);
        carrier_start_at(&mut h, 1_234_570, true);
        h.trgos();
        assert_eq!(h.t.next_event(), None, "unrecorded: nothing observable");
        let on = 36_000_000;
        let mut s = Signals::default();
        h.t.record_channel_at(on, 1, true, &mut s);
        assert!(s.replan);
        h.take(s);
        assert!(h.log.levels.is_empty(), "nothing emitted up to the switch");
        assert!(!h.t.channel_level(1));
        assert_eq!(h.t.next_event(), Some(on + 20));
        // 20 µs = 72 000 ticks: edges at on + 20 + 120 k ≤ on + 72 000, k = 0..=599.
        let off = on + 72_000;
        steps();
        let calls = board_advance(&mut h, off);
        let cost = steps();
        let expect: Vec<(Time, bool)> = (0..600).map(|k| (on + 20 + 120 * k, k % 2 == 0)).collect();
        assert_eq!(h.edges(1), expect);
        let mut s = Signals::default();
        h.t.record_channel_at(off, 1, false, &mut s);
        h.take(s);
        assert!(h.log.levels.is_empty());
        // Switched off: no carrier edge is reported or emitted any more.
        assert_eq!(h.t.next_event(), None);
        h.adv(on + super::super::TICKS_PER_S);
        assert!(h.log.levels.is_empty() && h.log.events.is_empty());
        eprintln!("20 µs recorded 15 MHz carrier: {calls} advance calls, {cost} steps");
    }

    #[test]
    fn cost_of_an_unrecorded_second() {
        use super::super::TICKS_PER_S;
        let mut h = H::new(1, 180 * MHZ);
        carrier_start(&mut h, true);
        steps();
        assert_eq!(h.t.next_event(), None);
        let lookahead = steps();
        let calls = board_advance(&mut h, TICKS_PER_S);
        let cost = steps();
        assert_eq!(calls, 1);
        // 180 000 000 kernel edges by 1 s, a multiple of 12: CNT 0.
        assert_eq!(h.r(TICKS_PER_S, CNT), 0);
        assert!(cost < 100 && lookahead < 100, "{cost} / {lookahead} steps");
        eprintln!(
            "1 s unrecorded carrier: {calls} advance call, {cost} steps (+{lookahead} per next_event)"
        );
    }

    #[test]
    fn moe_gates_advanced_outputs() {
        let mut h = H::new(1, 180 * MHZ);
        h.t.record_channel(1, true);
        carrier_start(&mut h, false);
        h.adv(999);
        assert!(h.edges(1).is_empty(), "MOE = 0: output not driven");
        // t = 1000: 50 counter changes (20 ticks each) → CNT 2 < 6, OC1REF high.
        h.w(1000, BDTR, BDTR_MOE);
        h.adv(1250);
        // Low at CNT 6 (change 54 → 1080), high at the wrap (change 60 → 1200).
        assert_eq!(h.edges(1), vec![(1000, true), (1080, false), (1200, true)]);
        h.w(1300, BDTR, 0); // CNT 5: OC1REF high, output drops
        h.adv(2000);
        assert_eq!(h.edges(1), vec![(1300, false)]);
    }

    #[test]
    fn unrecorded_carrier_costs_nothing_and_stays_exact() {
        use super::super::TICKS_PER_S;
        let mut h = H::new(1, 180 * MHZ);
        carrier_start(&mut h, true);
        assert_eq!(h.trgos(), vec![0], "UG with MMS = 000");
        assert_eq!(h.t.next_event(), None, "nothing observable");
        assert!(
            !h.w(10, PSC, 0),
            "a write that changes nothing observable does not re-plan"
        );
        // One second is 15 million periods; the steady cycle is skipped arithmetically.
        h.adv(TICKS_PER_S);
        assert!(h.log.levels.is_empty() && h.log.events.is_empty());
        // 180 000 000 changes by 1 s (a multiple of 12): CNT 0; 7 changes later CNT 7.
        assert_eq!(h.r(TICKS_PER_S + 140, CNT), 7);
        assert!(!h.t.channel_level(1), "CNT 7 ≥ 6: low");
        h.t.record_channel(1, true);
        assert_eq!(h.t.next_event(), Some(TICKS_PER_S + 240));
        h.adv(TICKS_PER_S + 480);
        assert_eq!(
            h.edges(1),
            vec![
                (TICKS_PER_S + 240, true),
                (TICKS_PER_S + 360, false),
                (TICKS_PER_S + 480, true)
            ]
        );
        h.t.record_channel(1, false);
        h.adv(2 * TICKS_PER_S);
        assert!(h.edges(1).is_empty());
    }

    #[test]
    fn toggle_parity_survives_the_skip() {
        use super::super::TICKS_PER_S;
        // Toggle on CNT = 3, ARR 9, 90 MHz: toggles at change 3 + 10k (k ≥ 0), 40 ticks each.
        // By 1 s − 1 (89 999 999 changes): k ≤ 8 999 999 → 9 000 000 toggles → low again.
        let mut h = H::new(2, 90 * MHZ);
        h.w(0, ARR, 9);
        h.w(0, CCR1, 3);
        h.w(0, CCMR1, TOGGLE);
        h.w(0, CCER, 1);
        h.w(0, CR1, CR1_CEN);
        h.adv(TICKS_PER_S - 1);
        assert!(!h.t.channel_level(1));
        h.adv(TICKS_PER_S + 120); // change 90 000 003: one more toggle
        assert!(h.t.channel_level(1));
    }

    #[test]
    fn repetition_counter_spaces_updates() {
        // TIM1, ARR 9, RCR 2 at 180 MHz: overflows every 200 ticks, UEV every third (600).
        let mut h = H::new(1, 180 * MHZ);
        h.w(0, ARR, 9);
        h.w(0, RCR, 2);
        h.w(0, EGR, EGR_UG); // loads the repetition counter
        h.w(0, SR, 0);
        h.w(0, DIER, DIER_UIE);
        h.w(0, CR1, CR1_CEN);
        assert_eq!(h.t.next_event(), Some(600));
        assert_eq!(h.r(599, SR) & SR_UIF, 0);
        assert_eq!(h.r(600, SR) & SR_UIF, SR_UIF);
        // CC1IF–CC4IF (CCR = 0 matches at each wrap) are set but not enabled.
        assert_eq!(h.irqs(), vec![25]);
    }

    #[test]
    fn clock_change_while_counting() {
        // TIM2 90 MHz, ARR 999: at 20 000 ticks CNT = 500; the clock halves to 45 MHz (80 ticks).
        let mut h = H::new(2, 90 * MHZ);
        h.w(0, ARR, 999);
        h.w(0, DIER, DIER_UIE);
        h.w(0, CR1, CR1_CEN);
        h.t.set_clocks(
            20_000,
            &Clocks {
                tim_apb1_hz: 45 * MHZ,
                ..Default::default()
            },
        );
        assert_eq!(h.t.frequency_hz(), 45 * MHZ);
        assert_eq!(h.r(28_000, CNT), 600);
        // 500 more changes of 80 ticks to the wrap.
        assert_eq!(h.t.next_event(), Some(60_000));
        assert_eq!(h.r(59_999, SR) & SR_UIF, 0);
        assert_eq!(h.r(60_000, SR) & SR_UIF, SR_UIF);
    }

    #[test]
    fn sr_is_write_zero_to_clear() {
        let mut h = H::new(3, 90 * MHZ);
        h.w(0, EGR, EGR_UG | 0b10); // UG and CC1G
        assert_eq!(h.r(0, SR), 0b11);
        h.w(0, SR, !0b10);
        assert_eq!(h.r(0, SR), SR_UIF);
        let mut s = Signals::default();
        h.t.write(0, SR, 0, 0xFFFF_0000, &mut s).unwrap(); // upper halfword only
        assert_eq!(h.r(0, SR), SR_UIF);
    }

    #[test]
    fn unmodelled_accesses_fail_loudly() {
        let mut h = H::new(2, 90 * MHZ);
        assert!(h.write_err(0, CR1, CR1_DIR).why.contains("DIR"));
        assert_eq!(h.r(0, CR1), 0, "a refused write changes nothing");
        assert!(h.write_err(0, CR1, 1 << 5).why.contains("CMS"));
        assert!(h.write_err(0, CCMR1, 0x01).why.contains("input capture"));
        assert!(h.write_err(0, CCMR1, 1 << 16).why.contains("OC1M[3]"));
        assert!(h.write_err(0, CCMR2, 0x80 << 8).why.contains("OC4CE"));
        assert!(h.write_err(0, SMCR, 0b100).why.contains("ITR1"));
        assert!(h.write_err(0, CR2, 0b011 << 4).why.contains("MMS"));
        assert!(h.write_err(0, DIER, 1 << 8).why.contains("DIER"));
        assert!(h.write_err(0, CCER, 1 << 2).why.contains("CC1NE"));
        assert!(
            h.write_err(0, BDTR, BDTR_MOE).why.contains("offset 0x44"),
            "no BDTR on TIM2"
        );
        let mut s = Signals::default();
        assert!(h.t.read(0, DCR_F4, &mut s).unwrap_err().why.contains("DCR"));
        h.w(0, CCMR1, PWM1);
        assert!(h
            .write_err(0, CCMR1, PWM2)
            .why
            .contains("PWM modes 1 and 2"));
        let mut t1 = H::new(1, 180 * MHZ);
        assert!(t1.write_err(0, BDTR, BDTR_MOE | 0x40).why.contains("BDTR"));
    }

    const SMCR_ITR1_RESET: u32 = (1 << 4) | SMS_RESET;
    const SMCR_ITR1_GATED: u32 = (1 << 4) | SMS_GATED;

    fn level(h: &mut H, t: Time, high: bool) {
        let mut s = Signals::default();
        h.t.on_event(t, Event::TrgoLevel { timer: 2, high }, &mut s);
        if high {
            h.t.on_event(t, Event::Trgo { timer: 2 }, &mut s);
        }
        h.take(s);
    }

    #[test]
    fn slave_reset_mode_turns_a_master_trgo_into_an_update_and_trgo() {
        // TIM8 at 180 MHz (20 ticks), PSC = ARR = 0xFFFF, TRGO on update, reset mode on ITR1.
        let mut h = H::new(8, 180 * MHZ);
        h.w(0, PSC, 0xFFFF);
        h.w(0, ARR, 0xFFFF);
        h.w(0, CR2, 0b010 << 4);
        h.w(0, SMCR, SMCR_ITR1_RESET);
        h.w(0, CR1, CR1_CEN);
        h.trgos();
        assert_eq!(h.r(0, SMCR), SMCR_ITR1_RESET);
        let mut s = Signals::default();
        // Another timer's TRGO is not ITR1.
        h.t.on_event(1000, Event::Trgo { timer: 3 }, &mut s);
        h.take(s);
        assert!(h.trgos().is_empty());
        let mut s = Signals::default();
        h.t.on_event(5000, Event::Trgo { timer: 2 }, &mut s);
        assert!(s.replan);
        h.take(s);
        assert_eq!(
            h.trgos(),
            vec![5000],
            "reset → update → TRGO at the master's TRGO"
        );
        assert_eq!(h.r(5000, SR) & (SR_UIF | SR_TIF), SR_UIF | SR_TIF);
        // Counter and prescaler re-initialised: CNT 0 until 65 536 kernel clocks later.
        assert_eq!(h.r(5000 + 65_535 * 20, CNT), 0);
        assert_eq!(h.r(5000 + 65_536 * 20 + 20, CNT), 1);
        // Without a slave mode the master's TRGO does nothing.
        h.w(2_000_000, SMCR, 0);
        let mut s = Signals::default();
        h.t.on_event(2_000_000, Event::Trgo { timer: 2 }, &mut s);
        h.take(s);
        assert!(h.trgos().is_empty());
    }

    #[test]
    fn slave_gated_mode_counts_only_while_the_master_runs() {
        // Triangle envelope plan: PSC 0, ARR = step − 1 = 99, CCR1 = 50, TRGO on update.
        let mut h = H::new(8, 180 * MHZ);
        h.w(0, ARR, 99);
        h.w(0, CCR1, 50);
        h.w(0, CR2, 0b010 << 4);
        h.w(0, SMCR, SMCR_ITR1_GATED);
        h.w(0, CR1, CR1_CEN);
        h.trgos();
        assert_eq!(h.t.next_event(), None, "gate closed: nothing happens");
        assert_eq!(h.r(10_000, CNT), 0);
        // Gate opens at 10 010: counting from the next kernel edge (10 020); update after 100
        // clocks (12 020), then every 2 000 ticks.
        level(&mut h, 10_010, true);
        assert_eq!(h.r(10_010, SR) & SR_TIF, SR_TIF);
        h.adv(16_020);
        assert_eq!(h.trgos(), vec![12_020, 14_020, 16_020]);
        // Gate closes at 17_000 (CNT 49): the counter holds.
        level(&mut h, 17_000, false);
        assert_eq!(h.r(17_000, CNT), 49);
        assert_eq!(h.r(1_000_000, CNT), 49);
        assert!(h.trgos().is_empty());
        // Reopened at 1 000 000: resumes from 49, update 51 clocks later.
        level(&mut h, 1_000_000, true);
        h.adv(1_000_000 + 51 * 20);
        assert_eq!(h.trgos(), vec![1_000_000 + 51 * 20]);
    }

    #[test]
    fn cc1de_raises_a_dma_request_at_each_cc1_match() {
        let mut h = H::new(8, 180 * MHZ);
        h.w(0, ARR, 99);
        h.w(0, CCR1, 50);
        h.w(0, DIER, 1 << 9);
        h.w(0, CR1, CR1_CEN);
        h.log.events.clear();
        // CEN at 0 (a kernel edge): CNT = k at 20 k, CNT 50 at 1 000, then every 100 clocks.
        assert_eq!(h.t.next_event(), Some(1000));
        h.adv(5000);
        let req: Vec<Time> = h
            .log
            .events
            .iter()
            .filter(|e| {
                e.1 == Event::DmaRequest(super::super::Request::TimCc {
                    timer: 8,
                    channel: 1,
                })
            })
            .map(|e| e.0)
            .collect();
        assert_eq!(req, vec![1000, 3000, 5000]);
        assert!(
            h.write_err(0, DIER, 1 << 8).why.contains("DIER"),
            "UDE is refused"
        );
    }

    #[test]
    fn master_enable_mode_signals_cen_as_a_level() {
        // TIM2 MMS = 001, one-pulse: TRGO rises at CEN and falls at the update that clears it.
        let mut h = H::new(2, 90 * MHZ);
        h.w(0, ARR, 9);
        h.w(0, CR2, 0b001 << 4);
        h.log.events.clear();
        h.w(400, CR1, CR1_OPM | CR1_CEN);
        h.adv(10_000);
        let lv: Vec<(Time, bool)> = h
            .log
            .events
            .iter()
            .filter_map(|e| match e.1 {
                Event::TrgoLevel { timer: 2, high } => Some((e.0, high)),
                _ => None,
            })
            .collect();
        // CEN at 400 (a kernel edge): CNT 1 at 440 … 9 at 760, the wrap (update) at 800.
        assert_eq!(lv, vec![(400, true), (800, false)]);
        assert_eq!(h.trgos(), vec![400]);
    }

    #[test]
    fn unmodelled_slave_settings_are_refused() {
        let mut h = H::new(8, 180 * MHZ);
        assert!(h
            .write_err(0, SMCR, (2 << 4) | SMS_RESET)
            .why
            .contains("TS"));
        assert!(h.write_err(0, SMCR, (1 << 4) | 0b110).why.contains("SMS"));
        assert!(h.write_err(0, SMCR, 1 << 7).why.contains("MSM"));
        let mut t2 = H::new(2, 90 * MHZ);
        assert!(t2.write_err(0, SMCR, SMCR_ITR1_RESET).why.contains("none"));
    }

    #[test]
    fn unrepresentable_clock_is_refused_at_the_next_access() {
        let mut h = H::new(2, 90 * MHZ);
        h.t.set_clocks(
            0,
            &Clocks {
                tim_apb1_hz: 7 * MHZ,
                ..Default::default()
            },
        );
        let mut s = Signals::default();
        assert!(h
            .t
            .read(0, CNT, &mut s)
            .unwrap_err()
            .why
            .contains("does not divide"));
    }
}
