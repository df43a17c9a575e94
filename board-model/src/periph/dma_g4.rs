//! STM32G474 DMA1/DMA2 controllers (RM0440 §12: eight channels each, single-item transfers per
//! request, normal or circular mode, HT/TC flags and interrupts) and the DMAMUX1 request router
//! (RM0440 §13) that feeds them. DMAMUX synchronisation and request generators, memory-to-memory
//! and data-width conversion are not modelled: using them is `Unmodelled`.
//!
//! Behaviours this model commits to:
//! - DMAMUX channel n (0..=15) forwards the request whose DMAREQ_ID it holds to DMA1 channel n+1
//!   (n ≤ 7) or DMA2 channel n−7 (§13.3.2); only requests 5 (ADC1), 6 (DAC1_CH1), 49 (TIM8_CH1), 34 (LPUART1_RX) and 35
//!   (LPUART1_TX) of RM0440 table 91 ("DMAMUX: assignment of multiplexer inputs to resources")
//!   are modelled. The LPUART1 numbers are taken from stm32-metapac 21's STM32G474RE data
//!   (`request: Some(34)` / `Some(35)`), which embassy-stm32 programs; they agree with the
//!   sequence USART1..UART5 = 24..33 then LPUART1 in third-party G4 tables, not re-read in the
//!   RM0440 PDF here. EGE (event generation) is accepted: its event output feeds only DMAMUX
//!   synchronisation inputs and request generators, which are not modelled, so it has no
//!   observable effect here.
//! - A level-sensitive request (`Event::DmaLevel`: LPUART1_TX, high while TXE/TXFNF with DMAT)
//!   reaches the channels that select it as `Event::DmaChannelLevel`, also when a DMAMUX channel
//!   starts selecting a request that is already high (or stops selecting one). The DMA channel
//!   moves one item for each high it is told of, and one when it is enabled while its request is
//!   high: the peripheral says high again after every item that leaves it high, so the channel
//!   keeps moving items for as long as the level stays up, as DMA1/DMA2 serve a request line
//!   that stays asserted (§12.4.3 "DMA transfers"; the F446 model does the same).
//! - A DMA channel moves one item per routed request while EN = 1 and CNDTR > 0: a `Copy`, then
//!   CNDTR − 1. HTIF is set the first time at least half the items have moved, TCIF at CNDTR = 0;
//!   circular mode reloads CNDTR and the addresses (§12.4.6); in normal mode the channel stays
//!   enabled but serves nothing more (§12.4.6: it must be disabled to be reprogrammed). GIF is the
//!   OR of the channel's TCIF/HTIF/TEIF.
//! - Clearing EN takes effect at once (no flag is set). Re-enabling a channel without
//!   reprogramming CNDTR is a "suspend and resume", which §12.4.6 says the hardware does not
//!   support: `Unmodelled`. EN cannot be set while TEIF is set (§12.6.3); TEIF never rises here
//!   (the board reports no bus errors), so that check is only a guard.
//! - CCR configuration and interrupt-enable bits, CNDTR, CPAR and CMAR "must not be written when
//!   the channel is enabled" (§12.6.3-12.6.6): a write that changes them while EN = 1 is
//!   `Unmodelled`, except a CCR write that also clears EN: the CCR bits are "read-only when the
//!   channel is enabled" (§12.6.3), so that write only disables the channel and the other bits
//!   keep their values.

use super::{merge, Copy, Event, Peripheral, Request, Signals, Time, Unmodelled};
use std::any::Any;

const ISR: u32 = 0x00;
const IFCR: u32 = 0x04;
/// Channel x (1..=8) registers at 0x08 + 20 × (x − 1) (§12.6.7 register map).
const CHANNEL_BASE: u32 = 0x08;
const CHANNEL_STRIDE: u32 = 20;
const CHANNELS: usize = 8;

// Per-channel flag bits in ISR/IFCR, at 4 × (x − 1) (§12.6.1/2).
const GIF: u32 = 1 << 0;
const TCIF: u32 = 1 << 1;
const HTIF: u32 = 1 << 2;
const TEIF: u32 = 1 << 3;

// DMA_CCRx (§12.6.3).
const CCR_EN: u32 = 1 << 0;
const CCR_TCIE: u32 = 1 << 1;
const CCR_HTIE: u32 = 1 << 2;
const CCR_TEIE: u32 = 1 << 3;
const CCR_DIR: u32 = 1 << 4;
const CCR_CIRC: u32 = 1 << 5;
const CCR_PINC: u32 = 1 << 6;
const CCR_MINC: u32 = 1 << 7;
const CCR_PSIZE_SHIFT: u32 = 8;
const CCR_MSIZE_SHIFT: u32 = 10;
const CCR_MEM2MEM: u32 = 1 << 14;
const CCR_DEFINED: u32 = 0x7FFF;

/// DMAREQ_IDs (RM0440 §13.3.2 table 91; see the module doc for where 34/35 come from).
const DMAREQ_ADC1: u32 = 5;
const DMAREQ_LPUART1_RX: u32 = 34;
const DMAREQ_LPUART1_TX: u32 = 35;
/// DAC1_CH1 and TIM8_CH1: stm32-metapac 21's STM32G474RE data (`request: Some(6)`, `Some(49)`),
/// the numbers embassy-stm32 programs; not re-read in RM0440 table 91 here.
const DMAREQ_DAC1_CH1: u32 = 6;
const DMAREQ_TIM8_CH1: u32 = 49;
const MUX_CHANNELS: usize = 16;

fn size_bytes(code: u32) -> Option<u8> {
    match code {
        0 => Some(1),
        1 => Some(2),
        2 => Some(4),
        _ => None,
    }
}

#[derive(Clone, Copy, Debug)]
struct Transfer {
    cpar: u32,
    cmar: u32,
    items: u32,
    item_bytes: u8,
}

#[derive(Clone, Copy, Debug, Default)]
struct Channel {
    ccr: u32,
    cndtr: u32,
    cpar: u32,
    cmar: u32,
    /// TCIF/HTIF/TEIF in their ISR positions for channel 1 (bits 3:1).
    flags: u32,
    /// The last CNDTR software wrote (to tell a fresh start from a resume).
    cndtr_written: u32,
    transfer: Option<Transfer>,
    /// The level of the level-sensitive request routed here (`Event::DmaChannelLevel`).
    level: bool,
}

/// One DMA controller (DMA1 or DMA2) of the G474.
pub struct DmaG4 {
    number: u8,
    irqs: [u16; 8],
    channels: [Channel; CHANNELS],
}

impl DmaG4 {
    /// `number`: 1 or 2; `irqs`: NVIC lines of channels 1..=8.
    pub fn new(number: u8, irqs: [u16; 8]) -> Self {
        DmaG4 {
            number,
            irqs,
            channels: [Channel::default(); CHANNELS],
        }
    }

    fn isr(&self) -> u32 {
        self.channels.iter().enumerate().fold(0, |acc, (i, c)| {
            let gif = if c.flags != 0 { GIF } else { 0 };
            acc | ((c.flags | gif) << (4 * i))
        })
    }

    fn write_ccr(
        &mut self,
        i: usize,
        offset: u32,
        value: u32,
        mask: u32,
        out: &mut Signals,
    ) -> Result<(), Unmodelled> {
        let n = self.number;
        let refuse = |why: String| {
            Err(Unmodelled::write(
                offset,
                value,
                format!("DMA{n} channel {}: {why}", i + 1),
            ))
        };
        let c = self.channels[i];
        let mut new = merge(c.ccr, value, mask);
        if new & !CCR_DEFINED != 0 {
            return refuse("CCR reserved bits written non-zero".into());
        }
        let was_on = c.ccr & CCR_EN != 0;
        if was_on && (new ^ c.ccr) & !CCR_EN != 0 {
            if new & CCR_EN != 0 {
                return refuse(
                    "CCR bits changed while EN = 1 (RM0440 §12.6.3: must not be written when enabled)"
                        .into(),
                );
            }
            // A write that clears EN: the other bits are read-only while EN = 1 (§12.6.3), so
            // they keep their values and only EN falls (embassy's `request_stop` writes
            // TCIE | TEIE alone).
            new = c.ccr & !CCR_EN;
        }
        match (was_on, new & CCR_EN != 0) {
            (false, true) => {
                if c.flags & TEIF != 0 {
                    return refuse("EN set while TEIF is set (§12.6.3)".into());
                }
                if new & CCR_MEM2MEM != 0 {
                    return refuse("memory-to-memory mode is not modelled".into());
                }
                let psize = (new >> CCR_PSIZE_SHIFT) & 0x3;
                let msize = (new >> CCR_MSIZE_SHIFT) & 0x3;
                let Some(item_bytes) = size_bytes(psize) else {
                    return refuse("PSIZE = 11 is reserved".into());
                };
                if psize != msize {
                    return refuse("PSIZE ≠ MSIZE (data width conversion) is not modelled".into());
                }
                if c.cndtr != c.cndtr_written {
                    return refuse(format!(
                        "re-enabled with CNDTR = {} left from a stopped transfer (written {}): suspend/resume is \
                         not supported by the hardware (§12.4.6)",
                        c.cndtr, c.cndtr_written
                    ));
                }
                self.channels[i].transfer = Some(Transfer {
                    cpar: c.cpar,
                    cmar: c.cmar,
                    items: c.cndtr,
                    item_bytes,
                });
            }
            (true, false) => self.channels[i].transfer = None,
            _ => {}
        }
        self.channels[i].ccr = new;
        out.replan = true;
        // A level-sensitive request already high is served as soon as its channel is enabled.
        if !was_on && new & CCR_EN != 0 && self.channels[i].level {
            self.serve(i, out);
        }
        Ok(())
    }

    fn serve(&mut self, i: usize, out: &mut Signals) {
        let c = &mut self.channels[i];
        let Some(t) = c.transfer else { return };
        if c.ccr & CCR_EN == 0 || c.cndtr == 0 {
            return;
        }
        let index = t.items - c.cndtr;
        let step = t.item_bytes as u32;
        let periph = if c.ccr & CCR_PINC != 0 {
            t.cpar.wrapping_add(index * step)
        } else {
            t.cpar
        };
        let memory = if c.ccr & CCR_MINC != 0 {
            t.cmar.wrapping_add(index * step)
        } else {
            t.cmar
        };
        // DIR = 0: read from peripheral; DIR = 1: read from memory (§12.6.3).
        let (from, to) = if c.ccr & CCR_DIR == 0 {
            (periph, memory)
        } else {
            (memory, periph)
        };
        out.copies.push(Copy {
            from,
            to,
            size: t.item_bytes,
        });
        c.cndtr -= 1;
        let moved = t.items - c.cndtr;
        if 2 * moved >= t.items && 2 * (moved - 1) < t.items {
            c.flags |= HTIF;
        }
        if c.cndtr == 0 {
            c.flags |= TCIF;
            if c.ccr & CCR_CIRC != 0 {
                c.cndtr = t.items;
            }
        }
        out.replan = true;
    }
}

impl Peripheral for DmaG4 {
    fn name(&self) -> &'static str {
        match self.number {
            1 => "DMA1",
            _ => "DMA2",
        }
    }

    fn read(&mut self, _now: Time, offset: u32, _out: &mut Signals) -> Result<u32, Unmodelled> {
        match offset {
            ISR => Ok(self.isr()),
            IFCR => Err(Unmodelled::read(
                offset,
                format!("DMA{}_IFCR is write-only", self.number),
            )),
            CHANNEL_BASE..=0xA3 => {
                let i = ((offset - CHANNEL_BASE) / CHANNEL_STRIDE) as usize;
                let c = &self.channels[i];
                match (offset - CHANNEL_BASE) % CHANNEL_STRIDE {
                    0x0 => Ok(c.ccr),
                    0x4 => Ok(c.cndtr),
                    0x8 => Ok(c.cpar),
                    0xC => Ok(c.cmar),
                    _ => Err(Unmodelled::read(offset, "reserved DMA channel word")),
                }
            }
            _ => Err(Unmodelled::read(offset, "no DMA register at this offset")),
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
            ISR => {
                return Err(Unmodelled::write(
                    offset,
                    value,
                    format!("DMA{}_ISR is read-only", self.number),
                ))
            }
            IFCR => {
                let bits = value & mask;
                for (i, c) in self.channels.iter_mut().enumerate() {
                    let b = (bits >> (4 * i)) & 0xF;
                    // CGIF clears all of the channel's flags; CTCIF/CHTIF/CTEIF their own (§12.6.2).
                    c.flags &= if b & GIF != 0 { 0 } else { !b };
                }
                out.replan = true;
            }
            CHANNEL_BASE..=0xA3 => {
                let i = ((offset - CHANNEL_BASE) / CHANNEL_STRIDE) as usize;
                let reg = (offset - CHANNEL_BASE) % CHANNEL_STRIDE;
                if reg == 0 {
                    return self.write_ccr(i, offset, value, mask, out);
                }
                let n = self.number;
                let c = &mut self.channels[i];
                let (field, writable, name) = match reg {
                    0x4 => (&mut c.cndtr, 0xFFFF, "CNDTR"),
                    0x8 => (&mut c.cpar, 0xFFFF_FFFF, "CPAR"),
                    0xC => (&mut c.cmar, 0xFFFF_FFFF, "CMAR"),
                    _ => {
                        return Err(Unmodelled::write(
                            offset,
                            value,
                            "reserved DMA channel word",
                        ))
                    }
                };
                let new = merge(*field, value, mask & writable);
                if c.ccr & CCR_EN != 0 && new != *field {
                    return Err(Unmodelled::write(
                        offset,
                        value,
                        format!(
                            "DMA{n} {name}{} written while the channel is enabled (§12.6)",
                            i + 1
                        ),
                    ));
                }
                *field = new;
                if reg == 0x4 {
                    c.cndtr_written = new;
                }
            }
            _ => {
                return Err(Unmodelled::write(
                    offset,
                    value,
                    "no DMA register at this offset",
                ))
            }
        }
        Ok(())
    }

    fn on_event(&mut self, _now: Time, event: Event, out: &mut Signals) {
        match event {
            Event::DmaChannelRequest {
                controller,
                channel,
            } if controller == self.number && (1..=CHANNELS as u8).contains(&channel) => {
                self.serve(channel as usize - 1, out);
            }
            Event::DmaChannelLevel {
                controller,
                channel,
                high,
            } if controller == self.number && (1..=CHANNELS as u8).contains(&channel) => {
                let i = channel as usize - 1;
                self.channels[i].level = high;
                if high {
                    self.serve(i, out);
                }
            }
            _ => {}
        }
    }

    fn irq_lines(&self, raise: &mut dyn FnMut(u16)) {
        for (i, c) in self.channels.iter().enumerate() {
            let up = (c.flags & TCIF != 0 && c.ccr & CCR_TCIE != 0)
                || (c.flags & HTIF != 0 && c.ccr & CCR_HTIE != 0)
                || (c.flags & TEIF != 0 && c.ccr & CCR_TEIE != 0);
            if up {
                raise(self.irqs[i]);
            }
        }
    }

    fn reset(&mut self, _now: Time) {
        // The request lines' levels come from the DMAMUX and survive the controller's reset.
        let levels = self.channels.map(|c| c.level);
        self.channels = [Channel::default(); CHANNELS];
        for (c, level) in self.channels.iter_mut().zip(levels) {
            c.level = level;
        }
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}

// DMAMUX1 (RM0440 §13.6).
const MUX_CSR: u32 = 0x80;
const MUX_CFR: u32 = 0x84;
const MUX_RGCR_BASE: u32 = 0x100;
const MUX_RGSR: u32 = 0x140;
const MUX_RGCFR: u32 = 0x144;
const MUX_GENERATORS: usize = 4;

const CXCR_DMAREQ_ID_MASK: u32 = 0x7F;
const CXCR_SOIE: u32 = 1 << 8;
const CXCR_EGE: u32 = 1 << 9;
const CXCR_SE: u32 = 1 << 16;
const CXCR_NBREQ_MASK: u32 = 0x1F << 19;
/// DMAREQ_ID[6:0], SOIE, EGE, SE, SPOL[18:17], NBREQ[23:19], SYNC_ID[28:24].
const CXCR_DEFINED: u32 = CXCR_DMAREQ_ID_MASK | CXCR_SOIE | CXCR_EGE | 0x1FFF_0000;

const RGCR_OIE: u32 = 1 << 8;
const RGCR_GE: u32 = 1 << 16;
/// SIG_ID[4:0], OIE, GE, GPOL[18:17], GNBREQ[23:19].
const RGCR_DEFINED: u32 = 0x1F | RGCR_OIE | 0x00FF_0000;

/// DMAMUX1 of the G474 at 0x4002_0800: routes peripheral requests to DMA1/DMA2 channels.
pub struct DmaMux {
    cxcr: [u32; MUX_CHANNELS],
    rgcr: [u32; MUX_GENERATORS],
    /// DMAREQ_IDs of the level-sensitive requests that are high now.
    high: Vec<u32>,
}

impl Default for DmaMux {
    fn default() -> Self {
        Self::new()
    }
}

impl DmaMux {
    pub fn new() -> Self {
        DmaMux {
            cxcr: [0; MUX_CHANNELS],
            rgcr: [0; MUX_GENERATORS],
            high: Vec::new(),
        }
    }

    /// The DMAMUX request ID of `request` on the G474; None for the F446's USART2 (the G474's
    /// link is LPUART1).
    fn request_id(request: Request) -> Option<u32> {
        match request {
            Request::Adc1 => Some(DMAREQ_ADC1),
            Request::Lpuart1Rx => Some(DMAREQ_LPUART1_RX),
            Request::Lpuart1Tx => Some(DMAREQ_LPUART1_TX),
            Request::Dac1Ch1 => Some(DMAREQ_DAC1_CH1),
            Request::TimCc {
                timer: 8,
                channel: 1,
            } => Some(DMAREQ_TIM8_CH1),
            Request::Usart2Rx | Request::Usart2Tx | Request::TimCc { .. } => None,
        }
    }

    /// DMAMUX channel n feeds DMA1 channels 1..=8 (n 0..=7) or DMA2 channels 1..=8 (n 8..=15)
    /// (§13.3.2).
    fn target(n: usize) -> (u8, u8) {
        (1 + (n / 8) as u8, (n % 8) as u8 + 1)
    }
}

impl Peripheral for DmaMux {
    fn name(&self) -> &'static str {
        "DMAMUX1"
    }

    fn read(&mut self, _now: Time, offset: u32, _out: &mut Signals) -> Result<u32, Unmodelled> {
        match offset {
            0x00..=0x3C => Ok(self.cxcr[(offset / 4) as usize]),
            // No synchronisation input and no request generator can be enabled, so no overrun
            // flag can ever be set: 0 is the true value.
            MUX_CSR | MUX_RGSR => Ok(0),
            MUX_RGCR_BASE..=0x10C => Ok(self.rgcr[((offset - MUX_RGCR_BASE) / 4) as usize]),
            MUX_CFR | MUX_RGCFR => Err(Unmodelled::read(
                offset,
                "DMAMUX clear-flag registers are write-only",
            )),
            _ => Err(Unmodelled::read(
                offset,
                "no DMAMUX register at this offset",
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
        match offset {
            0x00..=0x3C => {
                let n = (offset / 4) as usize;
                let old = self.cxcr[n];
                let new = merge(old, value, mask);
                let refuse = |why: String| {
                    Err(Unmodelled::write(
                        offset,
                        value,
                        format!("DMAMUX_C{n}CR: {why}"),
                    ))
                };
                if new & !CXCR_DEFINED != 0 {
                    return refuse("reserved bits written non-zero".into());
                }
                let id = new & CXCR_DMAREQ_ID_MASK;
                if ![
                    0,
                    DMAREQ_ADC1,
                    DMAREQ_DAC1_CH1,
                    DMAREQ_LPUART1_RX,
                    DMAREQ_LPUART1_TX,
                    DMAREQ_TIM8_CH1,
                ]
                .contains(&id)
                {
                    return refuse(format!(
                        "DMAREQ_ID {id} is not modelled (only 5 = ADC1, 6 = DAC1_CH1, 34/35 = LPUART1_RX/TX, 49 = TIM8_CH1)"
                    ));
                }
                if new & (CXCR_SE | CXCR_SOIE) != 0 {
                    return refuse("synchronisation (SE/SOIE) is not modelled".into());
                }
                // NBREQ "can only be written when both SE and EGE bits are reset" (§13.6.1).
                if (new ^ old) & CXCR_NBREQ_MASK != 0 && old & (CXCR_SE | CXCR_EGE) != 0 {
                    return refuse("NBREQ changed while SE or EGE is set (§13.6.1)".into());
                }
                self.cxcr[n] = new;
                // The channel now forwards another request: its DMA channel sees that one's level.
                let old_id = old & CXCR_DMAREQ_ID_MASK;
                let (was, is) = (self.high.contains(&old_id), self.high.contains(&id));
                if old_id != id && (was || is) {
                    let (controller, channel) = Self::target(n);
                    out.events.push((
                        now,
                        Event::DmaChannelLevel {
                            controller,
                            channel,
                            high: is,
                        },
                    ));
                }
            }
            MUX_CSR | MUX_RGSR => {
                return Err(Unmodelled::write(
                    offset,
                    value,
                    "DMAMUX status registers are read-only",
                ))
            }
            // Clearing flags that can never be set.
            MUX_CFR | MUX_RGCFR => {}
            MUX_RGCR_BASE..=0x10C => {
                let g = ((offset - MUX_RGCR_BASE) / 4) as usize;
                let new = merge(self.rgcr[g], value, mask);
                if new & !RGCR_DEFINED != 0 || new & (RGCR_GE | RGCR_OIE) != 0 {
                    return Err(Unmodelled::write(
                        offset,
                        value,
                        format!("DMAMUX request generator {g} is not modelled"),
                    ));
                }
                self.rgcr[g] = new;
            }
            _ => {
                return Err(Unmodelled::write(
                    offset,
                    value,
                    "no DMAMUX register at this offset",
                ))
            }
        }
        Ok(())
    }

    fn on_event(&mut self, now: Time, event: Event, out: &mut Signals) {
        let (request, level) = match event {
            Event::DmaRequest(r) => (r, None),
            Event::DmaLevel { request, high } => (request, Some(high)),
            _ => return,
        };
        let Some(id) = Self::request_id(request) else {
            return;
        };
        if let Some(high) = level {
            self.high.retain(|&h| h != id);
            if high {
                self.high.push(id);
            }
        }
        for (n, &cr) in self.cxcr.iter().enumerate() {
            if cr & CXCR_DMAREQ_ID_MASK == id {
                let (controller, channel) = Self::target(n);
                let e = match level {
                    None => Event::DmaChannelRequest {
                        controller,
                        channel,
                    },
                    Some(high) => Event::DmaChannelLevel {
                        controller,
                        channel,
                        high,
                    },
                };
                out.events.push((now, e));
            }
        }
    }

    fn reset(&mut self, _now: Time) {
        // The requests' levels are the peripherals' state, not the DMAMUX's: kept.
        let high = std::mem::take(&mut self.high);
        *self = DmaMux::new();
        self.high = high;
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

    const CCR1: u32 = 0x08;
    const CNDTR1: u32 = 0x0C;
    const CPAR1: u32 = 0x10;
    const CMAR1: u32 = 0x14;
    const ADC1_DR: u32 = 0x5000_0040;
    /// PSIZE/MSIZE 16, MINC, TCIE, HTIE.
    const CCR_ADC: u32 =
        (1 << CCR_PSIZE_SHIFT) | (1 << CCR_MSIZE_SHIFT) | CCR_MINC | CCR_TCIE | CCR_HTIE;

    fn w(p: &mut dyn Peripheral, off: u32, v: u32) -> Result<(), Unmodelled> {
        p.write(0, off, v, 0xFFFF_FFFF, &mut Signals::default())
    }
    fn r(p: &mut dyn Peripheral, off: u32) -> u32 {
        p.read(0, off, &mut Signals::default()).unwrap()
    }
    fn dma1() -> DmaG4 {
        DmaG4::new(1, [11, 12, 13, 14, 15, 16, 17, 96])
    }
    fn request(d: &mut DmaG4, channel: u8) -> Vec<Copy> {
        let mut s = Signals::default();
        d.on_event(
            0,
            Event::DmaChannelRequest {
                controller: 1,
                channel,
            },
            &mut s,
        );
        s.copies
    }
    fn setup(d: &mut DmaG4, items: u32, ccr: u32) {
        w(d, CPAR1, ADC1_DR).unwrap();
        w(d, CMAR1, 0x2000_0000).unwrap();
        w(d, CNDTR1, items).unwrap();
        w(d, CCR1, ccr).unwrap();
    }

    #[test]
    fn tim8_ch1_and_dac1_requests_are_routed_by_their_ids() {
        // The firmware's G474 envelope DMA: DMAMUX channel 3 (→ DMA1 channel 4) on request 49.
        let mut mux = DmaMux::new();
        let mut s = Signals::default();
        mux.write(0, 3 * 4, DMAREQ_TIM8_CH1, 0xFFFF_FFFF, &mut s)
            .unwrap();
        mux.write(0, 4 * 4, DMAREQ_DAC1_CH1, 0xFFFF_FFFF, &mut s)
            .unwrap();
        let mut s = Signals::default();
        mux.on_event(
            9,
            Event::DmaRequest(Request::TimCc {
                timer: 8,
                channel: 1,
            }),
            &mut s,
        );
        mux.on_event(10, Event::DmaRequest(Request::Dac1Ch1), &mut s);
        // TIM1's channel has no DMAMUX id modelled: dropped.
        mux.on_event(
            11,
            Event::DmaRequest(Request::TimCc {
                timer: 1,
                channel: 1,
            }),
            &mut s,
        );
        assert_eq!(
            s.events,
            vec![
                (
                    9,
                    Event::DmaChannelRequest {
                        controller: 1,
                        channel: 4
                    }
                ),
                (
                    10,
                    Event::DmaChannelRequest {
                        controller: 1,
                        channel: 5
                    }
                ),
            ]
        );
    }

    #[test]
    fn dmamux_routes_adc1_to_the_channels_that_select_it() {
        let mut mux = DmaMux::new();
        w(&mut mux, 0x00, 5).unwrap(); // channel 0 → DMA1 ch1
        w(&mut mux, 0x24, 5).unwrap(); // channel 9 → DMA2 ch2
        w(&mut mux, 0x04, 0).unwrap(); // channel 1: no request
        let mut s = Signals::default();
        mux.on_event(77, Event::DmaRequest(Request::Adc1), &mut s);
        assert_eq!(
            s.events,
            vec![
                (
                    77,
                    Event::DmaChannelRequest {
                        controller: 1,
                        channel: 1
                    }
                ),
                (
                    77,
                    Event::DmaChannelRequest {
                        controller: 2,
                        channel: 2
                    }
                ),
            ]
        );
        // Other events are not routed.
        let mut s = Signals::default();
        mux.on_event(0, Event::Trgo { timer: 3 }, &mut s);
        assert!(s.events.is_empty());
    }

    #[test]
    fn dmamux_embassy_sequence_and_unmodelled_ids() {
        let mut mux = DmaMux::new();
        // configure_dmamux: write NBREQ = 0, DMAREQ_ID = 5; then modify EGE = 1.
        w(&mut mux, 0x00, 5).unwrap();
        let v = r(&mut mux, 0x00);
        w(&mut mux, 0x00, v | CXCR_EGE).unwrap();
        assert_eq!(r(&mut mux, 0x00), 5 | CXCR_EGE);
        // Reconfiguring the same way again (EGE still set, NBREQ unchanged) is fine.
        w(&mut mux, 0x00, 5).unwrap();
        // NBREQ change with EGE set is refused; unmodelled request IDs and sync are refused.
        w(&mut mux, 0x00, 5 | CXCR_EGE).unwrap();
        assert!(w(&mut mux, 0x00, 5 | CXCR_EGE | (3 << 19)).is_err());
        assert!(w(&mut mux, 0x04, 7).is_err());
        assert!(w(&mut mux, 0x04, CXCR_SE).is_err());
        assert!(w(&mut mux, 0x100, RGCR_GE).is_err());
        assert_eq!(r(&mut mux, 0x80), 0);
    }

    #[test]
    fn circular_channel_sets_ht_tc_and_reloads() {
        let mut d = dma1();
        setup(&mut d, 4, CCR_ADC | CCR_CIRC | CCR_EN);
        assert_eq!(
            request(&mut d, 1),
            vec![Copy {
                from: ADC1_DR,
                to: 0x2000_0000,
                size: 2
            }]
        );
        assert_eq!(r(&mut d, ISR), 0);
        request(&mut d, 1);
        assert_eq!(r(&mut d, ISR), GIF | HTIF);
        let mut lines = Vec::new();
        d.irq_lines(&mut |n| lines.push(n));
        assert_eq!(lines, vec![11]);
        request(&mut d, 1);
        assert_eq!(
            request(&mut d, 1),
            vec![Copy {
                from: ADC1_DR,
                to: 0x2000_0006,
                size: 2
            }]
        );
        assert_eq!(r(&mut d, ISR), GIF | HTIF | TCIF);
        assert_eq!(r(&mut d, CNDTR1), 4);
        assert_eq!(
            request(&mut d, 1),
            vec![Copy {
                from: ADC1_DR,
                to: 0x2000_0000,
                size: 2
            }]
        );
        // CHTIF alone, then CGIF.
        w(&mut d, IFCR, HTIF).unwrap();
        assert_eq!(r(&mut d, ISR), GIF | TCIF);
        w(&mut d, IFCR, GIF).unwrap();
        assert_eq!(r(&mut d, ISR), 0);
    }

    #[test]
    fn normal_mode_stays_enabled_but_stops_after_the_last_item() {
        let mut d = dma1();
        setup(&mut d, 2, CCR_ADC | CCR_EN);
        request(&mut d, 1);
        request(&mut d, 1);
        assert_eq!(r(&mut d, CCR1) & CCR_EN, CCR_EN);
        assert_eq!(r(&mut d, CNDTR1), 0);
        assert!(request(&mut d, 1).is_empty());
        // Disable, reprogram, enable again: abort and restart is supported.
        w(&mut d, CCR1, CCR_ADC).unwrap();
        w(&mut d, CNDTR1, 2).unwrap();
        w(&mut d, CCR1, CCR_ADC | CCR_EN).unwrap();
        assert_eq!(request(&mut d, 1).len(), 1);
    }

    #[test]
    fn disabled_channel_drops_requests_and_resume_is_refused() {
        let mut d = dma1();
        setup(&mut d, 4, CCR_ADC);
        assert!(request(&mut d, 1).is_empty());
        w(&mut d, CCR1, CCR_ADC | CCR_EN).unwrap();
        request(&mut d, 1);
        w(&mut d, CCR1, CCR_ADC).unwrap();
        assert_eq!(r(&mut d, CCR1) & CCR_EN, 0, "disable reads back at once");
        assert_eq!(r(&mut d, ISR), 0, "no flag on disable");
        assert!(request(&mut d, 1).is_empty());
        assert!(
            w(&mut d, CCR1, CCR_ADC | CCR_EN).is_err(),
            "suspend/resume not supported"
        );
        // Requests for another channel or controller are not ours.
        let mut s = Signals::default();
        d.on_event(
            0,
            Event::DmaChannelRequest {
                controller: 2,
                channel: 1,
            },
            &mut s,
        );
        assert!(s.copies.is_empty());
    }

    #[test]
    fn registers_locked_while_enabled_and_unmodelled_modes() {
        let mut d = dma1();
        setup(&mut d, 4, CCR_ADC | CCR_CIRC | CCR_EN);
        assert!(w(&mut d, CNDTR1, 8).is_err());
        assert!(w(&mut d, CMAR1, 0x2000_0100).is_err());
        assert!(
            w(&mut d, CCR1, CCR_ADC | CCR_EN).is_err(),
            "CIRC cleared while enabled"
        );
        assert!(
            w(&mut d, CMAR1, 0x2000_0000).is_ok(),
            "same value: no change"
        );
        let mut d = dma1();
        w(&mut d, CNDTR1, 4).unwrap();
        assert!(w(&mut d, CCR1, CCR_ADC | CCR_MEM2MEM | CCR_EN).is_err());
        assert!(w(
            &mut d,
            CCR1,
            (1 << CCR_PSIZE_SHIFT) | (2 << CCR_MSIZE_SHIFT) | CCR_EN
        )
        .is_err());
        assert!(w(&mut d, ISR, 0).is_err());
        assert!(d.read(0, IFCR, &mut Signals::default()).is_err());
        assert!(
            d.read(0, 0x18, &mut Signals::default()).is_err(),
            "reserved word after CMAR1"
        );
    }

    /// LPUART1_TX (DMAREQ_ID 35) is a level: the DMAMUX forwards it to the channel that selects
    /// it, also when that selection comes after the level rose (embassy sets DMAT, then
    /// programs the DMAMUX and the channel); an enabled channel moves an item per high.
    #[test]
    fn a_level_request_through_the_dmamux_is_served_at_enable_and_while_high() {
        const LPUART1_TDR: u32 = 0x4000_8028;
        let mut mux = DmaMux::new();
        let mut d = dma1();
        let mut s = Signals::default();
        let level = |high| Event::DmaLevel {
            request: Request::Lpuart1Tx,
            high,
        };
        mux.on_event(0, level(true), &mut s);
        assert!(s.events.is_empty(), "no DMAMUX channel selects it yet");
        // DMAMUX channel 2 → DMA1 channel 3 (the firmware's TX channel), as embassy writes it.
        mux.write(1, 0x08, 35, 0xFFFF_FFFF, &mut s).unwrap();
        let to_ch3 = |high| Event::DmaChannelLevel {
            controller: 1,
            channel: 3,
            high,
        };
        assert_eq!(
            s.events,
            vec![(1, to_ch3(true))],
            "the level it now selects is high"
        );
        for (t, e) in std::mem::take(&mut s.events) {
            d.on_event(t, e, &mut s);
        }
        assert!(s.copies.is_empty(), "channel not enabled yet");
        // DMA1 channel 3: CPAR = TDR, CMAR = a buffer, 3 bytes, memory to peripheral, MINC.
        let ch3 = 0x08 + 2 * 20;
        w(&mut d, ch3 + 0x8, LPUART1_TDR).unwrap();
        w(&mut d, ch3 + 0xC, 0x2000_0100).unwrap();
        w(&mut d, ch3 + 0x4, 3).unwrap();
        d.write(
            2,
            ch3,
            CCR_DIR | CCR_MINC | CCR_TCIE | CCR_EN,
            0xFFFF_FFFF,
            &mut s,
        )
        .unwrap();
        assert_eq!(
            s.copies,
            vec![Copy {
                from: 0x2000_0100,
                to: LPUART1_TDR,
                size: 1
            }]
        );
        s.copies.clear();
        mux.on_event(3, level(false), &mut s);
        assert_eq!(s.events, vec![(3, to_ch3(false))]);
        for (t, e) in std::mem::take(&mut s.events) {
            d.on_event(t, e, &mut s);
        }
        assert!(s.copies.is_empty(), "low: nothing moves");
        mux.on_event(4, level(true), &mut s);
        for (t, e) in std::mem::take(&mut s.events) {
            d.on_event(t, e, &mut s);
        }
        assert_eq!(
            s.copies,
            vec![Copy {
                from: 0x2000_0101,
                to: LPUART1_TDR,
                size: 1
            }]
        );
        // LPUART1_RX (34) is a plain request; 36 is not modelled.
        let mut s = Signals::default();
        mux.write(0, 0x04, 34, 0xFFFF_FFFF, &mut s).unwrap();
        mux.on_event(5, Event::DmaRequest(Request::Lpuart1Rx), &mut s);
        assert_eq!(
            s.events,
            vec![(
                5,
                Event::DmaChannelRequest {
                    controller: 1,
                    channel: 2
                }
            )]
        );
        assert!(w(&mut mux, 0x0C, 36).is_err());
        // The F446's USART2 requests go nowhere on the G474.
        let mut s = Signals::default();
        mux.on_event(
            6,
            Event::DmaLevel {
                request: Request::Usart2Tx,
                high: true,
            },
            &mut s,
        );
        assert!(s.events.is_empty());
    }

    #[test]
    fn a_write_that_clears_en_only_disables() {
        let mut d = dma1();
        setup(&mut d, 4, CCR_ADC | CCR_DIR | CCR_EN);
        // embassy's request_stop: CCR = TEIE | TCIE (EN, DIR, MINC, sizes 0).
        w(&mut d, CCR1, CCR_TEIE | CCR_TCIE).unwrap();
        assert_eq!(
            r(&mut d, CCR1),
            CCR_ADC | CCR_DIR,
            "configuration read-only while EN = 1"
        );
        assert!(request(&mut d, 1).is_empty());
        // Disabled: now it can be reprogrammed.
        w(&mut d, CCR1, CCR_TEIE | CCR_TCIE).unwrap();
        assert_eq!(r(&mut d, CCR1), CCR_TEIE | CCR_TCIE);
    }

    #[test]
    fn memory_to_peripheral_direction() {
        let mut d = dma1();
        setup(&mut d, 2, CCR_ADC | CCR_DIR | CCR_EN);
        assert_eq!(
            request(&mut d, 1),
            vec![Copy {
                from: 0x2000_0000,
                to: ADC1_DR,
                size: 2
            }]
        );
    }
}
