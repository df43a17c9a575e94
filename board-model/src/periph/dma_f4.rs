//! STM32F446 DMA1/DMA2 controller (RM0390 §9): eight streams, each a single-item transfer per
//! peripheral request in direct mode (peripheral-to-memory or memory-to-peripheral), with normal or
//! circular mode, HT/TC flags and interrupts, and the stream/channel request mapping of table 29.
//! FIFO mode, double-buffer mode, peripheral flow control, memory-to-memory and bursts are not
//! modelled: enabling a stream that uses them is `Unmodelled`.
//!
//! Behaviours this model commits to:
//! - A request reaches the stream whose CHSEL selects it (§9.3.4, tables 28/29). A request to a
//!   disabled stream, or to one whose NDTR is 0, is dropped (the requesting peripheral sees its
//!   data unread: that is how the ADC ends in overrun).
//! - Each request moves one item at once: a `Copy` of PSIZE bytes, NDTR − 1. HTIF is set the
//!   first time at least half of the items have been moved (the manual says "half"; for an odd
//!   count it does not say which side, uncertain), TCIF when NDTR reaches 0. Circular mode reloads
//!   NDTR and the addresses (§9.3.9); normal mode clears EN (§9.5.5).
//! - Setting EN while any of the stream's flags in LISR/HISR is still set is refused
//!   (`Unmodelled`): §9.5.5 says the flags "must be cleared" first and does not say what the
//!   hardware does otherwise. Re-enabling a stream without rewriting NDTR (resuming a suspended
//!   transfer, §9.3.15) is refused likewise.
//! - Clearing EN takes effect at once (reads 0 on the next access: this model has no transfer in
//!   flight, since every transfer completes within the request) and sets TCIF, as §9.3.15 says
//!   for a stream disabled by software.
//! - While EN = 1 the configuration bits of SxCR and the NDTR/PAR/M0AR/M1AR/FCR registers are
//!   write-protected (§9.5.5-9.5.10): a write that would change them is `Unmodelled`.
//! - In direct mode MSIZE is forced to PSIZE and the burst fields to single when EN is set
//!   (§9.5.5), and reads show it. Transfer errors (TEIF), FIFO and direct-mode errors are never
//!   raised: the board does not report bus errors back.

use super::{merge, Copy, Event, Peripheral, Request, Signals, Time, Unmodelled};
use std::any::Any;

const LISR: u32 = 0x00;
const HISR: u32 = 0x04;
const LIFCR: u32 = 0x08;
const HIFCR: u32 = 0x0C;
/// Stream x registers at 0x10 + 0x18 × x (§9.5.11 register map).
const STREAM_BASE: u32 = 0x10;
const STREAM_STRIDE: u32 = 0x18;
const STREAMS: usize = 8;

// Per-stream flag bits inside its 6-bit group of LISR/HISR (§9.5.1).
const FEIF: u32 = 1 << 0;
const DMEIF: u32 = 1 << 2;
const TEIF: u32 = 1 << 3;
const HTIF: u32 = 1 << 4;
const TCIF: u32 = 1 << 5;
const FLAGS: u32 = FEIF | DMEIF | TEIF | HTIF | TCIF;
/// Bit position of stream (x mod 4)'s group in LISR/HISR.
const GROUP_SHIFT: [u32; 4] = [0, 6, 16, 22];

// DMA_SxCR (§9.5.5).
const CR_EN: u32 = 1 << 0;
const CR_DMEIE: u32 = 1 << 1;
const CR_TEIE: u32 = 1 << 2;
const CR_HTIE: u32 = 1 << 3;
const CR_TCIE: u32 = 1 << 4;
const CR_PFCTRL: u32 = 1 << 5;
const CR_DIR_SHIFT: u32 = 6;
const CR_CIRC: u32 = 1 << 8;
const CR_PINC: u32 = 1 << 9;
const CR_MINC: u32 = 1 << 10;
const CR_PSIZE_SHIFT: u32 = 11;
const CR_MSIZE_SHIFT: u32 = 13;
const CR_PINCOS: u32 = 1 << 15;
const CR_DBM: u32 = 1 << 18;
const CR_PBURST_MASK: u32 = 0x3 << 21;
const CR_MBURST_MASK: u32 = 0x3 << 23;
const CR_CHSEL_SHIFT: u32 = 25;
/// Bits 27:0 except reserved bit 20 and bits 31:28 (CHSEL is 3 bits on the F446: 27:25).
const CR_DEFINED: u32 = 0x0FEF_FFFF;
/// Bits that may change while EN = 1: EN itself and the interrupt enables. Everything else
/// "can be written only if EN is 0" (§9.5.5).
const CR_FREE: u32 = CR_EN | CR_DMEIE | CR_TEIE | CR_HTIE | CR_TCIE;

// DMA_SxFCR (§9.5.10).
const FCR_FTH_MASK: u32 = 0x3;
const FCR_DMDIS: u32 = 1 << 2;
const FCR_FS_EMPTY: u32 = 0b100 << 3;
const FCR_FEIE: u32 = 1 << 7;
/// Reset value 0x0000_0021: FTH = 1/2, FS = empty.
const FCR_RESET: u32 = 0x21;

/// The request a stream/channel pair carries (RM0390 §9.3.4, table 29 for DMA2; only the sources
/// the board models are listed).
fn request_for(controller: u8, stream: usize, channel: u32) -> Option<Request> {
    match (controller, stream, channel) {
        // DMA2 stream 0 channel 0 and stream 4 channel 0: ADC1.
        (2, 0, 0) | (2, 4, 0) => Some(Request::Adc1),
        // DMA1 stream 5 channel 4: USART2_RX; stream 6 channel 4: USART2_TX (table 28).
        (1, 5, 4) => Some(Request::Usart2Rx),
        (1, 6, 4) => Some(Request::Usart2Tx),
        // DMA1 stream 5 channel 7: DAC1 (table 28).
        (1, 5, 7) => Some(Request::Dac1Ch1),
        // DMA2 stream 2 channel 7: TIM8_CH1 (table 29; stm32-metapac 21 agrees: TIM8 CH1 on
        // DMA2_CH2 request 7). Channel 0 of the same stream carries TIM8_CH1/CH2/CH3 together:
        // not modelled.
        (2, 2, 7) => Some(Request::TimCc {
            timer: 8,
            channel: 1,
        }),
        _ => None,
    }
}

/// Bytes per item for a PSIZE/MSIZE code (00 byte, 01 half-word, 10 word, 11 reserved).
fn size_bytes(code: u32) -> Option<u8> {
    match code {
        0 => Some(1),
        1 => Some(2),
        2 => Some(4),
        _ => None,
    }
}

/// What the stream latched when it was enabled.
#[derive(Clone, Copy, Debug)]
struct Transfer {
    par: u32,
    m0ar: u32,
    /// NDTR at enable: the count circular mode reloads.
    items: u32,
    item_bytes: u8,
}

#[derive(Clone, Copy, Debug, Default)]
struct Stream {
    cr: u32,
    ndtr: u32,
    par: u32,
    m0ar: u32,
    m1ar: u32,
    fcr: u32,
    /// LISR/HISR bits of this stream, in group position 0 (FEIF..TCIF).
    flags: u32,
    /// The last NDTR value software wrote (to tell a fresh start from a resume).
    ndtr_written: u32,
    transfer: Option<Transfer>,
}

/// One DMA controller (DMA1 or DMA2) of the F446.
pub struct DmaF4 {
    number: u8,
    irqs: [u16; 8],
    /// Absolute base address, for messages.
    base: u32,
    streams: [Stream; STREAMS],
    /// Level-sensitive requests that are high now (`Event::DmaLevel`).
    levels: Vec<Request>,
}

impl DmaF4 {
    /// Serves `request` on every enabled stream that selects it.
    fn serve_request(&mut self, request: Request, out: &mut Signals) {
        for x in 0..STREAMS {
            let chsel = (self.streams[x].cr >> CR_CHSEL_SHIFT) & 0x7;
            if self.streams[x].cr & CR_EN != 0
                && request_for(self.number, x, chsel) == Some(request)
            {
                self.serve(x, out);
            }
        }
    }

    /// `number`: 1 or 2; `irqs`: NVIC lines of streams 0..7; `base`: 0x4002_6000 / 0x4002_6400.
    pub fn new(number: u8, irqs: [u16; 8], base: u32) -> Self {
        let mut dma = DmaF4 {
            number,
            irqs,
            base,
            streams: [Stream::default(); STREAMS],
            levels: Vec::new(),
        };
        dma.reset(0);
        dma
    }

    fn isr(&self, high: bool) -> u32 {
        let first = if high { 4 } else { 0 };
        (0..4).fold(0, |acc, i| {
            acc | (self.streams[first + i].flags << GROUP_SHIFT[i])
        })
    }

    fn clear_flags(&mut self, high: bool, bits: u32) {
        let first = if high { 4 } else { 0 };
        for (i, shift) in GROUP_SHIFT.iter().enumerate() {
            self.streams[first + i].flags &= !((bits >> shift) & FLAGS);
        }
    }

    /// Checks and latches a stream being enabled (EN 0 → 1).
    fn enable(&mut self, x: usize, offset: u32, value: u32, cr: u32) -> Result<u32, Unmodelled> {
        let n = self.number;
        let refuse = |why: String| {
            Err(Unmodelled::write(
                offset,
                value,
                format!("DMA{n} stream {x}: {why}"),
            ))
        };
        let s = &self.streams[x];
        if s.flags != 0 {
            return refuse(format!(
                "EN set while its LISR/HISR flags {:#07b} are uncleared (RM0390 §9.5.5: they must be cleared first)",
                s.flags
            ));
        }
        if s.fcr & FCR_DMDIS != 0 {
            return refuse("FIFO mode (FCR.DMDIS = 1) is not modelled".into());
        }
        if cr & CR_DBM != 0 {
            return refuse("double-buffer mode is not modelled".into());
        }
        if cr & CR_PFCTRL != 0 {
            return refuse("peripheral flow control is not modelled".into());
        }
        let dir = (cr >> CR_DIR_SHIFT) & 0x3;
        if dir > 1 {
            return refuse(format!(
                "DIR = {dir:#04b} (memory-to-memory or reserved) is not modelled"
            ));
        }
        if cr & CR_PINC != 0 && cr & CR_PINCOS != 0 {
            return refuse("PINCOS = 1 is not modelled".into());
        }
        let Some(item_bytes) = size_bytes((cr >> CR_PSIZE_SHIFT) & 0x3) else {
            return refuse("PSIZE = 11 is reserved".into());
        };
        let chsel = (cr >> CR_CHSEL_SHIFT) & 0x7;
        if request_for(self.number, x, chsel).is_none() {
            return refuse(format!("channel {chsel} request is not modelled"));
        }
        if s.ndtr != s.ndtr_written {
            return refuse(format!(
                "re-enabled with NDTR = {} left from a stopped transfer (written {}): resuming is not modelled",
                s.ndtr, s.ndtr_written
            ));
        }
        let transfer = Transfer {
            par: s.par,
            m0ar: s.m0ar,
            items: s.ndtr,
            item_bytes,
        };
        self.streams[x].transfer = Some(transfer);
        // Direct mode: MSIZE forced to PSIZE, bursts to single, as soon as EN = 1 (§9.5.5).
        let psize = (cr >> CR_PSIZE_SHIFT) & 0x3;
        Ok(
            (cr & !(0x3 << CR_MSIZE_SHIFT) & !CR_PBURST_MASK & !CR_MBURST_MASK)
                | (psize << CR_MSIZE_SHIFT),
        )
    }

    fn write_cr(
        &mut self,
        x: usize,
        offset: u32,
        value: u32,
        mask: u32,
        out: &mut Signals,
    ) -> Result<(), Unmodelled> {
        let old = self.streams[x].cr;
        let new = merge(old, value, mask);
        if new & !CR_DEFINED != 0 {
            return Err(Unmodelled::write(
                offset,
                value,
                format!("DMA{} S{x}CR reserved bits written non-zero", self.number),
            ));
        }
        let was_on = old & CR_EN != 0;
        if was_on && (new ^ old) & !CR_FREE != 0 {
            return Err(Unmodelled::write(
                offset,
                value,
                format!(
                    "DMA{} S{x}CR configuration bits changed while EN = 1 (RM0390 §9.5.5: writable only if EN = 0)",
                    self.number
                ),
            ));
        }
        let cr = match (was_on, new & CR_EN != 0) {
            (false, true) => self.enable(x, offset, value, new)?,
            (true, false) => {
                // Disabled by software: effective at once, and TCIF is set to mark the end of the
                // transfer (§9.3.15). NDTR keeps the items left.
                self.streams[x].transfer = None;
                self.streams[x].flags |= TCIF;
                new
            }
            _ => new,
        };
        self.streams[x].cr = cr;
        out.replan = true;
        // A level-sensitive request already high is served as soon as its stream is enabled.
        if !was_on && cr & CR_EN != 0 {
            let chsel = (cr >> CR_CHSEL_SHIFT) & 0x7;
            if let Some(r) = request_for(self.number, x, chsel) {
                if self.levels.contains(&r) {
                    self.serve(x, out);
                }
            }
        }
        Ok(())
    }

    /// One request on stream `x`: move one item.
    fn serve(&mut self, x: usize, out: &mut Signals) {
        let s = &mut self.streams[x];
        let Some(t) = s.transfer else { return };
        if s.cr & CR_EN == 0 || s.ndtr == 0 {
            return; // "If the value is zero, no transaction can be served" (§9.5.6).
        }
        let index = t.items - s.ndtr;
        let step = t.item_bytes as u32;
        let periph = if s.cr & CR_PINC != 0 {
            t.par.wrapping_add(index * step)
        } else {
            t.par
        };
        let memory = if s.cr & CR_MINC != 0 {
            t.m0ar.wrapping_add(index * step)
        } else {
            t.m0ar
        };
        let (from, to) = if (s.cr >> CR_DIR_SHIFT) & 0x3 == 0 {
            (periph, memory)
        } else {
            (memory, periph)
        };
        out.copies.push(Copy {
            from,
            to,
            size: t.item_bytes,
        });
        s.ndtr -= 1;
        let moved = t.items - s.ndtr;
        // HTIF the first time at least half the items have moved (see module doc).
        if 2 * moved >= t.items && 2 * (moved - 1) < t.items {
            s.flags |= HTIF;
        }
        if s.ndtr == 0 {
            s.flags |= TCIF;
            if s.cr & CR_CIRC != 0 {
                s.ndtr = t.items; // §9.3.9: NDTR reloaded, addresses back to the bases.
            } else {
                s.cr &= !CR_EN; // §9.5.5: EN cleared by hardware at the end of the transfer.
                s.transfer = None;
            }
        }
        out.replan = true;
    }

    fn stream_reg_name(reg: u32) -> &'static str {
        ["CR", "NDTR", "PAR", "M0AR", "M1AR", "FCR"][(reg / 4) as usize]
    }
}

impl Peripheral for DmaF4 {
    fn name(&self) -> &'static str {
        match self.number {
            1 => "DMA1",
            _ => "DMA2",
        }
    }

    fn read(&mut self, _now: Time, offset: u32, _out: &mut Signals) -> Result<u32, Unmodelled> {
        match offset {
            LISR => Ok(self.isr(false)),
            HISR => Ok(self.isr(true)),
            LIFCR | HIFCR => Err(Unmodelled::read(
                offset,
                format!("DMA{} LIFCR/HIFCR are write-only", self.number),
            )),
            STREAM_BASE..=0xCF => {
                let x = ((offset - STREAM_BASE) / STREAM_STRIDE) as usize;
                let s = &self.streams[x];
                Ok(match (offset - STREAM_BASE) % STREAM_STRIDE {
                    0x00 => s.cr,
                    0x04 => s.ndtr,
                    0x08 => s.par,
                    0x0C => s.m0ar,
                    0x10 => s.m1ar,
                    _ => s.fcr,
                })
            }
            _ => Err(Unmodelled::read(
                offset,
                format!("no DMA register at {:#010x}", self.base + offset),
            )),
        }
    }

    fn write(
        &mut self,
        _now: Time,
        offset: u32,
        value: u32,
        mask: u32,
        out: &mut Signals,
    ) -> Result<(), Unmodelled> {
        match offset {
            LISR | HISR => {
                return Err(Unmodelled::write(
                    offset,
                    value,
                    format!("DMA{} LISR/HISR are read-only", self.number),
                ))
            }
            LIFCR | HIFCR => {
                // Write 1 to clear (§9.5.3/4).
                self.clear_flags(offset == HIFCR, value & mask);
                out.replan = true;
            }
            STREAM_BASE..=0xCF => {
                let x = ((offset - STREAM_BASE) / STREAM_STRIDE) as usize;
                let reg = (offset - STREAM_BASE) % STREAM_STRIDE;
                if reg == 0 {
                    return self.write_cr(x, offset, value, mask, out);
                }
                let n = self.number;
                let s = &mut self.streams[x];
                let (field, writable) = match reg {
                    0x04 => (&mut s.ndtr, 0xFFFF),
                    0x08 => (&mut s.par, 0xFFFF_FFFF),
                    0x0C => (&mut s.m0ar, 0xFFFF_FFFF),
                    0x10 => (&mut s.m1ar, 0xFFFF_FFFF),
                    _ => (&mut s.fcr, FCR_FTH_MASK | FCR_DMDIS | FCR_FEIE),
                };
                let new = merge(*field, value, mask & writable);
                // FEIE may change at any time; everything else here is write-protected while EN = 1
                // (§9.5.6-9.5.10).
                let protected_change = (new ^ *field) & !(if reg == 0x14 { FCR_FEIE } else { 0 });
                if s.cr & CR_EN != 0 && protected_change != 0 {
                    return Err(Unmodelled::write(
                        offset,
                        value,
                        format!(
                            "DMA{n} S{x}{} written while the stream is enabled",
                            Self::stream_reg_name(reg)
                        ),
                    ));
                }
                *field = new;
                if reg == 0x04 {
                    s.ndtr_written = new;
                }
                if reg == 0x14 {
                    s.fcr = (s.fcr & !(0b111 << 3)) | FCR_FS_EMPTY;
                }
            }
            _ => {
                return Err(Unmodelled::write(
                    offset,
                    value,
                    format!("no DMA register at {:#010x}", self.base + offset),
                ))
            }
        }
        Ok(())
    }

    fn on_event(&mut self, _now: Time, event: Event, out: &mut Signals) {
        if let Event::DmaLevel { request, high } = event {
            self.levels.retain(|r| *r != request);
            if high {
                self.levels.push(request);
                self.serve_request(request, out);
            }
            return;
        }
        if let Event::DmaRequest(request) = event {
            for x in 0..STREAMS {
                let chsel = (self.streams[x].cr >> CR_CHSEL_SHIFT) & 0x7;
                if self.streams[x].cr & CR_EN != 0
                    && request_for(self.number, x, chsel) == Some(request)
                {
                    self.serve(x, out);
                }
            }
        }
    }

    fn irq_lines(&self, raise: &mut dyn FnMut(u16)) {
        for (x, s) in self.streams.iter().enumerate() {
            let up = (s.flags & TCIF != 0 && s.cr & CR_TCIE != 0)
                || (s.flags & HTIF != 0 && s.cr & CR_HTIE != 0)
                || (s.flags & TEIF != 0 && s.cr & CR_TEIE != 0)
                || (s.flags & DMEIF != 0 && s.cr & CR_DMEIE != 0)
                || (s.flags & FEIF != 0 && s.fcr & FCR_FEIE != 0);
            if up {
                raise(self.irqs[x]);
            }
        }
    }

    fn reset(&mut self, _now: Time) {
        self.levels.clear();
        for s in self.streams.iter_mut() {
            *s = Stream {
                fcr: FCR_RESET,
                ..Stream::default()
            };
        }
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

    const S0CR: u32 = 0x10;
    const S0NDTR: u32 = 0x14;
    const S0PAR: u32 = 0x18;
    const S0M0AR: u32 = 0x1C;
    const S0FCR: u32 = 0x24;
    const S4CR: u32 = 0x10 + 4 * 0x18;
    const ADC1_DR: u32 = 0x4001_204C;

    fn dma2() -> DmaF4 {
        DmaF4::new(2, [56, 57, 58, 59, 60, 68, 69, 70], 0x4002_6400)
    }
    fn w(d: &mut DmaF4, off: u32, v: u32) -> Result<(), Unmodelled> {
        d.write(0, off, v, 0xFFFF_FFFF, &mut Signals::default())
    }
    fn r(d: &mut DmaF4, off: u32) -> u32 {
        d.read(0, off, &mut Signals::default()).unwrap()
    }
    fn request(d: &mut DmaF4) -> Vec<Copy> {
        let mut s = Signals::default();
        d.on_event(0, Event::DmaRequest(Request::Adc1), &mut s);
        s.copies
    }
    /// P2M, 16-bit, MINC, TCIE, HTIE; CHSEL 0.
    const CR_ADC: u32 = (1 << CR_PSIZE_SHIFT) | (1 << CR_MSIZE_SHIFT) | CR_MINC | CR_TCIE | CR_HTIE;

    fn setup(d: &mut DmaF4, items: u32, cr: u32) {
        w(d, S0PAR, ADC1_DR).unwrap();
        w(d, S0M0AR, 0x2000_0000).unwrap();
        w(d, S0NDTR, items).unwrap();
        w(d, S0CR, cr).unwrap();
    }

    #[test]
    fn tim8_ch1_request_feeds_a_table_into_the_dac_on_stream_2_channel_7() {
        // docs/rf-level.md: M2P, 16-bit both sides, MINC, normal mode, NDTR = N, PAR = DHR12R1.
        let mut d = dma2();
        let (s2par, s2m0ar, s2ndtr, s2cr) = (
            0x10 + 2 * 0x18 + 8,
            0x10 + 2 * 0x18 + 12,
            0x10 + 2 * 0x18 + 4,
            0x10 + 2 * 0x18,
        );
        w(&mut d, s2par, 0x4000_7408).unwrap();
        w(&mut d, s2m0ar, 0x2000_0100).unwrap();
        w(&mut d, s2ndtr, 3).unwrap();
        let cr = (7 << CR_CHSEL_SHIFT)
            | (1 << CR_DIR_SHIFT)
            | (1 << CR_PSIZE_SHIFT)
            | (1 << CR_MSIZE_SHIFT)
            | CR_MINC;
        w(&mut d, s2cr, cr | CR_EN).unwrap();
        let mut moved = Vec::new();
        for _ in 0..4 {
            let mut s = Signals::default();
            d.on_event(
                0,
                Event::DmaRequest(Request::TimCc {
                    timer: 8,
                    channel: 1,
                }),
                &mut s,
            );
            moved.extend(s.copies);
        }
        let want: Vec<Copy> = (0..3)
            .map(|k| Copy {
                from: 0x2000_0100 + 2 * k,
                to: 0x4000_7408,
                size: 2,
            })
            .collect();
        assert_eq!(
            moved, want,
            "three items, then the stream is done (EN cleared)"
        );
        // Another timer's channel is not on this stream.
        let mut d = dma2();
        w(&mut d, s2ndtr, 3).unwrap();
        w(&mut d, s2cr, cr | CR_EN).unwrap();
        let mut s = Signals::default();
        d.on_event(
            0,
            Event::DmaRequest(Request::TimCc {
                timer: 1,
                channel: 1,
            }),
            &mut s,
        );
        assert!(s.copies.is_empty());
    }

    #[test]
    fn reset_values() {
        let mut d = dma2();
        assert_eq!(r(&mut d, S0FCR), 0x21);
        assert_eq!(r(&mut d, S0CR), 0);
        assert_eq!(r(&mut d, 0x00), 0);
    }

    #[test]
    fn normal_mode_moves_items_then_clears_en() {
        let mut d = dma2();
        setup(&mut d, 4, CR_ADC | CR_EN);
        let mut got = Vec::new();
        for _ in 0..4 {
            got.extend(request(&mut d));
        }
        assert_eq!(
            got,
            (0..4)
                .map(|i| Copy {
                    from: ADC1_DR,
                    to: 0x2000_0000 + 2 * i,
                    size: 2
                })
                .collect::<Vec<_>>()
        );
        // TCIF (bit 5) and HTIF (bit 4) of stream 0; EN cleared by hardware; NDTR = 0.
        assert_eq!(r(&mut d, 0x00), TCIF | HTIF);
        assert_eq!(r(&mut d, S0CR) & CR_EN, 0);
        assert_eq!(r(&mut d, S0NDTR), 0);
        assert!(
            request(&mut d).is_empty(),
            "after the last item nothing moves"
        );
    }

    #[test]
    fn half_transfer_flag_at_half() {
        let mut d = dma2();
        setup(&mut d, 4, CR_ADC | CR_EN);
        request(&mut d);
        assert_eq!(r(&mut d, 0x00) & HTIF, 0);
        request(&mut d);
        assert_eq!(r(&mut d, 0x00) & HTIF, HTIF);
        let mut lines = Vec::new();
        d.irq_lines(&mut |n| lines.push(n));
        assert_eq!(lines, vec![56]);
        w(&mut d, 0x08, HTIF).unwrap(); // LIFCR.CHTIF0
        assert_eq!(r(&mut d, 0x00), 0);
    }

    #[test]
    fn request_to_disabled_or_unselected_stream_is_dropped() {
        let mut d = dma2();
        setup(&mut d, 4, CR_ADC); // EN = 0
        assert!(request(&mut d).is_empty());
        assert_eq!(r(&mut d, S0NDTR), 4);
        // DMA1 has no ADC1 mapping at all.
        let mut d1 = DmaF4::new(1, [11, 12, 13, 14, 15, 16, 17, 47], 0x4002_6000);
        assert!(request(&mut d1).is_empty());
    }

    #[test]
    fn stream4_channel0_is_adc1_too() {
        let mut d = dma2();
        w(&mut d, S4CR + 8, ADC1_DR).unwrap();
        w(&mut d, S4CR + 12, 0x2000_0200).unwrap();
        w(&mut d, S4CR + 4, 2).unwrap();
        w(&mut d, S4CR, CR_ADC | CR_EN).unwrap();
        assert_eq!(
            request(&mut d),
            vec![Copy {
                from: ADC1_DR,
                to: 0x2000_0200,
                size: 2
            }]
        );
    }

    #[test]
    fn enable_needs_cleared_flags_and_modelled_mapping() {
        let mut d = dma2();
        setup(&mut d, 2, CR_ADC | CR_EN);
        request(&mut d);
        request(&mut d); // TCIF + HTIF, EN cleared
        w(&mut d, S0NDTR, 2).unwrap();
        assert!(w(&mut d, S0CR, CR_ADC | CR_EN).is_err(), "flags still set");
        w(&mut d, 0x08, 0b11_1101).unwrap();
        assert!(w(&mut d, S0CR, CR_ADC | CR_EN).is_ok());
        // Stream 1 channel 0 is not a modelled request.
        w(&mut d, 0x10 + 0x18 + 4, 2).unwrap();
        assert!(w(&mut d, 0x10 + 0x18, CR_ADC | CR_EN).is_err());
    }

    #[test]
    fn software_disable_is_immediate_and_sets_tcif() {
        let mut d = dma2();
        setup(&mut d, 8, CR_ADC | CR_CIRC | CR_EN);
        request(&mut d);
        let cr = r(&mut d, S0CR);
        w(&mut d, S0CR, cr & !CR_EN).unwrap();
        assert_eq!(r(&mut d, S0CR) & CR_EN, 0, "reads 0 at once");
        assert_eq!(r(&mut d, 0x00) & TCIF, TCIF);
        assert_eq!(r(&mut d, S0NDTR), 7, "NDTR keeps the items left");
        // Re-enabling without reprogramming NDTR (resume) is not modelled.
        w(&mut d, 0x08, 0b11_1101).unwrap();
        assert!(w(&mut d, S0CR, cr).is_err());
    }

    #[test]
    fn configuration_is_write_protected_while_enabled() {
        let mut d = dma2();
        setup(&mut d, 8, CR_ADC | CR_CIRC | CR_EN);
        assert!(w(&mut d, S0NDTR, 3).is_err());
        assert!(w(&mut d, S0M0AR, 0x2000_1000).is_err());
        assert!(w(&mut d, S0CR, (CR_ADC | CR_EN) & !CR_CIRC).is_err());
        // Interrupt enables may change; rewriting the same address is no change.
        assert!(w(&mut d, S0CR, CR_ADC | CR_CIRC | CR_EN | CR_TEIE).is_ok());
        assert!(w(&mut d, S0M0AR, 0x2000_0000).is_ok());
    }

    #[test]
    fn direct_mode_forces_msize_to_psize() {
        let mut d = dma2();
        // PSIZE = half-word, MSIZE = word, MBURST = INCR4: direct mode forces MSIZE = half-word, no burst.
        setup(
            &mut d,
            2,
            (1 << CR_PSIZE_SHIFT) | (2 << CR_MSIZE_SHIFT) | (1 << 23) | CR_MINC | CR_EN,
        );
        let cr = r(&mut d, S0CR);
        assert_eq!((cr >> CR_MSIZE_SHIFT) & 3, 1);
        assert_eq!(cr & CR_MBURST_MASK, 0);
    }

    #[test]
    fn unmodelled_modes_are_refused_at_enable() {
        let mut d = dma2();
        w(&mut d, S0FCR, FCR_DMDIS).unwrap();
        w(&mut d, S0NDTR, 2).unwrap();
        assert!(w(&mut d, S0CR, CR_ADC | CR_EN).is_err(), "FIFO mode");
        w(&mut d, S0FCR, 0).unwrap();
        assert!(
            w(&mut d, S0CR, CR_ADC | CR_DBM | CR_EN).is_err(),
            "double buffer"
        );
        assert!(
            w(&mut d, S0CR, CR_ADC | (2 << CR_DIR_SHIFT) | CR_EN).is_err(),
            "memory to memory"
        );
        assert!(w(&mut d, 0x00, 0).is_err(), "LISR is read-only");
        assert!(
            d.read(0, 0x08, &mut Signals::default()).is_err(),
            "LIFCR is write-only"
        );
    }

    /// USART2_TX (DMA1 stream 6 channel 4) is a level request: a stream enabled while it is
    /// high moves an item at once; a new high moves the next; while low nothing moves.
    #[test]
    fn a_level_request_is_served_at_enable_and_while_high() {
        let mut d = DmaF4::new(1, [11, 12, 13, 14, 15, 16, 17, 47], 0x4002_6000);
        let mut s = Signals::default();
        let level = |high| Event::DmaLevel {
            request: Request::Usart2Tx,
            high,
        };
        d.on_event(0, level(true), &mut s);
        assert!(s.copies.is_empty(), "no stream enabled yet");
        // Stream 6: PAR = USART2_DR, M0AR = a buffer, 3 bytes, memory to peripheral, MINC.
        let s6 = 0x10 + 6 * 0x18;
        w(&mut d, s6 + 0x8, 0x4000_4404).unwrap();
        w(&mut d, s6 + 0xC, 0x2000_0100).unwrap();
        w(&mut d, s6 + 0x4, 3).unwrap();
        let cr = (4 << CR_CHSEL_SHIFT) | (1 << CR_DIR_SHIFT) | CR_MINC | CR_TCIE;
        d.write(0, s6, cr | CR_EN, 0xFFFF_FFFF, &mut s).unwrap();
        assert_eq!(
            s.copies,
            vec![Copy {
                from: 0x2000_0100,
                to: 0x4000_4404,
                size: 1
            }]
        );
        s.copies.clear();
        d.on_event(1, level(false), &mut s);
        assert!(s.copies.is_empty());
        d.on_event(2, level(true), &mut s);
        assert_eq!(
            s.copies,
            vec![Copy {
                from: 0x2000_0101,
                to: 0x4000_4404,
                size: 1
            }]
        );
    }
}
