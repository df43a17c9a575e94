//! STM32F446 USART2 (RM0390 §25): the host link's UART, asynchronous 8N1 with 16× oversampling,
//! transmitter and receiver, DMA requests both ways, the IDLE line, overrun, and the interrupt
//! line (USART2 = position 38, RM0390 table 38). The host side is a byte queue with arrival
//! times (`send`) and a log of every byte sent with the time its stop bit ends (`output`).
//!
//! Behaviours this model commits to:
//! - Baud: with OVER8 = 0, baud = f_PCLK1 / USARTDIV and USART_BRR holds USARTDIV × 16 as
//!   mantissa ‖ fraction (§25.4.4, eq. 1), so one bit lasts BRR PCLK1 cycles. OVER8 = 1, word
//!   length 9 (M), parity (PCE), two or half stop bits (CR2.STOP), LIN, smartcard, IrDA,
//!   half-duplex, synchronous mode and hardware flow control are not modelled (`Unmodelled`).
//! - A frame is 10 bit times (start, 8 data, stop). Setting TE sends an idle frame first
//!   (§25.4.2, "Character transmission"); TC is set at the end of every frame when no data waits.
//! - A DR write while TE = 1 goes to the shift register at once if it is free (TXE stays 1),
//!   else waits in TDR (TXE = 0) until the frame in progress ends (§25.4.2, fig. 248).
//! - The TX DMA request is level-sensitive: high while TXE = 1 and DMAT = 1 (§25.4.13,
//!   "Transmission using DMA"); the RX DMA request is raised when RXNE rises with DMAR = 1 and
//!   served by reading DR (§25.4.13, "Reception using DMA").
//! - A byte that arrives while RXNE = 1 is lost and sets ORE; RDR keeps the old byte (§25.6.1).
//!   IDLE is set one frame after the last byte received, once per burst of bytes (§25.6.1).
//! - PE, FE, NF, ORE and IDLE clear on a read of SR followed by a read of DR; RXNE on a read of
//!   DR; TC on a read of SR followed by a write of DR, or by writing 0 to it (§25.6.1). The line
//!   never has noise or framing errors here: the host's bytes arrive whole.

use super::TICKS_PER_S;
use super::{merge, ClockDomain, Clocks, Event, Peripheral, Request, Signals, Time, Unmodelled};
use std::any::Any;
use std::collections::VecDeque;

const SR: u32 = 0x00;
const DR: u32 = 0x04;
const BRR: u32 = 0x08;
const CR1: u32 = 0x0C;
const CR2: u32 = 0x10;
const CR3: u32 = 0x14;
const GTPR: u32 = 0x18;

// USART_SR (§25.6.1).
const SR_PE: u32 = 1 << 0;
const SR_FE: u32 = 1 << 1;
const SR_NF: u32 = 1 << 2;
const SR_ORE: u32 = 1 << 3;
const SR_IDLE: u32 = 1 << 4;
const SR_RXNE: u32 = 1 << 5;
const SR_TC: u32 = 1 << 6;
const SR_TXE: u32 = 1 << 7;
/// Reset value 0x00C0: TXE and TC set.
const SR_RESET: u32 = SR_TXE | SR_TC;

// USART_CR1 (§25.6.4).
const CR1_RE: u32 = 1 << 2;
const CR1_TE: u32 = 1 << 3;
const CR1_IDLEIE: u32 = 1 << 4;
const CR1_RXNEIE: u32 = 1 << 5;
const CR1_TCIE: u32 = 1 << 6;
const CR1_TXEIE: u32 = 1 << 7;
const CR1_PEIE: u32 = 1 << 8;
const CR1_PCE: u32 = 1 << 10;
const CR1_M: u32 = 1 << 12;
const CR1_UE: u32 = 1 << 13;
const CR1_OVER8: u32 = 1 << 15;
/// SBK (0), RWU (1), WAKE (11) and PS (9) are accepted as stored bits with no effect but SBK
/// and RWU, which must stay 0.
const CR1_UNMODELLED: u32 = (1 << 0) | (1 << 1) | CR1_PCE | CR1_M | CR1_OVER8;

// USART_CR2 (§25.6.5): only ADD (3:0) may be non-zero; STOP (13:12) = 00 is one stop bit.
const CR2_ALLOWED: u32 = 0xF;
// USART_CR3 (§25.6.6).
const CR3_EIE: u32 = 1 << 0;
const CR3_DMAR: u32 = 1 << 6;
const CR3_DMAT: u32 = 1 << 7;
const CR3_ALLOWED: u32 = CR3_EIE | CR3_DMAR | CR3_DMAT;

/// USART2's position in the vector table (RM0390 table 38).
pub const IRQ_USART2: u16 = 38;
const BITS_PER_FRAME: u64 = 10;

/// The USART.
pub struct UsartF4 {
    sr: u32,
    rdr: u8,
    brr: u32,
    cr1: u32,
    cr2: u32,
    cr3: u32,
    gtpr: u32,
    pclk_hz: u64,
    /// A read of SR since the last DR access (the first half of the flag-clearing sequences).
    sr_read: bool,
    /// The byte in TDR waiting for the shift register.
    tdr: Option<u8>,
    /// The frame being shifted out: (byte or None for the idle frame, time its stop bit ends).
    shifting: Option<(Option<u8>, Time)>,
    /// Host bytes not yet received, with the time each one's stop bit ends.
    incoming: VecDeque<(Time, u8)>,
    /// When IDLE is due (one frame after the last byte received).
    idle_at: Option<Time>,
    /// The TX DMA request's level as last signalled.
    tx_request: bool,
    /// Every byte sent, with the time its stop bit ended.
    output: Vec<(Time, u8)>,
    /// Bytes lost to overrun.
    pub overruns: u64,
}

impl Default for UsartF4 {
    fn default() -> Self {
        Self::new()
    }
}

impl UsartF4 {
    pub fn new() -> Self {
        Self {
            sr: SR_RESET,
            rdr: 0,
            brr: 0,
            cr1: 0,
            cr2: 0,
            cr3: 0,
            gtpr: 0,
            pclk_hz: 0,
            sr_read: false,
            tdr: None,
            shifting: None,
            incoming: VecDeque::new(),
            idle_at: None,
            tx_request: false,
            output: Vec::new(),
            overruns: 0,
        }
    }

    /// One bit, master ticks (BRR PCLK1 cycles), or None before the clock and BRR are set.
    pub fn bit_ticks(&self) -> Option<Time> {
        if self.pclk_hz == 0 || self.brr < 16 || !TICKS_PER_S.is_multiple_of(self.pclk_hz) {
            return None;
        }
        Some(self.brr as u64 * (TICKS_PER_S / self.pclk_hz))
    }

    /// The configured rate, baud.
    pub fn baud(&self) -> Option<f64> {
        self.bit_ticks().map(|t| TICKS_PER_S as f64 / t as f64)
    }

    fn frame_ticks(&self) -> Option<Time> {
        self.bit_ticks().map(|b| b * BITS_PER_FRAME)
    }

    /// Queues `bytes` from the host, back to back at the line rate from `at` (after whatever is
    /// still queued). Before the USART is configured the bytes wait. Returns when the last
    /// one's stop bit ends.
    pub fn send(&mut self, at: Time, bytes: &[u8]) -> Time {
        let frame = self.frame_ticks().unwrap_or(TICKS_PER_S / 92_160);
        let mut t = self.incoming.back().map_or(at, |&(last, _)| last.max(at));
        for &b in bytes {
            t += frame;
            self.incoming.push_back((t, b));
        }
        t
    }

    /// Every byte transmitted so far, with the time its stop bit ended.
    pub fn output(&self) -> &[(Time, u8)] {
        &self.output
    }

    fn enabled(&self) -> bool {
        self.cr1 & CR1_UE != 0
    }

    fn update_tx_request(&mut self, now: Time, out: &mut Signals) {
        let level = self.enabled()
            && self.cr1 & CR1_TE != 0
            && self.cr3 & CR3_DMAT != 0
            && self.sr & SR_TXE != 0;
        if level != self.tx_request {
            self.tx_request = level;
            out.events.push((
                now,
                Event::DmaLevel {
                    request: Request::Usart2Tx,
                    high: level,
                },
            ));
        }
    }

    /// Starts shifting `byte` (None: an idle frame) at `now`.
    fn start_frame(&mut self, now: Time, byte: Option<u8>) -> Result<(), String> {
        let frame = self
            .frame_ticks()
            .ok_or("USART2 transmits with no baud rate (PCLK1 or BRR not set)")?;
        self.shifting = Some((byte, now + frame));
        self.sr &= !SR_TC;
        Ok(())
    }

    fn write_dr(&mut self, now: Time, value: u32, out: &mut Signals) -> Result<(), Unmodelled> {
        if !self.enabled() || self.cr1 & CR1_TE == 0 {
            return Err(Unmodelled::write(
                DR,
                value,
                "USART2_DR written with UE or TE clear",
            ));
        }
        let byte = value as u8;
        if self.sr_read {
            // SR read then DR write clears TC (§25.6.1).
            self.sr &= !SR_TC;
        }
        self.sr_read = false;
        if self.shifting.is_none() {
            self.start_frame(now, Some(byte))
                .map_err(|e| Unmodelled::write(DR, value, e))?;
            // Straight to the shift register: TXE stays 1, so the level request is still up and
            // the DMA moves the next byte into TDR at once.
            if self.tx_request {
                out.events.push((
                    now,
                    Event::DmaLevel {
                        request: Request::Usart2Tx,
                        high: true,
                    },
                ));
            }
        } else if self.tdr.is_none() {
            self.tdr = Some(byte);
            self.sr &= !SR_TXE;
        } else {
            return Err(Unmodelled::write(
                DR,
                value,
                "USART2_DR written with TXE = 0 (the byte in TDR would be overwritten)",
            ));
        }
        self.update_tx_request(now, out);
        out.replan = true;
        Ok(())
    }

    fn read_dr(&mut self) -> u32 {
        if self.sr_read {
            self.sr &= !(SR_PE | SR_FE | SR_NF | SR_ORE | SR_IDLE);
        }
        self.sr_read = false;
        self.sr &= !SR_RXNE;
        self.rdr as u32
    }

    fn check_cr1(&self, value: u32) -> Result<(), String> {
        if value & CR1_UNMODELLED != 0 {
            return Err(format!(
                "USART2_CR1 = {value:#06x}: OVER8, M, PCE, SBK and RWU are not modelled"
            ));
        }
        if value & !0xBFFF != 0 {
            return Err(format!("USART2_CR1 = {value:#06x}: reserved bits set"));
        }
        Ok(())
    }
}

impl Peripheral for UsartF4 {
    fn name(&self) -> &'static str {
        "USART2"
    }

    fn read(&mut self, _now: Time, offset: u32, _out: &mut Signals) -> Result<u32, Unmodelled> {
        Ok(match offset {
            SR => {
                self.sr_read = true;
                self.sr
            }
            DR => self.read_dr(),
            BRR => self.brr,
            CR1 => self.cr1,
            CR2 => self.cr2,
            CR3 => self.cr3,
            GTPR => self.gtpr,
            _ => return Err(Unmodelled::read(offset, "no USART2 register here")),
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
        match offset {
            SR => {
                // Only RXNE and TC may be cleared by writing 0 (rc_w0); the rest is read-only.
                let v = merge(self.sr, value, mask);
                let cleared = self.sr & !v & (SR_RXNE | SR_TC);
                self.sr &= !cleared;
            }
            DR => self.write_dr(now, value & mask, out)?,
            BRR => {
                let v = merge(self.brr, value, mask);
                if v & !0xFFFF != 0 {
                    return Err(Unmodelled::write(
                        offset,
                        value,
                        "USART2_BRR reserved bits set",
                    ));
                }
                self.brr = v;
            }
            CR1 => {
                let old = self.cr1;
                let v = merge(old, value, mask);
                self.check_cr1(v)
                    .map_err(|e| Unmodelled::write(offset, value, e))?;
                self.cr1 = v;
                let te_rises = v & CR1_TE != 0 && (old & CR1_TE == 0 || old & CR1_UE == 0);
                if te_rises && v & CR1_UE != 0 && self.shifting.is_none() {
                    // TE set: an idle frame goes out first (§25.4.2).
                    if self.frame_ticks().is_some() {
                        self.start_frame(now, None)
                            .map_err(|e| Unmodelled::write(offset, value, e))?;
                    }
                }
                if v & CR1_UE == 0 {
                    self.shifting = None;
                    self.tdr = None;
                }
                self.update_tx_request(now, out);
                out.replan = true;
            }
            CR2 => {
                let v = merge(self.cr2, value, mask);
                if v & !CR2_ALLOWED != 0 {
                    return Err(Unmodelled::write(
                        offset,
                        value,
                        "USART2_CR2: only one stop bit, asynchronous, no LIN is modelled",
                    ));
                }
                self.cr2 = v;
            }
            CR3 => {
                let v = merge(self.cr3, value, mask);
                if v & !CR3_ALLOWED != 0 {
                    return Err(Unmodelled::write(
                        offset,
                        value,
                        "USART2_CR3: only EIE, DMAR and DMAT are modelled",
                    ));
                }
                let dmar_rises = v & CR3_DMAR != 0 && self.cr3 & CR3_DMAR == 0;
                self.cr3 = v;
                if dmar_rises && self.sr & SR_RXNE != 0 {
                    out.events.push((now, Event::DmaRequest(Request::Usart2Rx)));
                }
                self.update_tx_request(now, out);
                out.replan = true;
            }
            GTPR => self.gtpr = merge(self.gtpr, value, mask),
            _ => return Err(Unmodelled::write(offset, value, "no USART2 register here")),
        }
        Ok(())
    }

    fn advance(&mut self, now: Time, out: &mut Signals) {
        loop {
            let next_tx = self.shifting.map(|(_, end)| end).filter(|&e| e <= now);
            let next_rx = self.incoming.front().map(|&(t, _)| t).filter(|&t| t <= now);
            let next_idle = self.idle_at.filter(|&t| t <= now);
            let Some(t) = [next_tx, next_rx, next_idle].into_iter().flatten().min() else {
                break;
            };
            if next_tx == Some(t) {
                let (byte, _) = self.shifting.take().unwrap_or((None, t));
                if let Some(b) = byte {
                    self.output.push((t, b));
                }
                match self.tdr.take() {
                    Some(b) => {
                        // TDR to the shift register: TXE rises.
                        let frame = self.frame_ticks().unwrap_or(0);
                        self.shifting = Some((Some(b), t + frame));
                        self.sr |= SR_TXE;
                    }
                    None => self.sr |= SR_TC,
                }
                self.update_tx_request(t, out);
            } else if next_rx == Some(t) {
                let Some((_, b)) = self.incoming.pop_front() else {
                    break;
                };
                if !self.enabled() || self.cr1 & CR1_RE == 0 {
                    continue; // nobody listening: the byte is gone
                }
                if self.sr & SR_RXNE != 0 {
                    self.sr |= SR_ORE;
                    self.overruns += 1;
                } else {
                    self.rdr = b;
                    self.sr |= SR_RXNE;
                    if self.cr3 & CR3_DMAR != 0 {
                        out.events.push((t, Event::DmaRequest(Request::Usart2Rx)));
                    }
                }
                self.idle_at = self.frame_ticks().map(|f| t + f);
            } else {
                self.idle_at = None;
                self.sr |= SR_IDLE;
            }
        }
    }

    fn next_event(&self) -> Option<Time> {
        let tx = self.shifting.map(|(_, end)| end);
        // Bytes wait until the receiver is on; they still need to be processed in time order.
        let rx = self.incoming.front().map(|&(t, _)| t);
        [tx, rx, self.idle_at].into_iter().flatten().min()
    }

    fn set_clocks(&mut self, _now: Time, clocks: &Clocks) {
        self.pclk_hz = ClockDomain::Apb1.hz(clocks);
    }

    fn irq_lines(&self, raise: &mut dyn FnMut(u16)) {
        let (sr, cr1, cr3) = (self.sr, self.cr1, self.cr3);
        let up = (cr1 & CR1_IDLEIE != 0 && sr & SR_IDLE != 0)
            || (cr1 & CR1_RXNEIE != 0 && sr & (SR_RXNE | SR_ORE) != 0)
            || (cr1 & CR1_TCIE != 0 && sr & SR_TC != 0)
            || (cr1 & CR1_TXEIE != 0 && sr & SR_TXE != 0)
            || (cr1 & CR1_PEIE != 0 && sr & SR_PE != 0)
            || (cr3 & CR3_EIE != 0 && sr & (SR_FE | SR_NF | SR_ORE) != 0);
        if up && self.enabled() {
            raise(IRQ_USART2);
        }
    }

    fn reset(&mut self, _now: Time) {
        let output = std::mem::take(&mut self.output);
        let incoming = std::mem::take(&mut self.incoming);
        let pclk = self.pclk_hz;
        *self = UsartF4::new();
        self.output = output;
        self.incoming = incoming;
        self.pclk_hz = pclk;
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

    const PCLK1: u64 = 45_000_000;

    fn configured() -> (UsartF4, Signals) {
        let mut u = UsartF4::new();
        let clocks = Clocks {
            pclk1_hz: PCLK1,
            ..Clocks::default()
        };
        u.set_clocks(0, &clocks);
        let mut s = Signals::default();
        // 921 600 baud: USARTDIV = 45 MHz / (16 × 921 600) = 3.0518 → BRR 0x31 (mantissa 3,
        // fraction 1): 45 MHz / 49 = 918 367 baud, 0.35 % slow.
        u.write(0, BRR, 0x31, 0xFFFF_FFFF, &mut s).unwrap();
        u.write(0, CR1, CR1_UE | CR1_TE | CR1_RE, 0xFFFF_FFFF, &mut s)
            .unwrap();
        (u, s)
    }

    #[test]
    fn brr_sets_the_bit_time() {
        let (u, _) = configured();
        assert_eq!(u.bit_ticks(), Some(49 * 80));
        assert!((u.baud().unwrap() - 918_367.3).abs() < 0.1);
    }

    #[test]
    fn a_byte_takes_ten_bit_times_after_the_idle_frame() {
        let (mut u, mut s) = configured();
        let frame = 10 * 49 * 80;
        // TE set at 0: an idle frame until `frame`.
        u.write(5, DR, 0x41, 0xFF, &mut s).unwrap();
        assert_eq!(u.sr & SR_TXE, 0, "TDR holds the byte behind the idle frame");
        u.advance(frame, &mut s);
        assert_eq!(u.sr & SR_TXE, SR_TXE);
        u.advance(2 * frame, &mut s);
        assert_eq!(u.output(), &[(2 * frame, 0x41)]);
        assert_eq!(u.sr & SR_TC, SR_TC);
    }

    #[test]
    fn received_bytes_raise_dma_requests_and_idle_follows() {
        let (mut u, mut s) = configured();
        u.write(0, CR3, CR3_DMAR, 0xFFFF_FFFF, &mut s).unwrap();
        u.send(1000, &[1, 2]);
        let frame = 10 * 49 * 80;
        s.events.clear();
        u.advance(1000 + frame, &mut s);
        assert_eq!(
            s.events,
            vec![(1000 + frame, Event::DmaRequest(Request::Usart2Rx))]
        );
        assert_eq!(u.read(0, DR, &mut s).unwrap(), 1);
        u.advance(1000 + 2 * frame, &mut s);
        assert_eq!(u.read(0, DR, &mut s).unwrap(), 2);
        assert_eq!(u.sr & SR_IDLE, 0);
        u.advance(1000 + 3 * frame, &mut s);
        assert_eq!(u.sr & SR_IDLE, SR_IDLE, "one frame after the last byte");
        // SR then DR clears it.
        let _ = u.read(0, SR, &mut s).unwrap();
        let _ = u.read(0, DR, &mut s).unwrap();
        assert_eq!(u.sr & SR_IDLE, 0);
    }

    #[test]
    fn a_byte_over_an_unread_one_is_an_overrun() {
        let (mut u, mut s) = configured();
        u.send(0, &[7, 8]);
        u.advance(3 * 10 * 49 * 80, &mut s);
        assert_eq!(u.sr & SR_ORE, SR_ORE);
        assert_eq!(u.overruns, 1);
        assert_eq!(
            u.read(0, DR, &mut s).unwrap(),
            7,
            "RDR keeps the first byte"
        );
    }

    #[test]
    fn the_tx_request_is_a_level() {
        let (mut u, mut s) = configured();
        s.events.clear();
        u.write(0, CR3, CR3_DMAT, 0xFFFF_FFFF, &mut s).unwrap();
        assert_eq!(
            s.events,
            vec![(
                0,
                Event::DmaLevel {
                    request: Request::Usart2Tx,
                    high: true
                }
            )]
        );
        s.events.clear();
        // The idle frame is shifting: the first byte waits in TDR, TXE falls.
        u.write(1, DR, 0x55, 0xFF, &mut s).unwrap();
        assert_eq!(
            s.events,
            vec![(
                1,
                Event::DmaLevel {
                    request: Request::Usart2Tx,
                    high: false
                }
            )]
        );
    }

    #[test]
    fn a_byte_straight_to_the_shifter_keeps_requesting() {
        let (mut u, mut s) = configured();
        u.advance(10 * 49 * 80, &mut s); // the idle frame is out
        u.write(0, CR3, CR3_DMAT, 0xFFFF_FFFF, &mut s).unwrap();
        s.events.clear();
        u.write(10 * 49 * 80, DR, 0x55, 0xFF, &mut s).unwrap();
        assert_eq!(u.sr & SR_TXE, SR_TXE);
        assert_eq!(
            s.events,
            vec![(
                10 * 49 * 80,
                Event::DmaLevel {
                    request: Request::Usart2Tx,
                    high: true
                }
            )],
            "the request stays up for the next byte"
        );
    }

    #[test]
    fn unmodelled_modes_are_refused() {
        let (mut u, mut s) = configured();
        assert!(u
            .write(0, CR1, CR1_UE | CR1_M, 0xFFFF_FFFF, &mut s)
            .is_err());
        assert!(u.write(0, CR2, 0x2000, 0xFFFF_FFFF, &mut s).is_err());
        assert!(u.write(0, CR3, 1 << 3, 0xFFFF_FFFF, &mut s).is_err());
        assert!(u.read(0, 0x1C, &mut s).is_err());
    }
}
