//! DAC1 channel 1 (the RF level output on PA4) of the STM32F446 (RM0390 §14, DAC on APB1 at
//! 0x4000_7400) and the STM32G474 (RM0440 DAC chapter, DAC1 on AHB2 at 0x5000_0800): the data holding
//! register, the data output register and its transfer rules, the trigger selection, and the
//! level the pin shows. What the firmware's RF level port and embassy-stm32 0.6's `dac` driver
//! touch is modelled; everything else is `Unmodelled`.
//!
//! Modelled (channel 1 only):
//! - CR: EN1, TEN1, TSEL1 (F446 3 bits at 5:3; G474 4 bits at 5:2), WAVE1 = 00 only (noise,
//!   triangle and the G474's sawtooth are refused), MAMP1 stored (it only matters with a wave),
//!   DMAEN1 (a DMA request at every selected trigger, see below), DMAUDRIE1 stored; F446 BOFF1
//!   (the buffer: no effect on the code the pin shows). G474 CEN1 (calibration) is refused.
//! - G474 MCR: MODE1 000/001/010 (connected to the pin, buffer on or off) and 011 (on-chip
//!   peripherals only: the pin is not driven); sample-and-hold (MODE1 1xx), DMADOUBLE1 and
//!   SINFORMAT1 are refused; HFSEL is stored (an interface timing setting, no effect here).
//!   STMODR, STR1 (sawtooth settings, no effect with WAVE1 = 00), CCR (offset trim) and the
//!   sample-and-hold time registers are stored.
//! - SWTRIGR.SWTRIG1, DHR12R1, DHR12L1, DHR8R1 (writes and reads), DOR1 (read-only), SR.DMAUDR1
//!   (rc_w1; never set: see below), G474 SR.DAC1RDY (set as EN1 is set: the wake-up time,
//!   DS12288 tWAKEUP, is not modelled).
//! - DHR → DOR (RM0390 §14.3 "DAC conversion"; RM0440 DAC chapter, "DAC conversion"; the
//!   subsection numbers were not re-read here): with TEN1 = 0 one bus clock
//!   after the DHR write; with TEN1 = 1, three bus clocks after the selected trigger (a software
//!   trigger: one clock, SWTRIG1 cleared then). The bus clock is the F446's APB1 clock (PCLK1)
//!   and the G474's dac_hclk (HCLK: DAC1 sits on AHB2). The value moved is DHR as it is at the
//!   trigger (the manual does not say whether a write inside the three clocks is taken; the
//!   firmware never writes that close to a trigger). A new trigger while a transfer is pending
//!   schedules another. Transfers happen whatever EN1 is (the digital part is clocked; not
//!   stated by the manual, not verified).
//! - Triggers (TSEL1): F446 RM0390 §14.3 "DAC trigger selection" table (number not re-read): 000 TIM6, 001 TIM8, 010 TIM7,
//!   011 TIM5, 100 TIM2, 101 TIM4, 110 EXTI9, 111 SWTRIG; G474 RM0440 DAC trigger table: 0000
//!   SWTRIG, 0001 TIM8, 0010 TIM7, 0011 TIM15, 0100 TIM2, 0101 TIM4, 0110 EXTI9, 0111 TIM6,
//!   1000 TIM3, 1001–1111 HRTIM. Both agree with stm32-metapac 21's DAC_CHX_TRGn table (the
//!   numbers embassy-stm32 programs). EXTI9 and HRTIM selections are refused with TEN1 = 1 (not
//!   modelled); a timer trigger arrives as that timer's `Event::Trgo`.
//! - DMAEN1: at each selected trigger a DMA request (`Request::Dac1Ch1`: F446 DMA1 stream 5
//!   channel 7, RM0390 table 28; G474 DMAMUX request 6, stm32-metapac 21). The underrun
//!   (DMAUDR1: a second trigger before the first request was acknowledged) is not detected: the
//!   DMA models serve a request at once or drop it, and the drop is not reported back.
//! - The pin (the reference circuit, `saw_boards::rf_level`): EN1 = 1 and the output connected
//!   → the pin shows DOR1; EN1 = 0 (or G474 MODE1 = 011) → the output is released and the
//!   divider's lower resistor pulls the gain pin to 0 V: recorded as code 0, not driven. Every
//!   change is recorded in `trace` (kept across resets).
//!
//! Channel 2, the dual registers and the G474's DAC2–DAC4 are not modelled.

use super::{
    merge, ticks_per_cycle, Clocks, Event, Peripheral, Request, Signals, Time, Unmodelled,
};
use std::any::Any;

/// Which chip's DAC.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DacChip {
    F446,
    G474,
}

const CR: u32 = 0x00;
const SWTRIGR: u32 = 0x04;
const DHR12R1: u32 = 0x08;
const DHR12L1: u32 = 0x0C;
const DHR8R1: u32 = 0x10;
const DHR12R2: u32 = 0x14;
const DHR8RD: u32 = 0x28;
const DOR1: u32 = 0x2C;
const DOR2: u32 = 0x30;
const SR: u32 = 0x34;
// G474 only (RM0440 DAC register map).
const CCR: u32 = 0x38;
const MCR: u32 = 0x3C;
const SHSR1: u32 = 0x40;
const SHRR: u32 = 0x4C;
const STR1: u32 = 0x58;
const STR2: u32 = 0x5C;
const STMODR: u32 = 0x60;

const CR_EN1: u32 = 1 << 0;
/// F446 only: output buffer disable.
const CR_BOFF1_F4: u32 = 1 << 1;
const CR_TEN1_F4: u32 = 1 << 2;
const CR_TEN1_G4: u32 = 1 << 1;
const CR_WAVE1: u32 = 3 << 6;
const CR_MAMP1: u32 = 0xF << 8;
const CR_DMAEN1: u32 = 1 << 12;
const CR_DMAUDRIE1: u32 = 1 << 13;
/// G474 only: calibration enable.
const CR_CEN1_G4: u32 = 1 << 14;

const SR_DAC1RDY_G4: u32 = 1 << 11;
const SR_DMAUDR1: u32 = 1 << 13;

const MCR_MODE1: u32 = 7;
const MCR_DMADOUBLE1: u32 = 1 << 8;
const MCR_SINFORMAT1: u32 = 1 << 9;
const MCR_HFSEL: u32 = 3 << 14;

/// What the trigger selection names.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Trigger {
    Software,
    Timer(u8),
    /// EXTI line 9 or an HRTIM output: not modelled.
    Other(&'static str),
}

/// One recorded change of the level the pin shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DacSample {
    pub at: Time,
    /// DOR1 while driven; 0 while released (the divider pulls the gain pin to 0 V).
    pub code: u16,
    /// EN1 = 1 and the output connected to the pin.
    pub driven: bool,
}

/// DAC1 of either chip (channel 1).
pub struct Dac {
    chip: DacChip,
    cr: u32,
    mcr: u32,
    sr: u32,
    swtrigr: u32,
    /// 12-bit data holding and output registers.
    dhr: u16,
    dor: u16,
    /// G474 registers stored without effect: CCR, SHSR1/2, SHHR, SHRR, STR1/2, STMODR.
    stored: [(u32, u32); 8],
    /// Bus-clock period in master ticks (0 until the clocks are known: transfers then happen at
    /// once).
    tick: u64,
    /// Scheduled DHR → DOR transfers: (time, value).
    pending: Vec<(Time, u16)>,
    /// Every change of what the pin shows.
    pub trace: Vec<DacSample>,
    /// Times of the selected trigger's rising edges (for the checks and tests).
    pub triggers: Vec<Time>,
    /// Planted defects (`BOARD_MODEL_PLANT`, to show a check fails): DHR → DOR one clock after
    /// every write even with TEN1 = 1; EN1 = 0 does not release the output.
    pub plant_ignore_ten: bool,
    pub plant_ignore_en: bool,
}

impl Dac {
    pub fn new(chip: DacChip) -> Self {
        Dac {
            chip,
            cr: 0,
            mcr: 0,
            sr: 0,
            swtrigr: 0,
            dhr: 0,
            dor: 0,
            stored: [
                (CCR, 0),
                (SHSR1, 0),
                (SHSR1 + 4, 0),
                (0x48, 0),
                (SHRR, 0x0001_0001),
                (STR1, 0),
                (STR2, 0),
                (STMODR, 0),
            ],
            tick: 0,
            pending: Vec::new(),
            trace: vec![DacSample {
                at: 0,
                code: 0,
                driven: false,
            }],
            triggers: Vec::new(),
            plant_ignore_ten: false,
            plant_ignore_en: false,
        }
    }

    fn ten(&self) -> bool {
        let bit = match self.chip {
            DacChip::F446 => CR_TEN1_F4,
            DacChip::G474 => CR_TEN1_G4,
        };
        self.cr & bit != 0
    }

    fn tsel(cr: u32, chip: DacChip) -> u32 {
        match chip {
            DacChip::F446 => (cr >> 3) & 7,
            DacChip::G474 => (cr >> 2) & 0xF,
        }
    }

    fn trigger(cr: u32, chip: DacChip) -> Trigger {
        let t = Self::tsel(cr, chip);
        match (chip, t) {
            (DacChip::F446, 0) => Trigger::Timer(6),
            (DacChip::F446, 1) => Trigger::Timer(8),
            (DacChip::F446, 2) => Trigger::Timer(7),
            (DacChip::F446, 3) => Trigger::Timer(5),
            (DacChip::F446, 4) => Trigger::Timer(2),
            (DacChip::F446, 5) => Trigger::Timer(4),
            (DacChip::F446, 6) => Trigger::Other("EXTI9"),
            (DacChip::F446, _) => Trigger::Software,
            (DacChip::G474, 0) => Trigger::Software,
            (DacChip::G474, 1) => Trigger::Timer(8),
            (DacChip::G474, 2) => Trigger::Timer(7),
            (DacChip::G474, 3) => Trigger::Timer(15),
            (DacChip::G474, 4) => Trigger::Timer(2),
            (DacChip::G474, 5) => Trigger::Timer(4),
            (DacChip::G474, 6) => Trigger::Other("EXTI9"),
            (DacChip::G474, 7) => Trigger::Timer(6),
            (DacChip::G474, 8) => Trigger::Timer(3),
            (DacChip::G474, _) => Trigger::Other("HRTIM"),
        }
    }

    /// The output reaches the pin: EN1, and on the G474 a MODE1 connected to the pin.
    fn driven(&self) -> bool {
        let connected = match self.chip {
            DacChip::F446 => true,
            DacChip::G474 => self.mcr & MCR_MODE1 != 0b011,
        };
        (self.cr & CR_EN1 != 0 || self.plant_ignore_en) && connected
    }

    /// What the pin shows now: (code, driven).
    pub fn output(&self) -> (u16, bool) {
        if self.driven() {
            (self.dor, true)
        } else {
            (0, false)
        }
    }

    /// DOR1 as of the last access or `advance`.
    pub fn dor(&self) -> u16 {
        self.dor
    }

    fn note(&mut self, at: Time) {
        let (code, driven) = self.output();
        let last = self.trace.last().copied();
        if last.is_none_or(|l| l.code != code || l.driven != driven) {
            self.trace.push(DacSample { at, code, driven });
        }
    }

    /// Carries out the transfers due by `now`, in time order.
    fn run(&mut self, now: Time) {
        self.pending.sort_by_key(|p| p.0);
        while let Some(&(t, v)) = self.pending.first() {
            if t > now {
                break;
            }
            self.pending.remove(0);
            self.dor = v;
            self.note(t);
        }
    }

    /// A trigger edge at `now`: schedule DHR → DOR `clocks` bus clocks later.
    fn schedule(&mut self, now: Time, clocks: u64, out: &mut Signals) {
        self.triggers.push(now);
        self.pending.push((now + clocks * self.tick, self.dhr));
        if self.cr & CR_DMAEN1 != 0 {
            out.events.push((now, Event::DmaRequest(Request::Dac1Ch1)));
        }
        out.replan = true;
    }

    fn refuse(&self, offset: u32, value: u32, why: impl Into<String>) -> Result<(), Unmodelled> {
        Err(Unmodelled::write(
            offset,
            value,
            format!("{}: {}", self.name(), why.into()),
        ))
    }

    fn write_cr(
        &mut self,
        now: Time,
        offset: u32,
        value: u32,
        mask: u32,
    ) -> Result<(), Unmodelled> {
        let v = merge(self.cr, value, mask);
        if v & 0xFFFF_0000 != 0 {
            return self.refuse(offset, value, "channel 2 (CR bits 31:16) is not modelled");
        }
        if v & CR_WAVE1 != 0 {
            return self.refuse(
                offset,
                value,
                format!(
                    "CR.WAVE1={:02b} (noise/triangle/sawtooth generation) is not modelled",
                    (v & CR_WAVE1) >> 6
                ),
            );
        }
        let ten = match self.chip {
            DacChip::F446 => v & CR_TEN1_F4 != 0,
            DacChip::G474 => {
                if v & CR_CEN1_G4 != 0 {
                    return self.refuse(offset, value, "CR.CEN1 (calibration) is not modelled");
                }
                if v & (1 << 15) != 0 {
                    return self.refuse(offset, value, "CR bit 15 is reserved");
                }
                v & CR_TEN1_G4 != 0
            }
        };
        if ten {
            if let Trigger::Other(what) = Self::trigger(v, self.chip) {
                return self.refuse(
                    offset,
                    value,
                    format!("CR.TSEL1 selects {what}, which is not modelled"),
                );
            }
        }
        let _ = (CR_BOFF1_F4, CR_MAMP1, CR_DMAUDRIE1);
        let was_on = self.cr & CR_EN1 != 0;
        self.cr = v;
        if self.chip == DacChip::G474 {
            // DAC1RDY follows EN1 (the wake-up time is not modelled).
            if v & CR_EN1 != 0 {
                self.sr |= SR_DAC1RDY_G4;
            } else {
                self.sr &= !SR_DAC1RDY_G4;
            }
        }
        let _ = was_on;
        self.note(now);
        Ok(())
    }

    fn write_dhr(&mut self, now: Time, code: u16, out: &mut Signals) {
        self.dhr = code & 0xFFF;
        if !self.ten() || self.plant_ignore_ten {
            // One bus clock after the write (RM0390 §14.3 / RM0440 "DAC conversion").
            self.pending.push((now + self.tick, self.dhr));
            out.replan = true;
            self.run(now);
        }
    }
}

impl Peripheral for Dac {
    fn name(&self) -> &'static str {
        match self.chip {
            DacChip::F446 => "DAC",
            DacChip::G474 => "DAC1",
        }
    }

    fn read(&mut self, now: Time, offset: u32, _out: &mut Signals) -> Result<u32, Unmodelled> {
        self.run(now);
        let g4 = self.chip == DacChip::G474;
        Ok(match offset {
            CR => self.cr,
            SWTRIGR => self.swtrigr,
            DHR12R1 => self.dhr as u32,
            DHR12L1 => (self.dhr as u32) << 4,
            DHR8R1 => (self.dhr as u32) >> 4,
            DOR1 => self.dor as u32,
            SR => self.sr,
            MCR if g4 => self.mcr,
            _ if g4 && self.stored.iter().any(|s| s.0 == offset) => {
                self.stored.iter().find(|s| s.0 == offset).unwrap().1
            }
            DHR12R2..=DHR8RD | DOR2 => {
                return Err(Unmodelled::read(
                    offset,
                    format!(
                        "{}: channel 2 and the dual registers are not modelled",
                        self.name()
                    ),
                ))
            }
            _ => {
                return Err(Unmodelled::read(
                    offset,
                    format!(
                        "{} register at offset {offset:#x} is not modelled",
                        self.name()
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
        self.run(now);
        let g4 = self.chip == DacChip::G474;
        match offset {
            CR => self.write_cr(now, offset, value, mask)?,
            SWTRIGR => {
                let v = value & mask;
                if v & !1 != 0 {
                    return self.refuse(
                        offset,
                        value,
                        "SWTRIGR.SWTRIG2 (channel 2) is not modelled",
                    );
                }
                // Only with TEN1 and the software trigger selected; SWTRIG1 is cleared one clock
                // later, when DHR has moved to DOR (RM0390 §14.5.2).
                if v & 1 != 0
                    && self.ten()
                    && Self::trigger(self.cr, self.chip) == Trigger::Software
                {
                    self.schedule(now, 1, out);
                }
            }
            DHR12R1 => {
                let v = merge(self.dhr as u32, value, mask);
                if g4 && v & 0xFFFF_0000 != 0 {
                    return self.refuse(
                        offset,
                        value,
                        "DHR12R1 bits 31:16 (DACC1DHRB, double data) are not modelled",
                    );
                }
                self.write_dhr(now, (v & 0xFFF) as u16, out);
            }
            DHR12L1 => {
                let v = merge((self.dhr as u32) << 4, value, mask);
                if g4 && v & 0xFFFF_0000 != 0 {
                    return self.refuse(
                        offset,
                        value,
                        "DHR12L1 bits 31:16 (double data) are not modelled",
                    );
                }
                self.write_dhr(now, ((v >> 4) & 0xFFF) as u16, out);
            }
            DHR8R1 => {
                let v = merge((self.dhr as u32) >> 4, value, mask);
                if g4 && v & 0xFFFF_0000 != 0 {
                    return self.refuse(
                        offset,
                        value,
                        "DHR8R1 bits 15:8 (double data) are not modelled",
                    );
                }
                self.write_dhr(now, ((v & 0xFF) << 4) as u16, out);
            }
            DOR1 | DOR2 => return self.refuse(offset, value, "DORx are read-only"),
            SR => {
                // DMAUDR1 is rc_w1; DAC1RDY and the other status bits are read-only.
                let v = value & mask;
                self.sr &= !(v & SR_DMAUDR1);
            }
            MCR if g4 => {
                let v = merge(self.mcr, value, mask);
                if v & MCR_MODE1 >= 0b100 {
                    return self.refuse(
                        offset,
                        value,
                        "MCR.MODE1 sample-and-hold modes are not modelled",
                    );
                }
                if v & (MCR_DMADOUBLE1 | MCR_SINFORMAT1) != 0 {
                    return self.refuse(
                        offset,
                        value,
                        "MCR.DMADOUBLE1/SINFORMAT1 are not modelled",
                    );
                }
                if v & !(MCR_MODE1 | MCR_HFSEL | (0x3FF << 16)) != 0 {
                    return self.refuse(
                        offset,
                        value,
                        format!(
                            "MCR bits {:#x} are not modelled",
                            v & !(MCR_MODE1 | MCR_HFSEL)
                        ),
                    );
                }
                if v & (0x3FF << 16) != 0 {
                    return self.refuse(offset, value, "MCR channel 2 bits are not modelled");
                }
                self.mcr = v;
                self.note(now);
            }
            _ if g4 && self.stored.iter().any(|s| s.0 == offset) => {
                let s = self.stored.iter_mut().find(|s| s.0 == offset).unwrap();
                s.1 = merge(s.1, value, mask);
            }
            DHR12R2..=DHR8RD => {
                return self.refuse(
                    offset,
                    value,
                    "channel 2 and the dual registers are not modelled",
                )
            }
            _ => {
                return self.refuse(
                    offset,
                    value,
                    format!("no modelled register at offset {offset:#x}"),
                )
            }
        }
        Ok(())
    }

    fn advance(&mut self, now: Time, _out: &mut Signals) {
        self.run(now);
    }

    fn next_event(&self) -> Option<Time> {
        self.pending.iter().map(|p| p.0).min()
    }

    fn on_event(&mut self, now: Time, event: Event, out: &mut Signals) {
        self.run(now);
        if let Event::Trgo { timer } = event {
            if self.ten() && Self::trigger(self.cr, self.chip) == Trigger::Timer(timer) {
                // Three bus clocks after the trigger (RM0390 §14.3 / RM0440 "DAC conversion").
                self.schedule(now, 3, out);
            }
        }
    }

    fn set_clocks(&mut self, _now: Time, clocks: &Clocks) {
        let hz = match self.chip {
            DacChip::F446 => clocks.pclk1_hz,
            DacChip::G474 => clocks.hclk_hz,
        };
        self.tick = if hz == 0 { 0 } else { ticks_per_cycle(hz) };
    }

    fn reset(&mut self, now: Time) {
        let (tick, trace, triggers, plants) = (
            self.tick,
            std::mem::take(&mut self.trace),
            std::mem::take(&mut self.triggers),
            (self.plant_ignore_ten, self.plant_ignore_en),
        );
        *self = Dac::new(self.chip);
        (self.plant_ignore_ten, self.plant_ignore_en) = plants;
        self.tick = tick;
        self.trace = trace;
        self.triggers = triggers;
        self.note(now);
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

    const MHZ: u64 = 1_000_000;

    fn dac(chip: DacChip) -> Dac {
        let mut d = Dac::new(chip);
        d.set_clocks(
            0,
            &Clocks {
                pclk1_hz: 45 * MHZ,
                hclk_hz: 150 * MHZ,
                ..Default::default()
            },
        );
        d
    }

    fn w(d: &mut Dac, t: Time, off: u32, v: u32) {
        let mut s = Signals::default();
        d.write(t, off, v, 0xFFFF_FFFF, &mut s).unwrap();
    }

    fn drive(d: &mut Dac, until: Time) {
        let mut s = Signals::default();
        while let Some(n) = d.next_event().filter(|&n| n <= until) {
            d.advance(n, &mut s);
        }
        d.advance(until, &mut s);
    }

    #[test]
    fn without_trigger_dhr_reaches_dor_one_bus_clock_later() {
        // F446: APB1 45 MHz = 80 master ticks per clock.
        let mut d = dac(DacChip::F446);
        w(&mut d, 0, CR, CR_EN1);
        w(&mut d, 1000, DHR12R1, 0x123);
        assert_eq!(d.next_event(), Some(1080));
        drive(&mut d, 1079);
        assert_eq!(d.dor(), 0);
        drive(&mut d, 1080);
        assert_eq!(d.dor(), 0x123);
        assert_eq!(
            d.trace.last(),
            Some(&DacSample {
                at: 1080,
                code: 0x123,
                driven: true
            })
        );
        // Left-aligned and 8-bit writes land in the same 12 bits.
        w(&mut d, 2000, DHR12L1, 0xABC0);
        drive(&mut d, 3000);
        assert_eq!(d.dor(), 0xABC);
        w(&mut d, 3000, DHR8R1, 0x7F);
        drive(&mut d, 4000);
        assert_eq!(d.dor(), 0x7F0);
        // G474: dac_hclk 150 MHz = 24 ticks.
        let mut g = dac(DacChip::G474);
        w(&mut g, 0, CR, CR_EN1);
        w(&mut g, 100, DHR12R1, 7);
        assert_eq!(g.next_event(), Some(124));
    }

    #[test]
    fn with_trigger_dor_follows_the_selected_trgo_three_bus_clocks_later() {
        let mut d = dac(DacChip::F446);
        // TSEL1 = 001 (TIM8), TEN1, EN1.
        w(&mut d, 0, CR, CR_EN1 | CR_TEN1_F4 | (1 << 3));
        w(&mut d, 100, DHR12R1, 500);
        drive(&mut d, 10_000);
        assert_eq!(d.dor(), 0, "no trigger yet: DHR waits");
        let mut s = Signals::default();
        d.on_event(10_000, Event::Trgo { timer: 2 }, &mut s);
        assert_eq!(d.next_event(), None, "TIM2 is not the selected trigger");
        d.on_event(10_000, Event::Trgo { timer: 8 }, &mut s);
        assert_eq!(d.next_event(), Some(10_240));
        drive(&mut d, 10_239);
        assert_eq!(d.dor(), 0);
        drive(&mut d, 10_240);
        assert_eq!(d.dor(), 500);
        // G474: TSEL1 = 0001 at bits 5:2, TEN1 at bit 1; 3 × 24 ticks.
        let mut g = dac(DacChip::G474);
        w(&mut g, 0, CR, CR_EN1 | CR_TEN1_G4 | (1 << 2));
        w(&mut g, 0, DHR12R1, 9);
        g.on_event(1000, Event::Trgo { timer: 8 }, &mut s);
        drive(&mut g, 1072);
        assert_eq!(g.dor(), 9);
    }

    #[test]
    fn software_trigger_and_dma_request() {
        let mut d = dac(DacChip::F446);
        w(&mut d, 0, CR, CR_EN1 | CR_TEN1_F4 | (7 << 3) | CR_DMAEN1);
        w(&mut d, 0, DHR12R1, 42);
        let mut s = Signals::default();
        d.write(800, SWTRIGR, 1, 0xFFFF_FFFF, &mut s).unwrap();
        assert_eq!(s.events, vec![(800, Event::DmaRequest(Request::Dac1Ch1))]);
        drive(&mut d, 880);
        assert_eq!(d.dor(), 42);
    }

    #[test]
    fn disabled_output_is_released_to_zero() {
        let mut d = dac(DacChip::F446);
        w(&mut d, 0, CR, CR_EN1);
        w(&mut d, 0, DHR12R1, 3000);
        drive(&mut d, 100);
        w(&mut d, 200, CR, 0);
        assert_eq!(d.output(), (0, false));
        assert_eq!(
            d.trace,
            vec![
                DacSample {
                    at: 0,
                    code: 0,
                    driven: false
                },
                DacSample {
                    at: 0,
                    code: 0,
                    driven: true
                },
                DacSample {
                    at: 80,
                    code: 3000,
                    driven: true
                },
                DacSample {
                    at: 200,
                    code: 0,
                    driven: false
                },
            ]
        );
        // G474 MODE1 = 011: on-chip only, the pin is not driven.
        let mut g = dac(DacChip::G474);
        w(&mut g, 0, MCR, 0b011);
        w(&mut g, 0, CR, CR_EN1);
        assert_eq!(g.output(), (0, false));
        assert_eq!(g.r_sr() & SR_DAC1RDY_G4, SR_DAC1RDY_G4);
    }

    /// The chain of docs/rf-level.md, by hand as the board delivers events: TIM2's UG (MMS =
    /// 010) → TRGO → TIM8 in slave reset mode → its update → TRGO → the DAC latches DHR three
    /// APB1 clocks later.
    #[test]
    fn tim2_update_reaches_the_dac_through_tim8() {
        use crate::periph::tim::{Timer, TimerConfig};
        use crate::periph::ClockDomain;
        let clocks = Clocks {
            pclk1_hz: 45 * MHZ,
            tim_apb1_hz: 90 * MHZ,
            tim_apb2_hz: 180 * MHZ,
            ..Default::default()
        };
        let cfg = |number, name, clock, advanced, itr1| TimerConfig {
            number,
            bits: 16,
            advanced,
            clock,
            name,
            irq_up: 0,
            irq_cc: 0,
            itr1,
        };
        let mut t2 = Timer::new(cfg(2, "TIM2", ClockDomain::TimApb1, false, None));
        let mut t8 = Timer::new(cfg(8, "TIM8", ClockDomain::TimApb2, true, Some(2)));
        let mut d = Dac::new(DacChip::F446);
        t2.set_clocks(0, &clocks);
        t8.set_clocks(0, &clocks);
        d.set_clocks(0, &clocks);
        let mut s = Signals::default();
        let all = 0xFFFF_FFFF;
        t8.write(0, 0x04, 0b010 << 4, all, &mut s).unwrap(); // CR2.MMS = update
        t8.write(0, 0x08, (1 << 4) | 0b100, all, &mut s).unwrap(); // SMCR: ITR1, reset
        t2.write(0, 0x04, 0b010 << 4, all, &mut s).unwrap();
        w(&mut d, 0, CR, CR_EN1 | CR_TEN1_F4 | (1 << 3));
        w(&mut d, 0, DHR12R1, 1234);
        s.events.clear();
        // Deliver events to every block until nothing new comes, as `Sim::settle_local` does.
        let mut pending = Vec::new();
        t2.write(4000, 0x14, 1, all, &mut s).unwrap(); // EGR.UG
        pending.append(&mut s.events);
        let mut seen = Vec::new();
        while let Some((t, e)) = pending.pop() {
            seen.push((t, e));
            let mut s = Signals::default();
            t8.on_event(t, e, &mut s);
            d.on_event(t, e, &mut s);
            pending.append(&mut s.events);
        }
        assert!(seen.contains(&(4000, Event::Trgo { timer: 2 })));
        assert!(seen.contains(&(4000, Event::Trgo { timer: 8 })));
        assert_eq!(d.next_event(), Some(4000 + 3 * 80));
        drive(&mut d, 4239);
        assert_eq!(d.dor(), 0);
        drive(&mut d, 4240);
        assert_eq!(d.dor(), 1234);
    }

    #[test]
    fn unmodelled_settings_are_refused() {
        let mut d = dac(DacChip::F446);
        let mut s = Signals::default();
        let e = |d: &mut Dac, off, v| {
            d.write(0, off, v, 0xFFFF_FFFF, &mut Signals::default())
                .unwrap_err()
                .why
        };
        assert!(e(&mut d, CR, 1 << 6).contains("WAVE1"));
        assert!(e(&mut d, CR, 1 << 16).contains("channel 2"));
        assert!(e(&mut d, CR, CR_TEN1_F4 | (6 << 3)).contains("EXTI9"));
        assert!(e(&mut d, DOR1, 0).contains("read-only"));
        assert!(d.read(0, DOR2, &mut s).is_err());
        let mut g = dac(DacChip::G474);
        assert!(e(&mut g, MCR, 0b100).contains("sample-and-hold"));
        assert!(e(&mut g, CR, CR_CEN1_G4).contains("calibration"));
        assert!(e(&mut g, CR, CR_TEN1_G4 | (9 << 2)).contains("HRTIM"));
    }

    impl Dac {
        fn r_sr(&mut self) -> u32 {
            self.read(0, SR, &mut Signals::default()).unwrap()
        }
    }
}
