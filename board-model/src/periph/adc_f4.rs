//! STM32F446 ADC block at 0x4001_2000 (RM0390 §13): ADC1's regular group (scan sequences started by
//! a timer TRGO or SWSTART, conversion timing from ADCCLK = PCLK2 / ADCPRE, EOC/STRT/OVR flags,
//! DMA requests and the overrun lock-out of §13.8.1) and the common registers. ADC2/ADC3, the
//! injected group, the analog watchdog, discontinuous mode and reduced resolutions are not
//! modelled: touching them is `Unmodelled`.
//!
//! What is modelled, precisely (the parts of RM0390 §13.8 this model commits to):
//! - Overrun detection is on when CR2.DMA = 1 or CR2.EOCS = 1 (§13.8, §13.13.1 OVR). An overrun
//!   is a conversion completing while the previous result has not been read from ADC_DR (by the
//!   CPU or by the DMA's copy, which reads ADC_DR through `read`).
//! - On overrun (§13.8.1): OVR is set, the rest of the regular sequence is aborted, no DMA request
//!   is issued for the lost result nor afterwards, and every regular trigger (external edge and
//!   SWSTART) is ignored while OVR = 1; the unserved result is forgotten with it. §13.8.2 says the no-DMA case (EOCS = 1) is managed the same
//!   way, so it is. Clearing OVR (writing 0 to ADC_SR.OVR) ends the lock-out; the manual's recovery
//!   recipe (re-initialise the DMA stream, clear OVR, trigger again) then works. ADC_DR keeps the
//!   last data that was not lost (the manual does not say whether the lost result overwrites it;
//!   uncertain).
//! - A regular trigger that arrives while a sequence is converting is ignored.
//! - Each result with CR2.DMA = 1 raises `Event::DmaRequest(Request::Adc1)` at its end time. The
//!   DDS = 0 behaviour (no request after the DMA's last transfer) needs the DMA's end-of-transfer
//!   signal, which the board does not carry: a request raised with DDS = 0 records a fault.
//!
//! Timing: a trigger at t starts rank 1 at t (the datasheet's few-ADCCLK trigger latency is not
//! modelled); each conversion takes (sampling time + 12) ADCCLK cycles (§13.5, 12-bit) and the
//! next rank starts when the previous ends. The input is sampled at the end of the sampling phase.
//! The schedule of a conversion is fixed when it starts: a clock change mid-conversion applies
//! from the next rank.
//!
//! The board must advance this model to each `next_event()` in turn and deliver the DMA request it
//! raised before the next conversion ends (it never lets time run past `next_event`); if a second
//! result lands while a request raised in the same `advance` call is still unread, a fault is
//! recorded instead of a false overrun.

use super::{merge, Clocks, Event, Peripheral, Request, Signals, Time, Unmodelled, TICKS_PER_S};
use std::any::Any;

// ADC1 registers (RM0390 §13.13).
const SR: u32 = 0x00;
const CR1: u32 = 0x04;
const CR2: u32 = 0x08;
const SMPR1: u32 = 0x0C;
const SMPR2: u32 = 0x10;
const SQR1: u32 = 0x2C;
const SQR2: u32 = 0x30;
const SQR3: u32 = 0x34;
const DR: u32 = 0x4C;
// Common registers (RM0390 §13.13.15-17).
const CSR: u32 = 0x300;
const CCR: u32 = 0x304;
const CDR: u32 = 0x308;

// ADC_SR bits (§13.13.1), all rc_w0.
const SR_AWD: u32 = 1 << 0;
const SR_EOC: u32 = 1 << 1;
const SR_JEOC: u32 = 1 << 2;
const SR_JSTRT: u32 = 1 << 3;
const SR_STRT: u32 = 1 << 4;
const SR_OVR: u32 = 1 << 5;
const SR_MASK: u32 = SR_AWD | SR_EOC | SR_JEOC | SR_JSTRT | SR_STRT | SR_OVR;

// ADC_CR1 bits (§13.13.2).
const CR1_EOCIE: u32 = 1 << 5;
const CR1_AWDIE: u32 = 1 << 6;
const CR1_JEOCIE: u32 = 1 << 7;
const CR1_SCAN: u32 = 1 << 8;
const CR1_JAUTO: u32 = 1 << 10;
const CR1_DISCEN: u32 = 1 << 11;
const CR1_JDISCEN: u32 = 1 << 12;
const CR1_JAWDEN: u32 = 1 << 22;
const CR1_AWDEN: u32 = 1 << 23;
const CR1_RES_SHIFT: u32 = 24;
const CR1_OVRIE: u32 = 1 << 26;
/// AWDCH[4:0], EOCIE..DISCNUM[15:13], JAWDEN, AWDEN, RES[25:24], OVRIE; the rest is reserved.
const CR1_DEFINED: u32 = 0x1F | (0x7FF << 5) | (0x3 << 22) | (0x3 << 24) | CR1_OVRIE;

// ADC_CR2 bits (§13.13.3).
const CR2_ADON: u32 = 1 << 0;
const CR2_CONT: u32 = 1 << 1;
const CR2_DMA: u32 = 1 << 8;
const CR2_DDS: u32 = 1 << 9;
const CR2_EOCS: u32 = 1 << 10;
const CR2_ALIGN: u32 = 1 << 11;
const CR2_JEXTSEL_SHIFT: u32 = 16;
const CR2_JEXTEN_SHIFT: u32 = 20;
const CR2_JSWSTART: u32 = 1 << 22;
const CR2_EXTSEL_SHIFT: u32 = 24;
const CR2_EXTEN_SHIFT: u32 = 28;
const CR2_SWSTART: u32 = 1 << 30;
/// Bits that hold state (SWSTART/JSWSTART are start commands, not stored).
const CR2_STORED: u32 = CR2_ADON
    | CR2_CONT
    | CR2_DMA
    | CR2_DDS
    | CR2_EOCS
    | CR2_ALIGN
    | (0xF << CR2_JEXTSEL_SHIFT)
    | (0x3 << CR2_JEXTEN_SHIFT)
    | (0xF << CR2_EXTSEL_SHIFT)
    | (0x3 << CR2_EXTEN_SHIFT);
const CR2_DEFINED: u32 = CR2_STORED | CR2_JSWSTART | CR2_SWSTART;

// ADC_CCR fields (§13.13.16).
const CCR_MULTI_MASK: u32 = 0x1F;
const CCR_DELAY_MASK: u32 = 0xF << 8;
const CCR_DDS: u32 = 1 << 13;
const CCR_DMA_MASK: u32 = 0x3 << 14;
const CCR_ADCPRE_SHIFT: u32 = 16;
const CCR_VBATE: u32 = 1 << 22;
const CCR_TSVREFE: u32 = 1 << 23;
const CCR_DEFINED: u32 = CCR_MULTI_MASK
    | CCR_DELAY_MASK
    | CCR_DDS
    | CCR_DMA_MASK
    | (0x3 << CCR_ADCPRE_SHIFT)
    | CCR_VBATE
    | CCR_TSVREFE;

/// SMPx codes 000..111 → sampling time in ADCCLK cycles (§13.13.4/5).
const SAMPLE_CYCLES: [u64; 8] = [3, 15, 28, 56, 84, 112, 144, 480];
/// SAR conversion of a 12-bit result: Tconv = sampling time + 12 cycles (§13.5).
const SAR_CYCLES_12BIT: u64 = 12;
/// ADCPRE codes → PCLK2 divider (§13.13.16).
const ADCPRE_DIV: [u64; 4] = [2, 4, 6, 8];
/// Highest channel number of the F446 ADC (IN0..IN15, 16/18 temperature/VBAT, 17 VREFINT).
const MAX_CHANNEL: u8 = 18;

/// EXTSEL codes of the regular group that are timer TRGO outputs (RM0390 §13.6, table
/// "External trigger for regular channels"): 0110 TIM2_TRGO, 1000 TIM3_TRGO, 1110 TIM8_TRGO.
/// The other codes are timer compare channels and EXTI11, which the board does not carry.
fn extsel_trgo_timer(extsel: u32) -> Option<u8> {
    match extsel {
        0b0110 => Some(2),
        0b1000 => Some(3),
        0b1110 => Some(8),
        _ => None,
    }
}

/// The conversion now in progress.
#[derive(Clone, Copy, Debug)]
struct Conversion {
    /// 0-based rank in the regular sequence.
    rank: u8,
    /// Last rank of this sequence (SQR1.L when SCAN = 1, else 0), latched at the trigger.
    last_rank: u8,
    channel: u8,
    /// End of the sampling phase: the input is held from here.
    sample_end_at: Time,
    /// Result in ADC_DR, EOC, DMA request.
    end_at: Time,
}

/// The STM32F446 ADC block (ADC1 + common registers).
pub struct AdcF4 {
    irq: u16,
    input: Box<dyn FnMut(Time, u8) -> Option<u16>>,
    clocks: Clocks,
    sr: u32,
    cr1: u32,
    cr2: u32,
    smpr1: u32,
    smpr2: u32,
    sqr1: u32,
    sqr2: u32,
    sqr3: u32,
    dr: u32,
    ccr: u32,
    /// ADC_DR holds a result nobody has read yet (the overrun condition of §13.8).
    dr_unread: bool,
    conversion: Option<Conversion>,
    fault: Option<String>,
}

impl AdcF4 {
    /// `irq`: the NVIC line of the ADC global interrupt (18 on the F446). `input(t, channel)` is the
    /// 12-bit code the converter sees on `channel` at `t`, None if nothing is wired to it.
    pub fn new(irq: u16, input: Box<dyn FnMut(Time, u8) -> Option<u16>>) -> Self {
        let mut adc = AdcF4 {
            irq,
            input,
            clocks: Clocks::default(),
            sr: 0,
            cr1: 0,
            cr2: 0,
            smpr1: 0,
            smpr2: 0,
            sqr1: 0,
            sqr2: 0,
            sqr3: 0,
            dr: 0,
            ccr: 0,
            dr_unread: false,
            conversion: None,
            fault: None,
        };
        adc.reset(0);
        adc
    }

    /// The first thing that went wrong during a conversion (an unwired channel, an unrepresentable
    /// clock, an unmodelled DMA mode), for the board to stop on.
    pub fn fault(&self) -> Option<String> {
        self.fault.clone()
    }

    fn record_fault(&mut self, why: String) {
        if self.fault.is_none() {
            self.fault = Some(why);
        }
    }

    /// Master ticks per ADCCLK cycle: ADCCLK = PCLK2 / ADCPRE (RM0390 §13.3.2, §13.13.16).
    fn ticks_per_adcclk(&self) -> Result<u64, String> {
        let pclk2_hz = self.clocks.pclk2_hz;
        if pclk2_hz == 0 {
            return Err("ADC1 conversion with PCLK2 unknown (no clock plan from the RCC)".into());
        }
        let div = ADCPRE_DIV[((self.ccr >> CCR_ADCPRE_SHIFT) & 0x3) as usize];
        // ADCCLK period = div / pclk2 seconds = TICKS_PER_S * div / pclk2 ticks, exactly or not at all.
        if !(TICKS_PER_S * div).is_multiple_of(pclk2_hz) {
            return Err(format!(
                "ADCCLK = {pclk2_hz} Hz / {div} has a period that is not a whole number of master ticks"
            ));
        }
        Ok(TICKS_PER_S * div / pclk2_hz)
    }

    /// Channel of 0-based regular rank `rank` (SQR3: ranks 1-6, SQR2: 7-12, SQR1: 13-16).
    fn rank_channel(&self, rank: u8) -> u8 {
        let (reg, slot) = match rank {
            0..=5 => (self.sqr3, rank),
            6..=11 => (self.sqr2, rank - 6),
            _ => (self.sqr1, rank - 12),
        };
        ((reg >> (5 * slot as u32)) & 0x1F) as u8
    }

    /// Sampling time of `channel` in ADCCLK cycles (SMPR2: channels 0-9, SMPR1: 10-18).
    fn sample_cycles(&self, channel: u8) -> u64 {
        let code = if channel <= 9 {
            (self.smpr2 >> (3 * channel as u32)) & 0x7
        } else {
            (self.smpr1 >> (3 * (channel as u32 - 10))) & 0x7
        };
        SAMPLE_CYCLES[code as usize]
    }

    /// Start converting `rank` at `t`.
    fn begin_rank(&mut self, rank: u8, last_rank: u8, t: Time) -> Result<(), String> {
        let channel = self.rank_channel(rank);
        if channel > MAX_CHANNEL {
            return Err(format!(
                "ADC1 regular rank {} selects channel {channel}, which does not exist",
                rank + 1
            ));
        }
        let tick = self.ticks_per_adcclk()?;
        let sample_end_at = t + self.sample_cycles(channel) * tick;
        let end_at = sample_end_at + SAR_CYCLES_12BIT * tick;
        self.conversion = Some(Conversion {
            rank,
            last_rank,
            channel,
            sample_end_at,
            end_at,
        });
        // STRT: "set by hardware when regular channel conversion starts" (§13.13.1).
        self.sr |= SR_STRT;
        Ok(())
    }

    /// A regular trigger (external edge or SWSTART) at `t`. Returns whether a sequence started.
    fn trigger(&mut self, t: Time) -> Result<bool, String> {
        if self.cr2 & CR2_ADON == 0 {
            return Ok(false); // Powered down: nothing converts (§13.3.1).
        }
        if self.conversion.is_some() {
            return Ok(false); // A trigger during a sequence is ignored.
        }
        if self.sr & SR_OVR != 0 {
            // §13.8.1: after an overrun "further regular triggers are ignored" until OVR is cleared.
            return Ok(false);
        }
        // Scan mode converts ranks 1..=L+1; without SCAN only rank 1 (§13.3.8).
        let last_rank = if self.cr1 & CR1_SCAN != 0 {
            ((self.sqr1 >> 20) & 0xF) as u8
        } else {
            0
        };
        self.begin_rank(0, last_rank, t)?;
        Ok(true)
    }

    /// The conversion `c` ends: result to ADC_DR, flags, DMA request, next rank.
    fn finish(&mut self, c: Conversion, request_outstanding: &mut bool, out: &mut Signals) {
        let t = c.end_at;
        self.conversion = None;
        let code = match (self.input)(c.sample_end_at, c.channel) {
            Some(code) if code <= 0xFFF => code as u32,
            Some(code) => {
                self.record_fault(format!(
                    "ADC1 input on channel {} returned {code}, not a 12-bit code",
                    c.channel
                ));
                (code & 0xFFF) as u32
            }
            None => {
                self.record_fault(format!(
                    "ADC1 converted channel {} at t = {t} ticks but nothing is wired to that channel",
                    c.channel
                ));
                0
            }
        };

        // Overrun detection is enabled only when DMA = 1 or EOCS = 1 (§13.13.1 OVR, §13.8).
        let detect_overrun = self.cr2 & (CR2_DMA | CR2_EOCS) != 0;
        if detect_overrun && self.dr_unread {
            if *request_outstanding {
                self.record_fault(
                    "ADC1: advance() ran past a DMA request it had just raised; the board must advance \
                     to next_event() and deliver events in between"
                        .into(),
                );
            }
            // §13.8.1: OVR set, the sequence is aborted, DMA requests stop, triggers are ignored
            // until OVR is cleared. The lost result does not reach ADC_DR (uncertain, see module doc).
            // The unserved request is dropped with it: the manual's recovery (re-initialise the DMA,
            // clear OVR, trigger) reads nothing from ADC_DR, so the next result must be accepted.
            self.sr |= SR_OVR;
            self.dr_unread = false;
            return;
        }

        // Data alignment (§13.4): right, or left-aligned 12-bit (<< 4).
        self.dr = if self.cr2 & CR2_ALIGN != 0 {
            code << 4
        } else {
            code
        };
        self.dr_unread = true;
        // EOCS = 1: EOC after each conversion; EOCS = 0: at the end of the sequence (§13.13.3).
        if self.cr2 & CR2_EOCS != 0 || c.rank == c.last_rank {
            self.sr |= SR_EOC;
        }
        if self.cr2 & CR2_DMA != 0 {
            if self.cr2 & CR2_DDS == 0 {
                self.record_fault(
                    "ADC1 DMA request with CR2.DDS = 0: stopping after the DMA's last transfer needs the \
                     DMA end-of-transfer signal, which is not modelled"
                        .into(),
                );
            }
            out.events.push((t, Event::DmaRequest(Request::Adc1)));
            *request_outstanding = true;
        }

        let next = if c.rank < c.last_rank {
            self.begin_rank(c.rank + 1, c.last_rank, t)
        } else if self.cr2 & CR2_CONT != 0 {
            // Continuous mode: the sequence restarts at once (§13.3.5).
            self.trigger(t).map(|_| ())
        } else {
            Ok(())
        };
        if let Err(why) = next {
            self.record_fault(why);
        }
    }

    fn check_cr1(&self, offset: u32, value: u32, new: u32) -> Result<(), Unmodelled> {
        let unmodelled = |why: &str| Err(Unmodelled::write(offset, value, why));
        if new & !CR1_DEFINED != 0 {
            return unmodelled("ADC1_CR1 reserved bits written non-zero");
        }
        if new & (CR1_AWDEN | CR1_JAWDEN | CR1_AWDIE) != 0 {
            return unmodelled("ADC1_CR1 analog watchdog (AWDEN/JAWDEN/AWDIE) is not modelled");
        }
        if new & (CR1_JAUTO | CR1_JDISCEN | CR1_JEOCIE) != 0 {
            return unmodelled("ADC1_CR1 injected group (JAUTO/JDISCEN/JEOCIE) is not modelled");
        }
        if new & CR1_DISCEN != 0 {
            return unmodelled("ADC1_CR1.DISCEN discontinuous mode is not modelled");
        }
        if (new >> CR1_RES_SHIFT) & 0x3 != 0 {
            return unmodelled("ADC1_CR1.RES other than 12-bit is not modelled");
        }
        Ok(())
    }

    fn check_cr2(&self, offset: u32, value: u32, new: u32) -> Result<(), Unmodelled> {
        let unmodelled = |why: String| Err(Unmodelled::write(offset, value, why));
        if new & !CR2_DEFINED != 0 {
            return unmodelled("ADC1_CR2 reserved bits written non-zero".into());
        }
        if (new >> CR2_JEXTEN_SHIFT) & 0x3 != 0 || new & CR2_JSWSTART != 0 {
            return unmodelled("ADC1_CR2 injected group (JEXTEN/JSWSTART) is not modelled".into());
        }
        let extsel = (new >> CR2_EXTSEL_SHIFT) & 0xF;
        if (new >> CR2_EXTEN_SHIFT) & 0x3 != 0 && extsel_trgo_timer(extsel).is_none() {
            return unmodelled(format!(
                "ADC1_CR2.EXTSEL = {extsel:#06b} selects a trigger other than a timer TRGO, which is not modelled"
            ));
        }
        Ok(())
    }
}

impl Peripheral for AdcF4 {
    fn name(&self) -> &'static str {
        "ADC1/common"
    }

    fn read(&mut self, _now: Time, offset: u32, out: &mut Signals) -> Result<u32, Unmodelled> {
        match offset {
            SR => Ok(self.sr),
            CR1 => Ok(self.cr1),
            // SWSTART reads 0: it is "cleared by hardware as soon as the conversion starts", and a
            // start the ADC does not take (off, busy, OVR lock-out) is not remembered (uncertain).
            CR2 => Ok(self.cr2),
            SMPR1 => Ok(self.smpr1),
            SMPR2 => Ok(self.smpr2),
            SQR1 => Ok(self.sqr1),
            SQR2 => Ok(self.sqr2),
            SQR3 => Ok(self.sqr3),
            DR => {
                // Reading ADC_DR clears EOC (§13.13.1) and is what ends the overrun condition.
                if self.sr & SR_EOC != 0 && self.cr1 & CR1_EOCIE != 0 {
                    out.replan = true;
                }
                self.sr &= !SR_EOC;
                self.dr_unread = false;
                Ok(self.dr)
            }
            // ADC_CSR mirrors ADC1's SR in bits 5:0; ADC2/ADC3 cannot leave reset here (any access to
            // them is Unmodelled), so their fields are truly 0.
            CSR => Ok(self.sr & SR_MASK),
            CCR => Ok(self.ccr),
            CDR => Err(Unmodelled::read(
                offset,
                "ADC_CDR (multi-ADC data) is not modelled",
            )),
            0x100..=0x2FF => Err(Unmodelled::read(offset, "ADC2/ADC3 are not modelled")),
            0x14..=0x28 | 0x38..=0x48 => Err(Unmodelled::read(
                offset,
                "ADC1 injected group / analog watchdog registers are not modelled",
            )),
            _ => Err(Unmodelled::read(offset, "no ADC register at this offset")),
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
        match offset {
            SR => {
                // rc_w0: writing 0 clears, 1 leaves (§13.13.1).
                let cleared = mask & !value & SR_MASK;
                self.sr &= !cleared;
                out.replan = true;
            }
            CR1 => {
                let new = merge(self.cr1, value, mask);
                self.check_cr1(offset, value, new)?;
                self.cr1 = new;
                out.replan = true;
            }
            CR2 => {
                let new = merge(self.cr2, value, mask);
                self.check_cr2(offset, value, new)?;
                let was_on = self.cr2 & CR2_ADON != 0;
                self.cr2 = new & CR2_STORED;
                if was_on && new & CR2_ADON == 0 {
                    // ADON = 0: "conversion is stopped and the ADC goes to power down" (§13.3.1).
                    self.conversion = None;
                }
                // SWSTART starts the regular group, external trigger enabled or not; it "can be set
                // only when ADON = 1" — ADON must already have been 1 before this write (§13.13.3).
                if new & CR2_SWSTART != 0 && was_on {
                    self.trigger(now)
                        .map_err(|why| Unmodelled::write(offset, value, why))?;
                }
                out.replan = true;
            }
            SMPR1 => self.smpr1 = merge(self.smpr1, value, mask) & 0x07FF_FFFF,
            SMPR2 => self.smpr2 = merge(self.smpr2, value, mask) & 0x3FFF_FFFF,
            SQR1 => self.sqr1 = merge(self.sqr1, value, mask) & 0x00FF_FFFF,
            SQR2 => self.sqr2 = merge(self.sqr2, value, mask) & 0x3FFF_FFFF,
            SQR3 => self.sqr3 = merge(self.sqr3, value, mask) & 0x3FFF_FFFF,
            DR => return Err(Unmodelled::write(offset, value, "ADC1_DR is read-only")),
            CSR => return Err(Unmodelled::write(offset, value, "ADC_CSR is read-only")),
            CCR => {
                let new = merge(self.ccr, value, mask);
                if new & !CCR_DEFINED != 0 {
                    return Err(Unmodelled::write(
                        offset,
                        value,
                        "ADC_CCR reserved bits written non-zero",
                    ));
                }
                if new & (CCR_MULTI_MASK | CCR_DMA_MASK) != 0 {
                    return Err(Unmodelled::write(
                        offset,
                        value,
                        "ADC_CCR multi-ADC mode (MULTI/DMA) is not modelled",
                    ));
                }
                // DELAY/DDS only act in multi-ADC mode; VBATE/TSVREFE connect internal channels,
                // which the input function answers for.
                self.ccr = new;
            }
            CDR => {
                return Err(Unmodelled::write(
                    offset,
                    value,
                    "ADC_CDR is read-only (multi-ADC data)",
                ))
            }
            0x100..=0x2FF => {
                return Err(Unmodelled::write(
                    offset,
                    value,
                    "ADC2/ADC3 are not modelled",
                ))
            }
            0x14..=0x28 | 0x38..=0x48 => {
                return Err(Unmodelled::write(
                    offset,
                    value,
                    "ADC1 injected group / analog watchdog registers are not modelled",
                ))
            }
            _ => {
                return Err(Unmodelled::write(
                    offset,
                    value,
                    "no ADC register at this offset",
                ))
            }
        }
        Ok(())
    }

    fn advance(&mut self, now: Time, out: &mut Signals) {
        let mut request_outstanding = false;
        while let Some(c) = self.conversion {
            if c.end_at > now {
                break;
            }
            // A DMA copy of this call's request would have cleared `dr_unread`; the flag only
            // matters while that request is still undelivered.
            if !self.dr_unread {
                request_outstanding = false;
            }
            self.finish(c, &mut request_outstanding, out);
        }
    }

    fn next_event(&self) -> Option<Time> {
        self.conversion.map(|c| c.end_at)
    }

    fn on_event(&mut self, now: Time, event: Event, out: &mut Signals) {
        if let Event::Trgo { timer } = event {
            let exten = (self.cr2 >> CR2_EXTEN_SHIFT) & 0x3;
            let extsel = (self.cr2 >> CR2_EXTSEL_SHIFT) & 0xF;
            // A TRGO is a one-clock pulse: rising edge at `now`, falling edge one timer clock later.
            // Any EXTEN ≠ 00 sees one trigger per pulse (with "both edges" the second edge falls
            // inside the conversion the first started, and is ignored) (§13.6).
            if exten != 0 && extsel_trgo_timer(extsel) == Some(timer) {
                match self.trigger(now) {
                    Ok(true) => out.replan = true,
                    Ok(false) => {}
                    Err(why) => self.record_fault(why),
                }
            }
        }
    }

    fn set_clocks(&mut self, _now: Time, clocks: &Clocks) {
        self.clocks = *clocks;
    }

    fn irq_lines(&self, raise: &mut dyn FnMut(u16)) {
        // §13.12: EOC with EOCIE, OVR with OVRIE (AWD/JEOC cannot be enabled here).
        if (self.sr & SR_EOC != 0 && self.cr1 & CR1_EOCIE != 0)
            || (self.sr & SR_OVR != 0 && self.cr1 & CR1_OVRIE != 0)
        {
            raise(self.irq);
        }
    }

    fn reset(&mut self, _now: Time) {
        // All ADC registers reset to 0 except HTR (not modelled) (§13.13).
        self.sr = 0;
        self.cr1 = 0;
        self.cr2 = 0;
        self.smpr1 = 0;
        self.smpr2 = 0;
        self.sqr1 = 0;
        self.sqr2 = 0;
        self.sqr3 = 0;
        self.dr = 0;
        self.ccr = 0;
        self.dr_unread = false;
        self.conversion = None;
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
    use crate::periph::dma_f4::DmaF4;
    use std::cell::RefCell;
    use std::collections::HashMap;
    use std::rc::Rc;

    const ADC_BASE: u32 = 0x4001_2000;
    const DMA2_BASE: u32 = 0x4002_6400;
    const BUF: u32 = 0x2000_0100;
    /// DMA2 stream 0 register offsets.
    const S0CR: u32 = 0x10;
    const S0NDTR: u32 = 0x14;
    const S0PAR: u32 = 0x18;
    const S0M0AR: u32 = 0x1C;
    const LISR: u32 = 0x00;
    const LIFCR: u32 = 0x08;

    /// F446 firmware clock plan: PCLK2 = 90 MHz.
    fn clocks() -> Clocks {
        Clocks {
            sysclk_hz: 180_000_000,
            hclk_hz: 180_000_000,
            pclk1_hz: 45_000_000,
            pclk2_hz: 90_000_000,
            ..Default::default()
        }
    }

    /// Input that answers `base + n` for the n-th sample it is asked for and logs (time, channel).
    fn counting_input(
        base: u16,
        log: Rc<RefCell<Vec<(Time, u8)>>>,
    ) -> Box<dyn FnMut(Time, u8) -> Option<u16>> {
        Box::new(move |t, ch| {
            let mut l = log.borrow_mut();
            l.push((t, ch));
            Some(base + l.len() as u16 - 1)
        })
    }

    fn w(p: &mut dyn Peripheral, now: Time, off: u32, v: u32) {
        let mut s = Signals::default();
        p.write(now, off, v, 0xFFFF_FFFF, &mut s).unwrap();
    }
    fn r(p: &mut dyn Peripheral, now: Time, off: u32) -> u32 {
        let mut s = Signals::default();
        p.read(now, off, &mut s).unwrap()
    }

    /// ADC + DMA2 + RAM, wired like the board: events go to the DMA, its copies read ADC_DR.
    struct Bench {
        now: Time,
        adc: AdcF4,
        dma: DmaF4,
        ram: HashMap<u32, u16>,
        copies: usize,
    }

    impl Bench {
        fn new(input: Box<dyn FnMut(Time, u8) -> Option<u16>>) -> Self {
            let mut adc = AdcF4::new(18, input);
            adc.set_clocks(0, &clocks());
            let dma = DmaF4::new(2, [56, 57, 58, 59, 60, 68, 69, 70], DMA2_BASE);
            Bench {
                now: 0,
                adc,
                dma,
                ram: HashMap::new(),
                copies: 0,
            }
        }

        fn deliver(&mut self, sig: Signals) {
            for (at, ev) in sig.events {
                let mut s = Signals::default();
                self.dma.on_event(at, ev, &mut s);
                self.adc.on_event(at, ev, &mut Signals::default());
                for c in s.copies {
                    assert_eq!(c.size, 2);
                    let v = if (ADC_BASE..ADC_BASE + 0x400).contains(&c.from) {
                        self.adc
                            .read(at, c.from - ADC_BASE, &mut Signals::default())
                            .unwrap() as u16
                    } else {
                        self.ram[&c.from]
                    };
                    self.ram.insert(c.to, v);
                    self.copies += 1;
                }
            }
        }

        /// Runs to `t`, stopping at every next_event like the board.
        fn run_to(&mut self, t: Time) {
            while let Some(next) = self.adc.next_event().filter(|&n| n <= t) {
                let mut s = Signals::default();
                self.adc.advance(next, &mut s);
                self.now = next;
                self.deliver(s);
            }
            self.now = t;
        }

        fn trgo(&mut self, timer: u8) {
            let mut s = Signals::default();
            self.adc.on_event(self.now, Event::Trgo { timer }, &mut s);
            self.deliver(s);
        }

        fn dma_w(&mut self, off: u32, v: u32) {
            w(&mut self.dma, self.now, off, v);
        }
        fn dma_r(&mut self, off: u32) -> u32 {
            r(&mut self.dma, self.now, off)
        }
        fn adc_w(&mut self, off: u32, v: u32) {
            w(&mut self.adc, self.now, off, v);
        }
        fn adc_r(&mut self, off: u32) -> u32 {
            r(&mut self.adc, self.now, off)
        }
    }

    /// What embassy + the firmware leave in ADC1 (v2.rs new/configure_dma/configure_sequence and
    /// board/f446.rs): ADCPRE /4, ADON, SCAN, EOCIE, OVRIE, DMA, DDS, EOCS, EXTEN rising,
    /// EXTSEL TIM3_TRGO, 16 ranks of channel 1 at 56 cycles.
    fn arm_like_firmware(b: &mut Bench) {
        b.adc_w(CCR, 1 << CCR_ADCPRE_SHIFT);
        b.adc_w(CR2, CR2_ADON);
        b.adc_w(SMPR2, 0b011 << 3);
        b.adc_w(SR, 0);
        b.adc_w(CR1, CR1_EOCIE | CR1_OVRIE | CR1_SCAN);
        b.adc_w(
            CR2,
            CR2_ADON
                | CR2_DMA
                | CR2_DDS
                | CR2_EOCS
                | (0b01 << CR2_EXTEN_SHIFT)
                | (0b1000 << CR2_EXTSEL_SHIFT),
        );
        let six = (0..6).fold(0, |acc, i| acc | (1 << (5 * i)));
        b.adc_w(SQR3, six);
        b.adc_w(SQR2, six);
        b.adc_w(
            SQR1,
            (0..4).fold(0, |acc, i| acc | (1 << (5 * i))) | (15 << 20),
        );
    }

    /// What embassy's ReadableRingBuffer::new leaves in DMA2 stream 0 (dma_bdma.rs configure):
    /// flags cleared, PAR = ADC1_DR, M0AR = buffer, NDTR = 32, direct mode, CHSEL 0, P2M, 16-bit,
    /// MINC, CIRC, TEIE/HTIE/TCIE, EN = 0.
    fn configure_stream0_like_embassy(b: &mut Bench) {
        b.dma_w(LIFCR, 0b11_1101);
        b.dma_w(S0PAR, ADC_BASE + DR);
        b.dma_w(S0M0AR, BUF);
        b.dma_w(S0NDTR, 32);
        b.dma_w(S0CR + 0x14, 0); // FCR: direct mode
        let cr = (1 << 13)
            | (1 << 11)
            | (1 << 10)
            | (1 << 8)
            | (0b11 << 16)
            | (1 << 4)
            | (1 << 3)
            | (1 << 2);
        b.dma_w(S0CR, cr);
    }

    #[test]
    fn sequence_timing_from_adcclk_and_sampling_time() {
        let log = Rc::new(RefCell::new(Vec::new()));
        let mut adc = AdcF4::new(18, counting_input(100, log.clone()));
        adc.set_clocks(0, &clocks());
        // ADCCLK = 90 MHz / 4 = 22.5 MHz → 3.6 GHz / 22.5 MHz = 160 ticks per cycle.
        w(&mut adc, 0, CCR, 0b01 << CCR_ADCPRE_SHIFT);
        // Rank 1 = channel 1 at 56 cycles, rank 2 = channel 5 at 3 cycles; L = 1 (two ranks).
        w(&mut adc, 0, SMPR2, 0b011 << 3); // channel 5: code 000
        w(&mut adc, 0, SQR3, 1 | (5 << 5));
        w(&mut adc, 0, SQR1, 1 << 20);
        w(&mut adc, 0, CR1, CR1_SCAN);
        w(&mut adc, 0, CR2, CR2_ADON);
        let t0 = 1_000;
        w(&mut adc, t0, CR2, CR2_ADON | CR2_SWSTART);
        assert_eq!(
            r(&mut adc, t0, CR2) & CR2_SWSTART,
            0,
            "SWSTART clears when the conversion starts"
        );
        assert_ne!(r(&mut adc, t0, SR) & SR_STRT, 0);
        // Rank 1: (56 + 12) × 160 = 10 880 ticks.
        assert_eq!(adc.next_event(), Some(t0 + 10_880));
        let mut s = Signals::default();
        adc.advance(t0 + 10_879, &mut s);
        assert_eq!(r(&mut adc, t0, SR) & SR_EOC, 0);
        adc.advance(t0 + 10_880, &mut s);
        // EOCS = 0: EOC only at the end of the sequence, not after rank 1.
        assert_eq!(r(&mut adc, t0, SR) & SR_EOC, 0);
        // Rank 2: (3 + 12) × 160 = 2 400 ticks after rank 1.
        assert_eq!(adc.next_event(), Some(t0 + 10_880 + 2_400));
        adc.advance(t0 + 13_280, &mut s);
        assert!(s.events.is_empty(), "DMA = 0: no request");
        assert_eq!(adc.next_event(), None);
        assert_ne!(r(&mut adc, t0, SR) & SR_EOC, 0);
        // Inputs held at the end of each sampling phase: 56 × 160 and 10 880 + 3 × 160.
        assert_eq!(*log.borrow(), vec![(t0 + 8_960, 1), (t0 + 10_880 + 480, 5)]);
        // DR holds the second result (101); reading it clears EOC.
        assert_eq!(r(&mut adc, t0, DR), 101);
        assert_eq!(r(&mut adc, t0, SR) & SR_EOC, 0);
        assert_eq!(adc.fault(), None);
    }

    #[test]
    fn adcpre_div8_and_left_alignment() {
        let mut adc = AdcF4::new(18, Box::new(|_, _| Some(0xABC)));
        adc.set_clocks(0, &clocks());
        // ADCCLK = 90 MHz / 8 = 11.25 MHz → 320 ticks; channel 0 at 480 cycles → 492 × 320.
        w(&mut adc, 0, CCR, 0b11 << CCR_ADCPRE_SHIFT);
        w(&mut adc, 0, SMPR2, 0b111);
        w(&mut adc, 0, CR2, CR2_ADON | CR2_ALIGN);
        w(&mut adc, 0, CR2, CR2_ADON | CR2_ALIGN | CR2_SWSTART);
        assert_eq!(adc.next_event(), Some(157_440));
        adc.advance(157_440, &mut Signals::default());
        assert_eq!(r(&mut adc, 0, DR), 0xABC0);
    }

    #[test]
    fn swstart_while_off_or_busy_does_nothing() {
        let mut adc = AdcF4::new(18, Box::new(|_, _| Some(1)));
        adc.set_clocks(0, &clocks());
        w(&mut adc, 0, CR2, CR2_SWSTART); // ADON = 0
        assert_eq!(adc.next_event(), None);
        w(&mut adc, 0, CR2, CR2_ADON | CR2_SWSTART); // ADON set in the same write: not yet on
        assert_eq!(adc.next_event(), None);
        w(&mut adc, 10, CR2, CR2_ADON | CR2_SWSTART);
        let end = adc.next_event().unwrap();
        w(&mut adc, 20, CR2, CR2_ADON | CR2_SWSTART); // busy: ignored, same schedule
        assert_eq!(adc.next_event(), Some(end));
        w(&mut adc, 30, CR2, 0); // ADON = 0 stops the conversion
        assert_eq!(adc.next_event(), None);
    }

    #[test]
    fn unwired_channel_is_a_fault() {
        let mut adc = AdcF4::new(18, Box::new(|_, ch| if ch == 1 { Some(5) } else { None }));
        adc.set_clocks(0, &clocks());
        w(&mut adc, 0, SQR3, 7);
        w(&mut adc, 0, CR2, CR2_ADON);
        w(&mut adc, 0, CR2, CR2_ADON | CR2_SWSTART);
        let t = adc.next_event().unwrap();
        adc.advance(t, &mut Signals::default());
        assert!(adc.fault().unwrap().contains("channel 7"));
    }

    #[test]
    fn unmodelled_configurations_fail_loudly() {
        let mut adc = AdcF4::new(18, Box::new(|_, _| Some(1)));
        let mut s = Signals::default();
        // EXTSEL 0111 = TIM3_CH1: a compare event the board does not carry.
        assert!(adc
            .write(
                0,
                CR2,
                (0b01 << CR2_EXTEN_SHIFT) | (0b0111 << CR2_EXTSEL_SHIFT),
                !0,
                &mut s
            )
            .is_err());
        assert!(adc.write(0, CR1, 1 << CR1_RES_SHIFT, !0, &mut s).is_err());
        assert!(adc.write(0, CR1, CR1_DISCEN, !0, &mut s).is_err());
        assert!(adc.write(0, CCR, 0b00110, !0, &mut s).is_err());
        assert!(adc.read(0, 0x100, &mut s).is_err());
        assert!(adc.read(0, 0x3C, &mut s).is_err());
        // EXTEN = 0 with any EXTSEL is fine (the selector is inert).
        assert!(adc
            .write(0, CR2, 0b0111 << CR2_EXTSEL_SHIFT, !0, &mut s)
            .is_ok());
    }

    #[test]
    fn sixteen_rank_scan_feeds_circular_dma_with_ht_and_tc() {
        let log = Rc::new(RefCell::new(Vec::new()));
        let mut b = Bench::new(counting_input(1000, log.clone()));
        arm_like_firmware(&mut b);
        configure_stream0_like_embassy(&mut b);
        let cr = b.dma_r(S0CR);
        b.dma_w(S0CR, cr | 1); // EN
                               // 16 ranks × (56 + 12) × 160 ticks = 174 080 ticks per trigger.
        b.now = 5_000;
        b.trgo(3);
        b.run_to(5_000 + 174_079);
        assert_eq!(b.copies, 15);
        assert_eq!(b.dma_r(LISR) & (1 << 4), 0, "HTIF not before 16 transfers");
        b.run_to(5_000 + 174_080);
        assert_eq!(b.copies, 16);
        assert_eq!(b.dma_r(S0NDTR), 16);
        assert_ne!(b.dma_r(LISR) & (1 << 4), 0, "HTIF at 16 of 32");
        assert_eq!(b.dma_r(LISR) & (1 << 5), 0);
        // A trigger from another timer is not selected.
        b.now = 300_000;
        b.trgo(2);
        assert_eq!(b.adc.next_event(), None);
        b.trgo(3);
        b.run_to(300_000 + 174_080);
        assert_eq!(b.copies, 32);
        assert_ne!(b.dma_r(LISR) & (1 << 5), 0, "TCIF at 32 of 32");
        assert_eq!(b.dma_r(S0NDTR), 32, "circular: NDTR reloaded");
        assert_eq!(b.dma_r(S0CR) & 1, 1, "circular: stream stays enabled");
        for i in 0..32u32 {
            assert_eq!(b.ram[&(BUF + 2 * i)], 1000 + i as u16, "sample {i}");
        }
        assert_eq!(b.adc_r(SR) & SR_OVR, 0);
        assert_eq!(b.adc.fault(), None);
        // The stream's interrupt line (DMA2_STREAM0 = 56) is up while HTIF/TCIF are set.
        let mut lines = Vec::new();
        b.dma.irq_lines(&mut |n| lines.push(n));
        assert_eq!(lines, vec![56]);
        // A third sequence wraps to the start of the buffer.
        b.dma_w(LIFCR, 0b11_1101);
        b.now = 600_000;
        b.trgo(3);
        b.run_to(600_000 + 174_080);
        assert_eq!(b.ram[&BUF], 1032);
        assert_eq!(b.dma_r(S0NDTR), 16);
    }

    /// The firmware defect: ADC armed (EXTEN rising, EXTSEL TIM3_TRGO, DMA = 1, ADON) and the DMA
    /// stream configured but not enabled when TIM3's UG pulses TRGO (MMS = 000 at that time).
    #[test]
    fn trigger_while_stream_disabled_overruns_and_locks_out_triggers() {
        let log = Rc::new(RefCell::new(Vec::new()));
        let mut b = Bench::new(counting_input(2000, log.clone()));
        arm_like_firmware(&mut b);
        configure_stream0_like_embassy(&mut b);
        // TIM3 EGR.UG with MMS = 000 → TRGO at t0.
        let t0 = 10_000;
        b.now = t0;
        b.trgo(3);
        // Rank 1 ends at t0 + 10 880: DR = 2000, EOC, a DMA request the disabled stream drops.
        b.run_to(t0 + 10_880);
        assert_eq!(b.copies, 0);
        assert_eq!(b.adc_r(SR) & (SR_EOC | SR_OVR), SR_EOC);
        // Rank 2 ends at t0 + 21 760 with DR still unread: overrun, sequence aborted.
        b.run_to(t0 + 21_760);
        assert_eq!(b.adc_r(SR) & SR_OVR, SR_OVR);
        assert_eq!(
            b.adc.next_event(),
            None,
            "the rest of the sequence is aborted"
        );
        let mut lines = Vec::new();
        b.adc.irq_lines(&mut |n| lines.push(n));
        assert_eq!(lines, vec![18], "OVRIE: the ADC line is up");
        // Firmware Sampler::start: DMA stream EN = 1, then SWSTART (RingBufferedAdc::start).
        b.now = 1_000_000;
        let cr = b.dma_r(S0CR);
        b.dma_w(S0CR, cr | 1);
        let cr2 = b.adc_r(CR2);
        b.adc_w(CR2, cr2 | CR2_SWSTART);
        assert_eq!(b.adc.next_event(), None, "SWSTART ignored while OVR = 1");
        // TIM3 now runs at 10 kHz: every TRGO is ignored.
        for k in 1..=5 {
            b.now = 1_000_000 + k * 360_000;
            b.trgo(3);
            assert_eq!(b.adc.next_event(), None, "TRGO {k} ignored while OVR = 1");
        }
        assert_eq!(b.copies, 0);
        assert_eq!(b.dma_r(S0NDTR), 32, "nothing ever reaches the ring buffer");
        assert_eq!(
            log.borrow().len(),
            2,
            "only the two conversions before the overrun ran"
        );
        // Recovery per RM0390 §13.8.1: DMA re-initialised (it is, and enabled), clear OVR, trigger.
        b.adc_w(SR, !SR_OVR);
        assert_eq!(b.adc_r(SR) & SR_OVR, 0);
        let t1 = 3_000_000;
        b.now = t1;
        b.trgo(3);
        b.run_to(t1 + 16 * 10_880 - 1);
        assert_eq!(b.copies, 15);
        b.run_to(t1 + 16 * 10_880);
        assert_eq!(b.copies, 16);
        assert_eq!(b.dma_r(S0NDTR), 16);
        assert_ne!(b.dma_r(LISR) & (1 << 4), 0);
        assert_eq!(b.adc_r(SR) & SR_OVR, 0);
        assert_eq!(b.adc.fault(), None);
    }
}
