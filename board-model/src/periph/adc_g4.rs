//! STM32G474 ADC1/ADC2 block at 0x5000_0000 (RM0440 §21): ADC1 (power-up, calibration,
//! enable, regular-group sequences on a timer TRGO or software start, the regular oversampler,
//! EOC/EOS/OVR flags and DMA requests) and the ADC12 common registers. ADC2, the injected group,
//! analog watchdogs, offsets, gain compensation, differential inputs, discontinuous mode and
//! reduced resolutions are not modelled: touching them is `Unmodelled`.
//!
//! Behaviours this model commits to:
//! - Power: the regulator is on when ADVREGEN = 1 and DEEPPWD = 0 (§21.4.6). Its start-up time
//!   (datasheet tADCVREG_STUP) has no status bit; the firmware waits a fixed delay, and this model
//!   does not check that delay.
//! - ADCAL (§21.4.8) self-clears 116 ADC clock cycles after it is set (the datasheet's tCAL as
//!   recalled, not checked against the DS: a plausible figure, the firmware only polls the bit).
//! - ADEN → ADRDY (§21.4.9) after 15 ADC clock cycles (a stand-in for the datasheet's tSTAB).
//!   ADDIS and ADSTP take effect at once (ADEN/ADSTART read 0 on the next access).
//! - The "software is allowed to write/set X only when ..." rules of §21.7 (ADC_CR, CFGR, CFGR2,
//!   SMPR, SQR, DIFSEL, CCR) are enforced: a write that breaks one is `Unmodelled`. Writing 0 to
//!   an rs bit of ADC_CR does nothing; writing 1 to an rs bit that already reads 1 does nothing.
//! - ADSTART = 1 with EXTEN = 0 starts a sequence at once and ADSTART clears at EOS; with EXTEN ≠ 0
//!   it arms the trigger and stays 1. Hardware triggers are ignored while ADSTART = 0 (§21.4.18)
//!   and while a sequence is converting.
//! - Timing: each conversion is sampling time + 12.5 ADC clock cycles (§21.4.16), back to back;
//!   with the oversampler on, a rank is N such conversions and its result lands at the end of
//!   the N-th (§21.4.30: EOC once per N conversions). The trigger latency is not modelled. The ADC
//!   clock is adc_ker_ck / PRESC (CKMODE = 00) or HCLK / 1, 2, 4 (CKMODE = 01, 10, 11) (§21.4.3).
//! - Oversampler (§21.4.30): the sum of N results is shifted right by OVSS with rounding to the
//!   nearest (the bits shifted out), and truncated to 16 bits; ALIGN is ignored (data right
//!   aligned) while ROVSE = 1. ROVSM only matters when injected or discontinuous conversions
//!   interrupt the oversampler, neither of which is modelled, so both values are accepted.
//! - Overrun (§21.4.27): OVR is set when a result lands while EOC is still 1. OVRMOD = 0 keeps the
//!   old ADC_DR, OVRMOD = 1 overwrites it; conversions go on either way. While OVR = 1 the ADC
//!   issues no DMA request, until software clears OVR.
//! - DMA: each result with DMAEN = 1 raises `Event::DmaRequest(Request::Adc1)` (to the DMAMUX).
//!   DMACFG = 0 (one-shot: stop at the DMA's end of transfer) needs the DMA_EOT signal, which the
//!   board does not carry: a request in one-shot mode records a fault.
//!
//! The board must advance this model to each `next_event()` in turn and deliver the DMA requests
//! in between (see `adc_f4`); a result landing while a request raised in the same `advance` call
//! is unread records a fault instead of a false overrun.

use super::{merge, Clocks, Event, Peripheral, Request, Signals, Time, Unmodelled, TICKS_PER_S};
use std::any::Any;

// ADC1 registers (RM0440 §21.7).
const ISR: u32 = 0x00;
const IER: u32 = 0x04;
const CR: u32 = 0x08;
const CFGR: u32 = 0x0C;
const CFGR2: u32 = 0x10;
const SMPR1: u32 = 0x14;
const SMPR2: u32 = 0x18;
const SQR1: u32 = 0x30;
const SQR2: u32 = 0x34;
const SQR3: u32 = 0x38;
const SQR4: u32 = 0x3C;
const DR: u32 = 0x40;
const DIFSEL: u32 = 0xB0;
// ADC12 common registers (RM0440 §21.8).
const CSR: u32 = 0x300;
const CCR: u32 = 0x308;
const CDR: u32 = 0x30C;
const CDR2: u32 = 0x310;

// ADC_ISR / ADC_IER bits (§21.7.1/2).
const ADRDY: u32 = 1 << 0;
const EOSMP: u32 = 1 << 1;
const EOC: u32 = 1 << 2;
const EOS: u32 = 1 << 3;
const OVR: u32 = 1 << 4;
const ISR_MASK: u32 = 0x7FF;
/// IER bits this model can raise: ADRDYIE, EOCIE, EOSIE, OVRIE.
const IER_MODELLED: u32 = ADRDY | EOC | EOS | OVR;

// ADC_CR bits (§21.7.3).
const CR_ADEN: u32 = 1 << 0;
const CR_ADDIS: u32 = 1 << 1;
const CR_ADSTART: u32 = 1 << 2;
const CR_JADSTART: u32 = 1 << 3;
const CR_ADSTP: u32 = 1 << 4;
const CR_JADSTP: u32 = 1 << 5;
const CR_ADVREGEN: u32 = 1 << 28;
const CR_DEEPPWD: u32 = 1 << 29;
const CR_ADCALDIF: u32 = 1 << 30;
const CR_ADCAL: u32 = 1 << 31;
/// rs bits: set by software, cleared by hardware.
const CR_RS: u32 = CR_ADEN | CR_ADDIS | CR_ADSTART | CR_JADSTART | CR_ADSTP | CR_JADSTP | CR_ADCAL;
/// rw bits.
const CR_RW: u32 = CR_ADVREGEN | CR_DEEPPWD | CR_ADCALDIF;
const CR_RESET: u32 = CR_DEEPPWD;

// ADC_CFGR fields (§21.7.4).
const CFGR_DMAEN: u32 = 1 << 0;
const CFGR_DMACFG: u32 = 1 << 1;
const CFGR_RES_SHIFT: u32 = 3;
const CFGR_EXTSEL_SHIFT: u32 = 5;
const CFGR_EXTEN_SHIFT: u32 = 10;
const CFGR_OVRMOD: u32 = 1 << 12;
const CFGR_CONT: u32 = 1 << 13;
const CFGR_AUTDLY: u32 = 1 << 14;
const CFGR_ALIGN: u32 = 1 << 15;
const CFGR_DISCEN: u32 = 1 << 16;
const CFGR_JDISCEN: u32 = 1 << 20;
const CFGR_JQM: u32 = 1 << 21;
const CFGR_AWD1EN: u32 = 1 << 23;
const CFGR_JAWD1EN: u32 = 1 << 24;
const CFGR_JAUTO: u32 = 1 << 25;
/// Bit 2 is reserved.
const CFGR_DEFINED: u32 = !(1 << 2);
const CFGR_RESET: u32 = 1 << 31; // JQDIS

// ADC_CFGR2 fields (§21.7.5).
const CFGR2_ROVSE: u32 = 1 << 0;
const CFGR2_JOVSE: u32 = 1 << 1;
const CFGR2_OVSR_SHIFT: u32 = 2;
const CFGR2_OVSS_SHIFT: u32 = 5;
const CFGR2_TROVS: u32 = 1 << 9;
const CFGR2_ROVSM: u32 = 1 << 10;
const CFGR2_GCOMP: u32 = 1 << 16;
const CFGR2_SWTRIG: u32 = 1 << 25;
const CFGR2_BULB: u32 = 1 << 26;
const CFGR2_SMPTRIG: u32 = 1 << 27;
const CFGR2_DEFINED: u32 = CFGR2_ROVSE
    | CFGR2_JOVSE
    | (0x7 << CFGR2_OVSR_SHIFT)
    | (0xF << CFGR2_OVSS_SHIFT)
    | CFGR2_TROVS
    | CFGR2_ROVSM
    | CFGR2_GCOMP
    | CFGR2_SWTRIG
    | CFGR2_BULB
    | CFGR2_SMPTRIG;

const SMPR1_SMPPLUS: u32 = 1 << 31;

// ADC12_CCR fields (§21.8.2).
const CCR_DUAL_MASK: u32 = 0x1F;
const CCR_DELAY_MASK: u32 = 0xF << 8;
const CCR_DMACFG: u32 = 1 << 13;
const CCR_MDMA_MASK: u32 = 0x3 << 14;
const CCR_CKMODE_SHIFT: u32 = 16;
const CCR_PRESC_SHIFT: u32 = 18;
const CCR_VREFEN: u32 = 1 << 22;
const CCR_VSENSEEN: u32 = 1 << 23;
const CCR_VBATEN: u32 = 1 << 24;
const CCR_DEFINED: u32 = CCR_DUAL_MASK
    | CCR_DELAY_MASK
    | CCR_DMACFG
    | CCR_MDMA_MASK
    | (0x3 << CCR_CKMODE_SHIFT)
    | (0xF << CCR_PRESC_SHIFT)
    | CCR_VREFEN
    | CCR_VSENSEEN
    | CCR_VBATEN;

/// SMPx codes → sampling time in half ADC clock cycles: 2.5, 6.5, 12.5, 24.5, 47.5, 92.5, 247.5,
/// 640.5 cycles (§21.7.6).
const SAMPLE_HALF_CYCLES: [u64; 8] = [5, 13, 25, 49, 95, 185, 495, 1281];
/// 12-bit successive approximation: 12.5 cycles (§21.4.16).
const SAR_HALF_CYCLES_12BIT: u64 = 25;
/// Calibration time in ADC clock cycles (datasheet tCAL, see module doc).
const CAL_CYCLES: u64 = 116;
/// ADEN → ADRDY in ADC clock cycles (stand-in for tSTAB, see module doc).
const STAB_CYCLES: u64 = 15;
/// CCR.PRESC codes 0000..1011 → divider (§21.8.2); 1100..1111 reserved.
const PRESC_DIV: [u64; 12] = [1, 2, 4, 6, 8, 10, 12, 16, 32, 64, 128, 256];
/// ADC1 channels 0..18.
const MAX_CHANNEL: u8 = 18;

/// EXTSEL codes of the ADC1/2 regular group that are timer TRGO outputs (RM0440 §21.4.18, table
/// "ADC1 and ADC2 - External triggers for regular channels"): EXT4 TIM3_TRGO, EXT7 TIM8_TRGO,
/// EXT9 TIM1_TRGO, EXT11 TIM2_TRGO, EXT12 TIM4_TRGO, EXT13 TIM6_TRGO, EXT14 TIM15_TRGO,
/// EXT16 TIM20_TRGO, EXT30 TIM7_TRGO. TRGO2, compare, HRTIM, EXTI and LPTIM sources are not
/// carried by the board.
fn extsel_trgo_timer(extsel: u32) -> Option<u8> {
    match extsel {
        4 => Some(3),
        7 => Some(8),
        9 => Some(1),
        11 => Some(2),
        12 => Some(4),
        13 => Some(6),
        14 => Some(15),
        16 => Some(20),
        30 => Some(7),
        _ => None,
    }
}

/// One regular rank being converted (N conversions when the oversampler is on).
#[derive(Clone, Copy, Debug)]
struct Conversion {
    rank: u8,
    last_rank: u8,
    channel: u8,
    start_at: Time,
    /// One conversion: sampling + SAR.
    conversion_ticks: u64,
    sample_ticks: u64,
    /// Conversions summed into this result (1, or the oversampling ratio).
    count: u32,
    end_at: Time,
}

/// ES0430 (STM32G47x/48x errata), "Wrong ADC result if conversion done late after calibration
/// or previous conversion": more than 1 ms.
pub const LATE_CONVERSION_TICKS: Time = TICKS_PER_S / 1_000;

/// The STM32G474 ADC1/ADC2 block (ADC1 + ADC12 common registers).
pub struct AdcG4 {
    irq: u16,
    input: Box<dyn FnMut(Time, u8) -> Option<u16>>,
    clocks: Clocks,
    isr: u32,
    ier: u32,
    cr: u32,
    cfgr: u32,
    cfgr2: u32,
    smpr1: u32,
    smpr2: u32,
    sqr: [u32; 4],
    dr: u32,
    difsel: u32,
    ccr: u32,
    /// ADCAL clears at this time.
    calibration_end_at: Option<Time>,
    /// ADRDY rises at this time.
    ready_at: Option<Time>,
    /// When the ADC last finished a conversion or its calibration (None: neither since reset),
    /// for ES0430's late-conversion erratum (`LATE_CONVERSION_TICKS`).
    last_activity_at: Option<Time>,
    /// Results with a late first conversion (ES0430) that raised a DMA request, i.e. reached the
    /// firmware's buffer: their end-of-conversion times. A firmware that works around the
    /// erratum leaves this empty.
    pub late_results_delivered: Vec<Time>,
    /// Times of ADC_CR writes that carry ADEN = 1 while ADEN already reads 1: RM0440 §21.7.3
    /// lets software set ADEN "only when all bits of ADC_CR are 0" but ADVREGEN/ADCALDIF, so a
    /// read-modify-write that sets another rs bit writes ADEN back outside the rule (ST's
    /// LL_ADC_REG_StartConversion writes the rs bits 0). The model cannot know what silicon does
    /// with it, so it records the write instead of refusing it.
    pub aden_written_back: Vec<Time>,
    conversion: Option<Conversion>,
    fault: Option<String>,
}

impl AdcG4 {
    /// `irq`: NVIC line of ADC1_2 (18 on the G474). `input(t, channel)`: the 12-bit code on
    /// `channel` at `t`, None if nothing is wired to it.
    pub fn new(irq: u16, input: Box<dyn FnMut(Time, u8) -> Option<u16>>) -> Self {
        let mut adc = AdcG4 {
            irq,
            input,
            clocks: Clocks::default(),
            isr: 0,
            ier: 0,
            cr: CR_RESET,
            cfgr: CFGR_RESET,
            cfgr2: 0,
            smpr1: 0,
            smpr2: 0,
            sqr: [0; 4],
            dr: 0,
            difsel: 0,
            ccr: 0,
            calibration_end_at: None,
            ready_at: None,
            last_activity_at: None,
            late_results_delivered: Vec::new(),
            aden_written_back: Vec::new(),
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

    /// Master ticks per ADC clock cycle (§21.4.3).
    fn ticks_per_adc_cycle(&self) -> Result<u64, String> {
        let ckmode = (self.ccr >> CCR_CKMODE_SHIFT) & 0x3;
        let (source_hz, div, source) = match ckmode {
            0 => {
                let presc = ((self.ccr >> CCR_PRESC_SHIFT) & 0xF) as usize;
                (self.clocks.adc_kernel_hz, PRESC_DIV[presc], "adc_ker_ck")
            }
            1 => (self.clocks.hclk_hz, 1, "HCLK"),
            2 => (self.clocks.hclk_hz, 2, "HCLK"),
            _ => (self.clocks.hclk_hz, 4, "HCLK"),
        };
        if source_hz == 0 {
            return Err(format!(
                "ADC1 clock source {source} is unknown (0 Hz in the clock plan)"
            ));
        }
        if !(TICKS_PER_S * div).is_multiple_of(source_hz) {
            return Err(format!(
                "ADC1 clock {source} {source_hz} Hz / {div} is not a whole number of master ticks"
            ));
        }
        Ok(TICKS_PER_S * div / source_hz)
    }

    /// Channel of 0-based rank (SQR1: ranks 1-4 at bits 6.., SQR2: 5-9, SQR3: 10-14, SQR4: 15-16).
    fn rank_channel(&self, rank: u8) -> u8 {
        let (reg, shift) = match rank {
            0..=3 => (self.sqr[0], 6 + 6 * rank as u32),
            4..=8 => (self.sqr[1], 6 * (rank as u32 - 4)),
            9..=13 => (self.sqr[2], 6 * (rank as u32 - 9)),
            _ => (self.sqr[3], 6 * (rank as u32 - 14)),
        };
        ((reg >> shift) & 0x1F) as u8
    }

    fn sample_half_cycles(&self, channel: u8) -> u64 {
        let code = if channel <= 9 {
            (self.smpr1 >> (3 * channel as u32)) & 0x7
        } else {
            (self.smpr2 >> (3 * (channel as u32 - 10))) & 0x7
        };
        SAMPLE_HALF_CYCLES[code as usize]
    }

    fn oversampling_ratio(&self) -> u32 {
        if self.cfgr2 & CFGR2_ROVSE != 0 {
            2 << ((self.cfgr2 >> CFGR2_OVSR_SHIFT) & 0x7)
        } else {
            1
        }
    }

    fn begin_rank(&mut self, rank: u8, last_rank: u8, t: Time) -> Result<(), String> {
        let channel = self.rank_channel(rank);
        if channel > MAX_CHANNEL {
            return Err(format!(
                "ADC1 regular rank {} selects channel {channel}, which does not exist",
                rank + 1
            ));
        }
        let tick = self.ticks_per_adc_cycle()?;
        let half_to_ticks = |half: u64| -> Result<u64, String> {
            if !(half * tick).is_multiple_of(2) {
                return Err("ADC1 half clock cycle is not a whole number of master ticks".into());
            }
            Ok(half * tick / 2)
        };
        let sample_half = self.sample_half_cycles(channel);
        let sample_ticks = half_to_ticks(sample_half)?;
        let conversion_ticks = half_to_ticks(sample_half + SAR_HALF_CYCLES_12BIT)?;
        let count = self.oversampling_ratio();
        self.conversion = Some(Conversion {
            rank,
            last_rank,
            channel,
            start_at: t,
            conversion_ticks,
            sample_ticks,
            count,
            end_at: t + count as u64 * conversion_ticks,
        });
        Ok(())
    }

    /// Starts a regular sequence at `t` if the ADC can take a trigger now.
    fn trigger(&mut self, t: Time) -> Result<bool, String> {
        if self.cr & CR_ADSTART == 0 || self.conversion.is_some() {
            return Ok(false);
        }
        let last_rank = (self.sqr[0] & 0xF) as u8;
        self.begin_rank(0, last_rank, t)?;
        Ok(true)
    }

    /// Flags that become true on their own (calibration done, ready) up to `now`.
    fn settle(&mut self, now: Time) {
        if let Some(t) = self.calibration_end_at.filter(|&t| t <= now) {
            self.last_activity_at = Some(t);
            self.calibration_end_at = None;
            self.cr &= !CR_ADCAL;
        }
        if self.ready_at.is_some_and(|t| t <= now) {
            self.ready_at = None;
            self.isr |= ADRDY;
        }
        // EOSMP: end of the sampling phase of the conversion in progress (§21.4.23).
        if let Some(c) = self.conversion {
            if now >= c.start_at + c.sample_ticks {
                self.isr |= EOSMP;
            }
        }
    }

    fn finish(&mut self, c: Conversion, request_outstanding: &mut bool, out: &mut Signals) {
        let t = c.end_at;
        self.conversion = None;
        let mut sum: u32 = 0;
        // ES0430: the first conversion more than 1 ms after the calibration or the previous
        // conversion may be wrong; the erratum gives no figure, the model reads it as 0 (a
        // discharged sampling capacitor: the largest error on a mid-scale input).
        let late = self
            .last_activity_at
            .is_none_or(|t| c.start_at.saturating_sub(t) > LATE_CONVERSION_TICKS);
        self.last_activity_at = Some(t);
        for i in 0..c.count as u64 {
            let held_at = c.start_at + i * c.conversion_ticks + c.sample_ticks;
            let code = match (self.input)(held_at, c.channel) {
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
                        "ADC1 converted channel {} at t = {held_at} ticks but nothing is wired to that channel",
                        c.channel
                    ));
                    0
                }
            };
            sum += if i == 0 && late { 0 } else { code };
        }
        self.isr |= EOSMP;
        let value = if self.cfgr2 & CFGR2_ROVSE != 0 {
            // §21.4.30: shift right by OVSS rounding to nearest, keep the 16 LSBs; ALIGN ignored.
            let shift = (self.cfgr2 >> CFGR2_OVSS_SHIFT) & 0xF;
            let rounded = if shift == 0 {
                sum
            } else {
                (sum + (1 << (shift - 1))) >> shift
            };
            rounded & 0xFFFF
        } else if self.cfgr & CFGR_ALIGN != 0 {
            sum << 4
        } else {
            sum
        };

        if self.isr & EOC != 0 {
            if *request_outstanding {
                self.record_fault(
                    "ADC1: advance() ran past a DMA request it had just raised; the board must advance \
                     to next_event() and deliver events in between"
                        .into(),
                );
            }
            // §21.4.27: overrun; OVRMOD decides whether ADC_DR keeps the old data.
            self.isr |= OVR;
            if self.cfgr & CFGR_OVRMOD != 0 {
                self.dr = value;
            }
        } else {
            self.dr = value;
        }
        self.isr |= EOC;
        if c.rank == c.last_rank {
            self.isr |= EOS;
        }
        // No DMA request while OVR = 1 (§21.4.27).
        if self.cfgr & CFGR_DMAEN != 0 && self.isr & OVR == 0 {
            if self.cfgr & CFGR_DMACFG == 0 {
                self.record_fault(
                    "ADC1 DMA request in one-shot mode (CFGR.DMACFG = 0): stopping at the DMA's end of \
                     transfer needs the DMA_EOT signal, which is not modelled"
                        .into(),
                );
            }
            out.events.push((t, Event::DmaRequest(Request::Adc1)));
            *request_outstanding = true;
            if late {
                self.late_results_delivered.push(t);
            }
        }

        let next = if c.rank < c.last_rank {
            self.begin_rank(c.rank + 1, c.last_rank, t)
        } else if self.cfgr & CFGR_CONT != 0 {
            self.trigger(t).map(|_| ())
        } else {
            if (self.cfgr >> CFGR_EXTEN_SHIFT) & 0x3 == 0 {
                // Single mode, software trigger: ADSTART clears at EOS (§21.7.3).
                self.cr &= !CR_ADSTART;
            }
            Ok(())
        };
        if let Err(why) = next {
            self.record_fault(why);
        }
    }

    /// Registers that "software is allowed to write only when ADSTART = 0" (CFGR, CFGR2, SMPR,
    /// SQR: §21.7.4-21.7.11): a change while ADSTART = 1 is refused.
    fn guard_adstart(
        &self,
        offset: u32,
        value: u32,
        old: u32,
        new: u32,
        name: &str,
    ) -> Result<(), Unmodelled> {
        if self.cr & CR_ADSTART != 0 && old != new {
            return Err(Unmodelled::write(
                offset,
                value,
                format!("ADC1_{name} changed while ADSTART = 1 (RM0440 §21.7: writable only when ADSTART = 0)"),
            ));
        }
        Ok(())
    }

    fn write_cr(
        &mut self,
        now: Time,
        offset: u32,
        value: u32,
        mask: u32,
        out: &mut Signals,
    ) -> Result<(), Unmodelled> {
        let old = self.cr;
        let written = merge(old, value, mask);
        if value & mask & CR_ADEN != 0 && old & CR_ADEN != 0 {
            self.aden_written_back.push(now);
        }
        let set = written & !old & CR_RS;
        let refuse = |why: &str| Err(Unmodelled::write(offset, value, format!("ADC1_CR: {why}")));
        if set & (CR_JADSTART | CR_JADSTP) != 0 {
            return refuse("injected group (JADSTART/JADSTP) is not modelled");
        }
        let busy =
            old & (CR_ADCAL | CR_ADSTART | CR_ADSTP | CR_ADDIS | CR_JADSTART | CR_JADSTP) != 0;
        let disabled = old & CR_ADEN == 0 && !busy;
        if (written ^ old) & CR_RW != 0 && !disabled {
            return refuse(
                "DEEPPWD/ADVREGEN/ADCALDIF written while the ADC is not disabled (§21.7.3)",
            );
        }
        // rw bits take the written value; rs bits only go 0 → 1 by software. Nothing is committed
        // until every rule has passed.
        let mut cr = (old & CR_RS) | (written & CR_RW);
        let regulator_on = cr & CR_ADVREGEN != 0 && cr & CR_DEEPPWD == 0;
        let mut calibration_end_at = self.calibration_end_at;
        let mut ready_at = self.ready_at;
        let mut stop = false;
        let mut start = false;
        if set & CR_ADCAL != 0 {
            if !disabled || !regulator_on {
                return refuse(
                    "ADCAL set while the ADC is enabled/busy or its regulator is off (§21.4.8)",
                );
            }
            let tick = self
                .ticks_per_adc_cycle()
                .map_err(|why| Unmodelled::write(offset, value, why))?;
            cr |= CR_ADCAL;
            calibration_end_at = Some(now + CAL_CYCLES * tick);
        }
        if set & CR_ADEN != 0 {
            if !disabled || set & CR_ADCAL != 0 || !regulator_on {
                return refuse(
                    "ADEN set while other ADC_CR bits are set or the regulator is off (§21.4.9)",
                );
            }
            let tick = self
                .ticks_per_adc_cycle()
                .map_err(|why| Unmodelled::write(offset, value, why))?;
            cr |= CR_ADEN;
            ready_at = Some(now + STAB_CYCLES * tick);
        }
        if set & CR_ADDIS != 0 {
            if old & CR_ADEN == 0 || old & (CR_ADSTART | CR_JADSTART) != 0 {
                return refuse("ADDIS set while the ADC is not enabled or is converting (§21.4.9)");
            }
            // Disabled at once: ADEN and ADDIS read 0.
            cr &= !(CR_ADEN | CR_ADDIS);
            ready_at = None;
        }
        if set & CR_ADSTP != 0 {
            if old & CR_ADSTART == 0 || old & CR_ADDIS != 0 {
                return refuse("ADSTP set while ADSTART = 0 or ADDIS = 1 (§21.4.17)");
            }
            // The ongoing conversion is aborted and the sequence reset; ADSTART and ADSTP clear.
            cr &= !(CR_ADSTART | CR_ADSTP);
            stop = true;
        }
        if set & CR_ADSTART != 0 {
            if old & CR_ADEN == 0
                || old & CR_ADDIS != 0
                || self.ready_at.is_some()
                || set & CR_ADSTP != 0
            {
                return refuse("ADSTART set while the ADC is not enabled and ready (§21.4.15)");
            }
            cr |= CR_ADSTART;
            // Software trigger (EXTEN = 0): the sequence starts now; otherwise armed (§21.4.15).
            start = (self.cfgr >> CFGR_EXTEN_SHIFT) & 0x3 == 0;
        }
        let saved = (self.cr, self.conversion);
        self.cr = cr;
        if stop {
            self.conversion = None;
        }
        if start {
            if let Err(why) = self.trigger(now) {
                (self.cr, self.conversion) = saved;
                return Err(Unmodelled::write(offset, value, why));
            }
        }
        self.calibration_end_at = calibration_end_at;
        self.ready_at = ready_at;
        out.replan = true;
        Ok(())
    }

    fn check_cfgr(&self, offset: u32, value: u32, new: u32) -> Result<(), Unmodelled> {
        let refuse = |why: String| {
            Err(Unmodelled::write(
                offset,
                value,
                format!("ADC1_CFGR: {why}"),
            ))
        };
        if new & !CFGR_DEFINED != 0 {
            return refuse("reserved bit 2 written non-zero".into());
        }
        if new & (CFGR_DISCEN | CFGR_AUTDLY) != 0 {
            return refuse("discontinuous / auto-delayed mode is not modelled".into());
        }
        if new & (CFGR_JDISCEN | CFGR_JQM | CFGR_JAUTO | CFGR_JAWD1EN) != 0 {
            return refuse("injected group settings are not modelled".into());
        }
        if new & CFGR_AWD1EN != 0 {
            return refuse("analog watchdog 1 is not modelled".into());
        }
        if (new >> CFGR_RES_SHIFT) & 0x3 != 0 {
            return refuse("resolution other than 12-bit is not modelled".into());
        }
        let extsel = (new >> CFGR_EXTSEL_SHIFT) & 0x1F;
        if (new >> CFGR_EXTEN_SHIFT) & 0x3 != 0 && extsel_trgo_timer(extsel).is_none() {
            return refuse(format!(
                "EXTSEL = {extsel} selects a trigger other than a timer TRGO, which is not modelled"
            ));
        }
        Ok(())
    }

    fn check_cfgr2(&self, offset: u32, value: u32, new: u32) -> Result<(), Unmodelled> {
        let refuse = |why: &str| {
            Err(Unmodelled::write(
                offset,
                value,
                format!("ADC1_CFGR2: {why}"),
            ))
        };
        if new & !CFGR2_DEFINED != 0 {
            return refuse("reserved bits written non-zero");
        }
        if new & (CFGR2_JOVSE | CFGR2_GCOMP | CFGR2_SWTRIG | CFGR2_BULB | CFGR2_SMPTRIG) != 0 {
            return refuse("injected oversampling, gain compensation and sampling-time control are not modelled");
        }
        if new & CFGR2_TROVS != 0 {
            return refuse("triggered oversampling (TROVS = 1) is not modelled");
        }
        if (new >> CFGR2_OVSS_SHIFT) & 0xF > 8 {
            return refuse("OVSS above 8 is reserved");
        }
        Ok(())
    }
}

impl Peripheral for AdcG4 {
    fn name(&self) -> &'static str {
        "ADC1/ADC12 common"
    }

    fn read(&mut self, now: Time, offset: u32, out: &mut Signals) -> Result<u32, Unmodelled> {
        self.settle(now);
        match offset {
            ISR => Ok(self.isr),
            IER => Ok(self.ier),
            CR => Ok(self.cr),
            CFGR => Ok(self.cfgr),
            CFGR2 => Ok(self.cfgr2),
            SMPR1 => Ok(self.smpr1),
            SMPR2 => Ok(self.smpr2),
            SQR1 | SQR2 | SQR3 | SQR4 => Ok(self.sqr[((offset - SQR1) / 4) as usize]),
            DR => {
                // Reading ADC_DR clears EOC (§21.7.1).
                if self.isr & EOC != 0 && self.ier & EOC != 0 {
                    out.replan = true;
                }
                self.isr &= !EOC;
                Ok(self.dr)
            }
            DIFSEL => Ok(self.difsel),
            // ADC12_CSR: ADC1's ISR as master in bits 10:0; ADC2 cannot leave reset (any access to
            // it is Unmodelled), so the slave half is truly 0.
            CSR => Ok(self.isr & ISR_MASK),
            CCR => Ok(self.ccr),
            CDR | CDR2 => Err(Unmodelled::read(
                offset,
                "ADC12_CDR/CDR2 (dual-mode data) are not modelled",
            )),
            0x100..=0x2FF => Err(Unmodelled::read(offset, "ADC2 is not modelled")),
            _ => Err(Unmodelled::read(
                offset,
                "this ADC1 register (injected, watchdog, offset, calibration factor, gain) is not modelled",
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
        match offset {
            ISR => {
                // rc_w1 (§21.7.1).
                self.isr &= !(value & mask & ISR_MASK);
                out.replan = true;
            }
            IER => {
                let new = merge(self.ier, value, mask);
                if new & !IER_MODELLED != 0 {
                    return Err(Unmodelled::write(
                        offset,
                        value,
                        "ADC1_IER: only ADRDYIE, EOCIE, EOSIE and OVRIE are modelled",
                    ));
                }
                self.ier = new;
                out.replan = true;
            }
            CR => return self.write_cr(now, offset, value, mask, out),
            CFGR => {
                let new = merge(self.cfgr, value, mask);
                self.guard_adstart(offset, value, self.cfgr, new, "CFGR")?;
                self.check_cfgr(offset, value, new)?;
                self.cfgr = new;
            }
            CFGR2 => {
                let new = merge(self.cfgr2, value, mask);
                self.guard_adstart(offset, value, self.cfgr2, new, "CFGR2")?;
                self.check_cfgr2(offset, value, new)?;
                self.cfgr2 = new;
            }
            SMPR1 => {
                let new = merge(self.smpr1, value, mask) & (0x3FFF_FFFF | SMPR1_SMPPLUS);
                self.guard_adstart(offset, value, self.smpr1, new, "SMPR1")?;
                if new & SMPR1_SMPPLUS != 0 {
                    return Err(Unmodelled::write(offset, value, "ADC1_SMPR1.SMPPLUS is not modelled"));
                }
                self.smpr1 = new;
            }
            SMPR2 => {
                let new = merge(self.smpr2, value, mask) & 0x07FF_FFFF;
                self.guard_adstart(offset, value, self.smpr2, new, "SMPR2")?;
                self.smpr2 = new;
            }
            SQR1 | SQR2 | SQR3 | SQR4 => {
                let i = ((offset - SQR1) / 4) as usize;
                // SQR1: L[3:0] and SQ1-4 at 6..; SQR2/3: five 5-bit fields at 0, 6, ..; SQR4: two.
                let defined = [0x1F7D_F7CF, 0x1F7D_F7DF, 0x1F7D_F7DF, 0x0000_07DF][i];
                let new = merge(self.sqr[i], value, mask) & defined;
                self.guard_adstart(offset, value, self.sqr[i], new, "SQRx")?;
                self.sqr[i] = new;
            }
            DR => return Err(Unmodelled::write(offset, value, "ADC1_DR is read-only")),
            DIFSEL => {
                let new = merge(self.difsel, value, mask) & 0x7FFFF;
                if new != self.difsel {
                    if self.cr & (CR_ADEN | CR_ADCAL | CR_ADSTART | CR_ADSTP | CR_ADDIS) != 0 {
                        return Err(Unmodelled::write(
                            offset,
                            value,
                            "ADC1_DIFSEL changed while the ADC is not disabled (§21.7.24: writable only when ADEN = 0)",
                        ));
                    }
                    return Err(Unmodelled::write(
                        offset,
                        value,
                        "ADC1_DIFSEL differential inputs are not modelled",
                    ));
                }
            }
            CSR => return Err(Unmodelled::write(offset, value, "ADC12_CSR is read-only")),
            CCR => {
                let new = merge(self.ccr, value, mask);
                let refuse = |why: &str| Err(Unmodelled::write(offset, value, format!("ADC12_CCR: {why}")));
                if new & !CCR_DEFINED != 0 {
                    return refuse("reserved bits written non-zero");
                }
                if new & (CCR_DUAL_MASK | CCR_MDMA_MASK | CCR_DMACFG) != 0 {
                    return refuse("dual mode (DUAL/MDMA/DMACFG) is not modelled");
                }
                if (new >> CCR_PRESC_SHIFT) & 0xF > 0b1011 {
                    return refuse("PRESC code is reserved");
                }
                let clock_bits = (0x3 << CCR_CKMODE_SHIFT) | (0xF << CCR_PRESC_SHIFT);
                if (new ^ self.ccr) & clock_bits != 0 && self.cr & (CR_ADEN | CR_ADCAL) != 0 {
                    return refuse("CKMODE/PRESC changed while ADC1 is enabled (§21.8.2: writable only when the ADCs are disabled)");
                }
                // DELAY only acts in dual mode; VREFEN/VSENSEEN/VBATEN connect internal channels,
                // which the input function answers for.
                self.ccr = new;
            }
            CDR | CDR2 => return Err(Unmodelled::write(offset, value, "ADC12_CDR/CDR2 are read-only")),
            0x100..=0x2FF => return Err(Unmodelled::write(offset, value, "ADC2 is not modelled")),
            _ => {
                return Err(Unmodelled::write(
                    offset,
                    value,
                    "this ADC1 register (injected, watchdog, offset, calibration factor, gain) is not modelled",
                ))
            }
        }
        Ok(())
    }

    fn advance(&mut self, now: Time, out: &mut Signals) {
        self.settle(now);
        let mut request_outstanding = false;
        while let Some(c) = self.conversion {
            if c.end_at > now {
                break;
            }
            if self.isr & EOC == 0 {
                request_outstanding = false;
            }
            self.finish(c, &mut request_outstanding, out);
        }
        self.settle(now);
    }

    fn next_event(&self) -> Option<Time> {
        [
            self.calibration_end_at,
            self.ready_at,
            self.conversion.map(|c| c.end_at),
        ]
        .into_iter()
        .flatten()
        .min()
    }

    fn on_event(&mut self, now: Time, event: Event, out: &mut Signals) {
        if let Event::Trgo { timer } = event {
            let exten = (self.cfgr >> CFGR_EXTEN_SHIFT) & 0x3;
            let extsel = (self.cfgr >> CFGR_EXTSEL_SHIFT) & 0x1F;
            // One trigger per TRGO pulse for any EXTEN ≠ 00 (see adc_f4); ignored while ADSTART = 0
            // (§21.4.18) or while converting.
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
        if self.isr & self.ier & IER_MODELLED != 0 {
            raise(self.irq);
        }
    }

    fn reset(&mut self, _now: Time) {
        // Reset values (§21.7): CR = 0x2000_0000 (DEEPPWD), CFGR = 0x8000_0000 (JQDIS), rest 0.
        self.isr = 0;
        self.ier = 0;
        self.cr = CR_RESET;
        self.cfgr = CFGR_RESET;
        self.cfgr2 = 0;
        self.smpr1 = 0;
        self.smpr2 = 0;
        self.sqr = [0; 4];
        self.dr = 0;
        self.difsel = 0;
        self.ccr = 0;
        self.last_activity_at = None;
        self.calibration_end_at = None;
        self.ready_at = None;
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
    use crate::periph::dma_g4::{DmaG4, DmaMux};
    use std::cell::RefCell;
    use std::collections::HashMap;
    use std::rc::Rc;

    const ADC_BASE: u32 = 0x5000_0000;
    const BUF: u32 = 0x2000_0400;

    /// G474 firmware clock plan: SYSCLK = HCLK = 150 MHz, ADC12 kernel clock = SYSCLK.
    fn clocks() -> Clocks {
        Clocks {
            sysclk_hz: 150_000_000,
            hclk_hz: 150_000_000,
            pclk1_hz: 150_000_000,
            pclk2_hz: 150_000_000,
            adc_kernel_hz: 150_000_000,
            ..Default::default()
        }
    }

    fn w(p: &mut dyn Peripheral, now: Time, off: u32, v: u32) {
        let mut s = Signals::default();
        p.write(now, off, v, 0xFFFF_FFFF, &mut s)
            .unwrap_or_else(|e| panic!("{e:?}"));
    }
    fn r(p: &mut dyn Peripheral, now: Time, off: u32) -> u32 {
        p.read(now, off, &mut Signals::default()).unwrap()
    }
    fn modify(p: &mut dyn Peripheral, now: Time, off: u32, f: impl FnOnce(u32) -> u32) {
        let v = r(p, now, off);
        w(p, now, off, f(v));
    }
    fn run(adc: &mut AdcG4, to: Time) -> Signals {
        let mut all = Signals::default();
        while let Some(t) = adc.next_event().filter(|&t| t <= to) {
            let mut s = Signals::default();
            adc.advance(t, &mut s);
            all.events.extend(s.events);
        }
        all
    }

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

    /// embassy g4.rs Adc::new with PRESC /4 (150 MHz → 37.5 MHz: 96 ticks per cycle) and the
    /// firmware's oversampler settings; returns the time it is ready.
    fn bring_up(adc: &mut AdcG4, rovs: Option<(u32, u32)>) -> Time {
        let mut t = 0;
        adc.set_clocks(0, &clocks());
        modify(adc, t, CCR, |v| v | (0b0010 << CCR_PRESC_SHIFT));
        modify(adc, t, CR, |v| (v & !CR_DEEPPWD) | CR_ADVREGEN);
        t += 20 * 3_600; // 20 µs
        modify(adc, t, DIFSEL, |v| v);
        modify(adc, t, CR, |v| v & !CR_ADCALDIF);
        modify(adc, t, CR, |v| v | CR_ADCAL);
        // ADCAL stays 1 for 116 cycles × 96 ticks = 11 136 ticks.
        assert_eq!(r(adc, t + 11_135, CR) & CR_ADCAL, CR_ADCAL);
        assert_eq!(adc.next_event(), Some(t + 11_136));
        t += 11_136;
        assert_eq!(r(adc, t, CR) & CR_ADCAL, 0);
        t += 20 * 3_600;
        modify(adc, t, CR, |v| v | CR_ADCALDIF);
        modify(adc, t, CR, |v| v | CR_ADCAL);
        t += 11_136;
        assert_eq!(r(adc, t, CR) & CR_ADCAL, 0);
        t += 20 * 3_600;
        // enable(): clear ADRDY, ADEN, poll ADRDY.
        modify(adc, t, ISR, |v| v | ADRDY);
        modify(adc, t, CR, |v| v | CR_ADEN);
        assert_eq!(r(adc, t, ISR) & ADRDY, 0);
        assert_eq!(adc.next_event(), Some(t + 15 * 96));
        t += 15 * 96;
        assert_eq!(r(adc, t, ISR) & ADRDY, ADRDY);
        modify(adc, t, CFGR, |v| {
            v & !(CFGR_CONT | (0x3 << CFGR_EXTEN_SHIFT))
        });
        if let Some((ovsr, ovss)) = rovs {
            modify(adc, t, CFGR2, |v| v | (ovss << CFGR2_OVSS_SHIFT));
            modify(adc, t, CFGR2, |v| v | (ovsr << CFGR2_OVSR_SHIFT));
            modify(adc, t, CFGR2, |v| v & !CFGR2_TROVS);
            modify(adc, t, CFGR2, |v| v & !CFGR2_ROVSM);
            modify(adc, t, CFGR2, |v| v | CFGR2_ROVSE);
        }
        t
    }

    /// embassy into_ring_buffered + configure_dma: one rank of `channel` at 24.5 cycles, DMA
    /// circular, EXTEN rising on TIM3_TRGO (EXTSEL 4), EOSIE off.
    fn configure_ring_buffered(adc: &mut AdcG4, t: Time, channel: u32) {
        modify(adc, t, CFGR, |v| v & !(CFGR_CONT | CFGR_DMAEN));
        modify(adc, t, CR, |v| v & !CR_ADEN); // no effect: rs bit
        w(adc, t, SMPR1, 0b011 << (3 * channel));
        w(adc, t, SMPR2, 0);
        w(adc, t, SQR1, channel << 6);
        w(adc, t, SQR2, 0);
        w(adc, t, SQR3, 0);
        w(adc, t, SQR4, 0);
        w(adc, t, DIFSEL, 0);
        modify(adc, t, ISR, |v| v | OVR);
        modify(adc, t, CFGR, |v| v | CFGR_DMACFG | CFGR_DMAEN);
        modify(adc, t, CFGR, |v| v & !CFGR_CONT);
        modify(adc, t, CFGR, |v| {
            v | (4 << CFGR_EXTSEL_SHIFT) | (1 << CFGR_EXTEN_SHIFT)
        });
        modify(adc, t, IER, |v| v & !EOS);
        assert_eq!(r(adc, t, CR) & CR_ADEN, CR_ADEN);
    }

    #[test]
    fn reset_values_and_power_rules() {
        let mut adc = AdcG4::new(18, Box::new(|_, _| Some(0)));
        adc.set_clocks(0, &clocks());
        assert_eq!(r(&mut adc, 0, CR), 0x2000_0000);
        assert_eq!(r(&mut adc, 0, CFGR), 0x8000_0000);
        let mut s = Signals::default();
        // ADCAL in deep power-down / without the regulator is refused.
        assert!(adc.write(0, CR, CR_DEEPPWD | CR_ADCAL, !0, &mut s).is_err());
        assert!(adc.write(0, CR, CR_ADEN, !0, &mut s).is_err());
        w(&mut adc, 0, CR, CR_ADVREGEN);
        w(&mut adc, 0, CR, CR_ADVREGEN | CR_ADEN);
        // Regulator bits are locked while enabled.
        assert!(adc.write(10, CR, CR_ADEN, !0, &mut s).is_err());
        // ADSTART before ADRDY is refused.
        assert!(adc
            .write(10, CR, CR_ADVREGEN | CR_ADEN | CR_ADSTART, !0, &mut s)
            .is_err());
    }

    #[test]
    fn software_start_converts_one_sequence_and_clears_adstart() {
        let log = Rc::new(RefCell::new(Vec::new()));
        let mut adc = AdcG4::new(18, counting_input(700, log.clone()));
        let t = bring_up(&mut adc, None);
        // Ranks: channel 2 at 24.5 cycles, channel 3 at 2.5 cycles.
        w(&mut adc, t, SMPR1, 0b011 << 6); // channel 3: code 000
        w(&mut adc, t, SQR1, 1 | (2 << 6) | (3 << 12));
        modify(&mut adc, t, CR, |v| v | CR_ADSTART);
        // Rank 1: (24.5 + 12.5) × 96 = 3 552 ticks; rank 2: (2.5 + 12.5) × 96 = 1 440 ticks.
        assert_eq!(adc.next_event(), Some(t + 3_552));
        run(&mut adc, t + 3_552);
        assert_eq!(r(&mut adc, t + 3_552, ISR) & (EOC | EOS), EOC);
        assert_eq!(r(&mut adc, t + 3_552, DR), 700);
        assert_eq!(adc.next_event(), Some(t + 4_992));
        run(&mut adc, t + 4_992);
        assert_eq!(r(&mut adc, t + 4_992, ISR) & (EOC | EOS), EOC | EOS);
        assert_eq!(
            r(&mut adc, t + 4_992, CR) & CR_ADSTART,
            0,
            "ADSTART clears at EOS (software trigger)"
        );
        assert_eq!(r(&mut adc, t + 4_992, DR), 701);
        // Inputs held at the end of sampling: 24.5 × 96 = 2 352 and 3 552 + 2.5 × 96 = 3 792.
        assert_eq!(*log.borrow(), vec![(t + 2_352, 2), (t + 3_792, 3)]);
    }

    #[test]
    fn oversampler_ratio16_shift0_sums_sixteen_conversions() {
        let log = Rc::new(RefCell::new(Vec::new()));
        // Codes 4000, 4001, ..., 4015: sum = 16 × 4000 + 120 = 64 120 (fits 16 bits).
        let mut adc = AdcG4::new(18, counting_input(4000, log.clone()));
        let t0 = bring_up(&mut adc, Some((0b011, 0)));
        configure_ring_buffered(&mut adc, t0, 2);
        modify(&mut adc, t0, CR, |v| v | CR_ADSTART);
        assert_eq!(
            adc.next_event(),
            None,
            "EXTEN rising: armed, waiting for TRGO"
        );
        let t = t0 + 1_000;
        let mut s = Signals::default();
        adc.on_event(t, Event::Trgo { timer: 3 }, &mut s);
        // 16 × 37 cycles × 96 ticks = 56 832 ticks.
        assert_eq!(adc.next_event(), Some(t + 56_832));
        let s = run(&mut adc, t + 56_831);
        assert!(s.events.is_empty());
        assert_eq!(
            r(&mut adc, t, ISR) & EOC,
            0,
            "no EOC before the 16th conversion"
        );
        let s = run(&mut adc, t + 56_832);
        assert_eq!(
            s.events,
            vec![(t + 56_832, Event::DmaRequest(Request::Adc1))]
        );
        assert_eq!(r(&mut adc, t, DR), 64_120);
        assert_eq!(log.borrow().len(), 16);
        // Each held at its own sampling end: t + k × 3 552 + 2 352.
        for (k, &(at, ch)) in log.borrow().iter().enumerate() {
            assert_eq!((at, ch), (t + k as u64 * 3_552 + 2_352, 2));
        }
        assert_eq!(
            r(&mut adc, t, CR) & CR_ADSTART,
            CR_ADSTART,
            "hardware trigger: ADSTART stays 1"
        );
    }

    /// ES0430's late conversion: a trigger more than 1 ms after the calibration finds the first
    /// of its 16 conversions read as 0; the next trigger, 100 µs later, converts all 16. At
    /// exactly 1 ms after the previous conversion nothing is lost.
    #[test]
    fn a_conversion_more_than_1_ms_late_reads_wrong() {
        let log = Rc::new(RefCell::new(Vec::new()));
        let mut adc = AdcG4::new(18, counting_input(4000, log.clone()));
        let t0 = bring_up(&mut adc, Some((0b011, 0)));
        configure_ring_buffered(&mut adc, t0, 2);
        modify(&mut adc, t0, CR, |v| v | CR_ADSTART);
        // 2 ms after ADRDY: more than 1 ms after the calibration.
        let t = t0 + 2 * TICKS_PER_S / 1_000;
        adc.on_event(t, Event::Trgo { timer: 3 }, &mut Signals::default());
        run(&mut adc, t + 56_832);
        // Codes 4000..=4015 with the first lost: 64 120 − 4 000.
        assert_eq!(r(&mut adc, t, DR), 60_120);
        let t = t + 360_000; // 100 µs later
        adc.on_event(t, Event::Trgo { timer: 3 }, &mut Signals::default());
        run(&mut adc, t + 56_832);
        // Codes 4016..=4031: 16 × 4016 + 120.
        assert_eq!(r(&mut adc, t, DR), 64_376);
        // Exactly 1 ms after the previous sequence's end: not late.
        let t = t + 56_832 + TICKS_PER_S / 1_000;
        adc.on_event(t, Event::Trgo { timer: 3 }, &mut Signals::default());
        run(&mut adc, t + 56_832);
        assert_eq!(r(&mut adc, t, DR), 16 * 4032 + 120);
    }

    #[test]
    fn oversampler_shift_rounds_and_truncates() {
        // RM0440 table "Maximum output results vs N and M" with raw data 0xFFF.
        let cases = [
            (0b000, 2, 0x0800),
            (0b011, 4, 0x0FFF),
            (0b100, 0, 0xFFE0),
            // The firmware's setting (32×, shift 1): the 16-conversion code's full scale.
            (0b100, 1, 0xFFF0),
            (0b111, 8, 0x0FFF),
        ];
        for (ovsr, ovss, expected) in cases {
            let mut adc = AdcG4::new(18, Box::new(|_, _| Some(0xFFF)));
            let t = bring_up(&mut adc, Some((ovsr, ovss)));
            modify(&mut adc, t, CR, |v| v | CR_ADSTART);
            run(&mut adc, u64::MAX / 2);
            assert_eq!(r(&mut adc, t, DR), expected, "OVSR {ovsr:#05b} OVSS {ovss}");
        }
        // Rounding to nearest, a half up (§21.4.30): 32 conversions summing to an odd number
        // (one reads 1, the rest 0: 1 → 1 after a 1-bit shift, where truncation gives 0; all 1
        // but one 0: 31 → 16, not 15).
        for (first, rest, expected) in [(1u16, 0u16, 1u32), (0, 1, 16)] {
            let k = Rc::new(RefCell::new(0u32));
            let k2 = k.clone();
            let mut adc = AdcG4::new(
                18,
                Box::new(move |_, _| {
                    let i = *k2.borrow();
                    *k2.borrow_mut() += 1;
                    Some(if i % 32 == 0 { first } else { rest })
                }),
            );
            let t = bring_up(&mut adc, Some((0b100, 1)));
            modify(&mut adc, t, CR, |v| v | CR_ADSTART);
            run(&mut adc, u64::MAX / 2);
            assert_eq!(r(&mut adc, t, DR), expected, "first {first}, rest {rest}");
            assert!(*k.borrow() >= 32);
        }
    }

    #[test]
    fn triggers_are_ignored_while_adstart_is_0() {
        let mut adc = AdcG4::new(18, Box::new(|_, _| Some(1)));
        let t = bring_up(&mut adc, Some((0b011, 0)));
        configure_ring_buffered(&mut adc, t, 2);
        // TIM3 UG during Sampler::new, before start(): ADSTART = 0.
        adc.on_event(t + 10, Event::Trgo { timer: 3 }, &mut Signals::default());
        assert_eq!(adc.next_event(), None);
        modify(&mut adc, t + 20, CR, |v| v | CR_ADSTART);
        adc.on_event(t + 30, Event::Trgo { timer: 4 }, &mut Signals::default());
        assert_eq!(
            adc.next_event(),
            None,
            "TIM4 TRGO is not the selected trigger"
        );
        adc.on_event(t + 40, Event::Trgo { timer: 3 }, &mut Signals::default());
        assert_eq!(adc.next_event(), Some(t + 40 + 56_832));
        // A trigger during the conversion is ignored.
        adc.on_event(t + 50, Event::Trgo { timer: 3 }, &mut Signals::default());
        assert_eq!(adc.next_event(), Some(t + 40 + 56_832));
        // Configuration is locked while ADSTART = 1; ADSTP stops at once.
        assert!(adc
            .write(t + 60, CFGR2, 0, !0, &mut Signals::default())
            .is_err());
        modify(&mut adc, t + 60, CR, |v| v | CR_ADSTP);
        assert_eq!(r(&mut adc, t + 60, CR) & (CR_ADSTART | CR_ADSTP), 0);
        assert_eq!(adc.next_event(), None);
    }

    #[test]
    fn overrun_blocks_dma_requests_until_cleared() {
        let mut adc = AdcG4::new(18, Box::new(|_, _| Some(0x123)));
        let t = bring_up(&mut adc, None);
        configure_ring_buffered(&mut adc, t, 2);
        modify(&mut adc, t, CR, |v| v | CR_ADSTART);
        let mut at = t;
        let mut trig = |adc: &mut AdcG4| {
            at += 100_000;
            adc.on_event(at, Event::Trgo { timer: 3 }, &mut Signals::default());
            run(adc, at + 10_000).events.len()
        };
        assert_eq!(trig(&mut adc), 1, "first result: request (nobody reads DR)");
        assert_eq!(trig(&mut adc), 0, "EOC still 1: overrun, no request");
        assert_eq!(r(&mut adc, 0, ISR) & OVR, OVR);
        assert_eq!(
            trig(&mut adc),
            0,
            "conversions go on, requests stay blocked"
        );
        modify(&mut adc, 0, ISR, |_| OVR | EOC);
        assert_eq!(trig(&mut adc), 1, "OVR cleared: requests resume");
        assert_eq!(adc.fault(), None);
    }

    #[test]
    fn unmodelled_settings_fail_loudly() {
        let mut adc = AdcG4::new(18, Box::new(|_, _| Some(1)));
        let mut s = Signals::default();
        assert!(adc
            .write(
                0,
                CFGR,
                CFGR_RESET | (1 << CFGR_EXTEN_SHIFT) | (3 << CFGR_EXTSEL_SHIFT),
                !0,
                &mut s
            )
            .is_err());
        assert!(adc
            .write(0, CFGR, CFGR_RESET | CFGR_DISCEN, !0, &mut s)
            .is_err());
        assert!(adc.write(0, CFGR2, CFGR2_TROVS, !0, &mut s).is_err());
        assert!(adc.write(0, IER, 1 << 1, !0, &mut s).is_err(), "EOSMPIE");
        assert!(adc.write(0, DIFSEL, 1 << 2, !0, &mut s).is_err());
        assert!(adc.write(0, CCR, 1, !0, &mut s).is_err(), "dual mode");
        assert!(adc.read(0, 0x100, &mut s).is_err(), "ADC2");
        assert!(adc.read(0, 0xB4, &mut s).is_err(), "CALFACT");
    }

    /// ADC1 → DMAMUX channel 0 (request 5) → DMA1 channel 1 circular over 4 half-words, as the
    /// firmware's G474 sampler sets it up (embassy dmamux.rs configure_dmamux, dma_bdma.rs).
    #[test]
    fn oversampled_results_reach_memory_through_dmamux_and_dma() {
        let n = Rc::new(RefCell::new(0u16));
        let n2 = n.clone();
        // Conversion codes 100 + k for the k-th trigger: the firmware's 32× with shift 1 makes
        // each result 32 × (100 + k) / 2 = 16 × (100 + k).
        let mut adc = AdcG4::new(18, Box::new(move |_, _| Some(100 + *n2.borrow())));
        let t0 = bring_up(&mut adc, Some((0b100, 1)));
        configure_ring_buffered(&mut adc, t0, 2);
        let mut mux = DmaMux::new();
        let mut dma = DmaG4::new(1, [11, 12, 13, 14, 15, 16, 17, 96]);
        w(&mut mux, t0, 0x00, 5);
        modify(&mut mux, t0, 0x00, |v| v | (1 << 9)); // EGE
        w(&mut dma, t0, 0x04, 0b1111); // IFCR ch1
        w(&mut dma, t0, 0x10, ADC_BASE + DR); // CPAR1
        w(&mut dma, t0, 0x14, BUF); // CMAR1
        w(&mut dma, t0, 0x0C, 4); // CNDTR1
                                  // CCR1: PSIZE/MSIZE 16, MINC, CIRC, TEIE/HTIE/TCIE, PL very high, EN = 0.
        let ccr =
            (1 << 8) | (1 << 10) | (1 << 7) | (1 << 5) | (1 << 3) | (1 << 2) | (1 << 1) | (3 << 12);
        w(&mut dma, t0, 0x08, ccr);
        // Sampler::start: DMA EN, ADSTART; then TIM3 runs.
        w(&mut dma, t0, 0x08, ccr | 1);
        modify(&mut adc, t0, CR, |v| v | CR_ADSTART);
        let mut ram: HashMap<u32, u16> = HashMap::new();
        for k in 0..6u64 {
            *n.borrow_mut() = k as u16;
            let t = t0 + 1_000 + k * 360_000; // 100 µs
            adc.on_event(t, Event::Trgo { timer: 3 }, &mut Signals::default());
            // The 32 conversions end inside 300 000 ticks (83 µs) of the trigger.
            while let Some(next) = adc.next_event().filter(|&x| x <= t + 300_000) {
                let mut s = Signals::default();
                adc.advance(next, &mut s);
                for (at, ev) in s.events {
                    let mut routed = Signals::default();
                    mux.on_event(at, ev, &mut routed);
                    assert_eq!(
                        routed.events,
                        vec![(
                            at,
                            Event::DmaChannelRequest {
                                controller: 1,
                                channel: 1
                            }
                        )]
                    );
                    for (at2, ev2) in routed.events {
                        let mut moved = Signals::default();
                        dma.on_event(at2, ev2, &mut moved);
                        for c in moved.copies {
                            let v = adc
                                .read(at2, c.from - ADC_BASE, &mut Signals::default())
                                .unwrap() as u16;
                            ram.insert(c.to, v);
                        }
                    }
                }
            }
            let isr = r(&mut dma, t, 0x00);
            match k {
                1 => assert_eq!(isr & 0b1111, 0b0101, "HT after 2 of 4 (GIF | HTIF)"),
                3 => assert_eq!(isr & 0b1111, 0b0111, "TC after 4 of 4"),
                _ => {}
            }
        }
        // Six results in a ring of four: slots hold results 4, 5, 2, 3.
        let got: Vec<u16> = (0..4).map(|i| ram[&(BUF + 2 * i)]).collect();
        assert_eq!(got, vec![16 * 104, 16 * 105, 16 * 102, 16 * 103]);
        assert_eq!(r(&mut dma, 0, 0x0C), 2);
        assert_eq!(r(&mut adc, 0, ISR) & OVR, 0);
        assert_eq!(adc.fault(), None);
    }
}
