//! STM32G474 LPUART1 (RM0440 §38 "Low-power universal asynchronous receiver transmitter
//! (LPUART)"): the host link's UART on the G474, asynchronous 8N1, transmitter and receiver with
//! or without the 8-byte FIFOs, DMA requests both ways, the IDLE line, overrun, and the interrupt
//! line (LPUART1 = position 91, RM0440 §16.3 table 97; stm32-metapac 21's STM32G474RE vector
//! table agrees). The host side is a byte queue with arrival times (`send`) and a log of every
//! byte sent with the time its stop bit ends (`output`), as for the F446's USART2 (`usart_f4`).
//!
//! What embassy-stm32 0.6 writes here (usart/mod.rs `Uart::new_inner`, `configure`,
//! `find_and_set_brr`, `UartTx::write`, `on_interrupt`; usart/ringbuffered.rs), in order: RCC
//! enable-and-reset (APB1ENR2/APB1RSTR2 bit 0); CR3 = 0 (no RTS/CTS/DE); CR1.UE = 0; BRR =
//! 256 × f_ck / baud rounded, PRESC = 0 (/1); CR2 = 0 (one stop bit); CR3 ONEBIT = HDSEL = 0;
//! CR1 = UE | TE | RE | FIFOEN (usart_v4 always sets FIFOEN: FIFO mode is what runs); then CR3
//! DMAT before each DMA write; the ring-buffered receiver sets CR1.IDLEIE and CR3 EIE | DMAR,
//! and reads ISR then writes the whole ISR image to ICR to clear what it saw.
//!
//! Behaviours this model commits to:
//! - Baud: baud = 256 × f_ck / LPUARTDIV with LPUARTDIV = BRR[19:0] (§38.4.8 "LPUART baud rate
//!   generation"), f_ck the kernel clock (RCC_CCIPR.LPUART1SEL: PCLK1 by default, RM0440
//!   §7.4.26) divided by LPUART_PRESC (§38.7.11: 1, 2, 4, 6, 8, 10, 12, 16, 32, 64, 128, 256).
//!   A frame is 10 bit times (start, 8 data, stop), 10 × 256 × BRR kernel cycles, rounded to the
//!   nearest master tick (1/3.6 GHz): at 150 MHz and BRR 41 667 a frame is 39 062.8 ticks, taken
//!   as 39 063 (8 ppm long). BRR below 0x300 is forbidden (§38.4.8) and refused.
//! - Word length 7 or 9 (M1/M0), parity (PCE), stop bits other than 1 (CR2.STOP), mute mode,
//!   address match, wakeup from Stop, swap/inversion, half-duplex, RS-485 driver enable,
//!   RTS/CTS, OVRDIS, DDRE, the FIFO thresholds and their interrupts, and send-break are not
//!   modelled (`Unmodelled` when set). ISR.BUSY, CTS/CTSIF, CMF, SBKF, RWU, WUF, RXFT and TXFT
//!   read 0: none of them can be set by what is modelled, except BUSY during a reception and the
//!   threshold flags, which nothing here reads (a known gap).
//! - FIFOEN = 0: one TDR and one RDR (TXE/RXNE). FIFOEN = 1: an 8-byte TXFIFO and RXFIFO; TXE
//!   reads as TXFNF (TXFIFO not full), RXNE as RXFNE (RXFIFO not empty), and TXFE (TXFIFO empty)
//!   and RXFF (RXFIFO full) are shown (§38.4 "LPUART FIFOs and thresholds"). FIFOEN, BRR, PRESC
//!   and CR2 may only change while UE = 0 (§38.7.1, §38.7.2, §38.7.4, §38.7.11); the write that
//!   sets UE may carry them (the model reads "UE = 0" as the value before the write).
//! - Setting TE sends an idle frame first (§38.4 "Character transmission procedure"). A TDR write
//!   while TE = 1 goes to the shift register at once if it is free (TXE/TXFNF stays 1), else
//!   waits in TDR/TXFIFO; a write when TDR/TXFIFO is full would lose a byte: `Unmodelled`.
//! - TC is set when a frame containing data ends and no data waits (TXE = 1 / TXFE = 1); it is
//!   cleared by writing TCCF in ICR or by a TDR write (§38.7.6 ISR "TC"). The idle frame TE sends
//!   does not change it.
//! - The TX DMA request is a level: high while TXE (TXFNF in FIFO mode) = 1 and DMAT = 1 (§38.4
//!   "Transmission using DMA": "whenever the TXE flag (TXFNF flag if FIFO mode is enabled) is
//!   set"); the RX request is raised when a byte enters RDR/RXFIFO with DMAR = 1, and again after
//!   a read of RDR that leaves the RXFIFO not empty (§38.4 "Reception using DMA": "whenever the
//!   RXNE flag (RXFNE flag if FIFO mode is enabled) is set").
//! - RXNE/RXFNE is cleared by reading RDR (one byte out of the RXFIFO). A byte that arrives while
//!   RDR/RXFIFO is full is lost and sets ORE; what was received stays (§38.4 "Overrun error").
//!   IDLE is set one frame after the last byte received, once per burst. ORE, IDLE, TC (and PE,
//!   FE, NE, which never rise: the host's bytes arrive whole) clear through ICR: ORECF, IDLECF,
//!   TCCF, PECF, FECF, NECF (§38.7.8); other ICR bits (embassy writes the whole ISR image) clear
//!   nothing modelled and are ignored.
//! - Clearing UE stops the LPUART at once: the frame being shifted, TDR/TXFIFO and RDR/RXFIFO are
//!   discarded and the ISR flags go back to their reset values (§38.7.1 CR1 "UE", as the author
//!   reads it). TEACK/REACK follow TE/RE while UE = 1, with no acknowledge delay.
//! - RQR: RXFRQ discards RDR/RXFIFO, TXFRQ discards TDR/TXFIFO (§38.7.5); SBKRQ and MMRQ are not
//!   modelled.
//!
//! Not checked against the RM0440 PDF in this session (written from the register layout of
//! stm32-metapac 21 `usart_v4` and the author's reading of the USART/LPUART chapters): the exact
//! subsection numbers cited above other than §38.4.8 and §7.4.26, and that the LPUART_ICR has
//! no TXFECF (bit 5 is ignored here; TXFE is computed from the TXFIFO).

use super::{merge, Clocks, Event, Peripheral, Request, Signals, Time, Unmodelled, TICKS_PER_S};
use std::any::Any;
use std::collections::VecDeque;

const CR1: u32 = 0x00;
const CR2: u32 = 0x04;
const CR3: u32 = 0x08;
const BRR: u32 = 0x0C;
const RQR: u32 = 0x18;
const ISR: u32 = 0x1C;
const ICR: u32 = 0x20;
const RDR: u32 = 0x24;
const TDR: u32 = 0x28;
const PRESC: u32 = 0x2C;

// LPUART_ISR (§38.7.6 FIFO enabled / §38.7.7 FIFO disabled).
const ISR_PE: u32 = 1 << 0;
const ISR_FE: u32 = 1 << 1;
const ISR_NE: u32 = 1 << 2;
const ISR_ORE: u32 = 1 << 3;
const ISR_IDLE: u32 = 1 << 4;
/// RXNE (FIFO disabled) / RXFNE (FIFO enabled).
const ISR_RXNE: u32 = 1 << 5;
const ISR_TC: u32 = 1 << 6;
/// TXE (FIFO disabled) / TXFNF (FIFO enabled).
const ISR_TXE: u32 = 1 << 7;
const ISR_TEACK: u32 = 1 << 21;
const ISR_REACK: u32 = 1 << 22;
const ISR_TXFE: u32 = 1 << 23;
const ISR_RXFF: u32 = 1 << 24;

// LPUART_CR1 (§38.7.1).
const CR1_UE: u32 = 1 << 0;
const CR1_RE: u32 = 1 << 2;
const CR1_TE: u32 = 1 << 3;
const CR1_IDLEIE: u32 = 1 << 4;
const CR1_RXNEIE: u32 = 1 << 5;
const CR1_TCIE: u32 = 1 << 6;
const CR1_TXEIE: u32 = 1 << 7;
const CR1_PEIE: u32 = 1 << 8;
const CR1_FIFOEN: u32 = 1 << 29;
const CR1_TXFEIE: u32 = 1 << 30;
const CR1_RXFFIE: u32 = 1 << 31;
/// UESM (1), PS (9), PCE (10), WAKE (11), M0 (12), MME (13), CMIE (14), DEDT/DEAT (25:16) and
/// M1 (28), and the reserved bits 15, 26, 27, must stay 0.
const CR1_ALLOWED: u32 = CR1_UE
    | CR1_RE
    | CR1_TE
    | CR1_IDLEIE
    | CR1_RXNEIE
    | CR1_TCIE
    | CR1_TXEIE
    | CR1_PEIE
    | CR1_FIFOEN
    | CR1_TXFEIE
    | CR1_RXFFIE;

// LPUART_CR2 (§38.7.2): only ADD[31:24] and ADDM7 (4) may be non-zero (they only matter in mute
// mode, which cannot be entered here); STOP = 00 is one stop bit.
const CR2_ALLOWED: u32 = 0xFF00_0010;
// LPUART_CR3 (§38.7.3).
const CR3_EIE: u32 = 1 << 0;
const CR3_DMAR: u32 = 1 << 6;
const CR3_DMAT: u32 = 1 << 7;
const CR3_ALLOWED: u32 = CR3_EIE | CR3_DMAR | CR3_DMAT;

// LPUART_ICR (§38.7.8).
const ICR_CLEARS: u32 = ISR_PE | ISR_FE | ISR_NE | ISR_ORE | ISR_IDLE | ISR_TC;
// LPUART_RQR (§38.7.5).
const RQR_SBKRQ: u32 = 1 << 1;
const RQR_MMRQ: u32 = 1 << 2;
const RQR_RXFRQ: u32 = 1 << 3;
const RQR_TXFRQ: u32 = 1 << 4;

/// LPUARTDIV below this is forbidden (§38.4.8).
const BRR_MIN: u32 = 0x300;
/// The FIFOs' depth in FIFO mode (§38.4 "LPUART FIFOs and thresholds": 8 data).
const FIFO_DEPTH: usize = 8;
/// LPUART_PRESC.PRESCALER 0..=11 (§38.7.11).
const PRESC_DIV: [u64; 12] = [1, 2, 4, 6, 8, 10, 12, 16, 32, 64, 128, 256];

/// LPUART1's position in the vector table (RM0440 table 97).
pub const IRQ_LPUART1: u16 = 91;
const BITS_PER_FRAME: u64 = 10;

/// The LPUART.
pub struct LpuartG4 {
    cr1: u32,
    cr2: u32,
    cr3: u32,
    brr: u32,
    presc: u32,
    /// PE, FE, NE, ORE, IDLE, TC.
    flags: u32,
    kernel_hz: u64,
    /// TDR (FIFO disabled, at most one byte) or the TXFIFO.
    tx_fifo: VecDeque<u8>,
    /// RDR (FIFO disabled) or the RXFIFO.
    rx_fifo: VecDeque<u8>,
    /// What a read of an empty RDR returns: the last byte received.
    rdr_last: u8,
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

impl Default for LpuartG4 {
    fn default() -> Self {
        Self::new()
    }
}

impl LpuartG4 {
    pub fn new() -> Self {
        Self {
            cr1: 0,
            cr2: 0,
            cr3: 0,
            brr: 0,
            presc: 0,
            // Reset: TXE and TC set (the rest of the reset ISR is computed).
            flags: ISR_TC,
            kernel_hz: 0,
            tx_fifo: VecDeque::new(),
            rx_fifo: VecDeque::new(),
            rdr_last: 0,
            shifting: None,
            incoming: VecDeque::new(),
            idle_at: None,
            tx_request: false,
            output: Vec::new(),
            overruns: 0,
        }
    }

    /// One frame (10 bits), master ticks, rounded to the nearest tick; None before the kernel
    /// clock and BRR are set or when the kernel clock does not divide the master clock.
    pub fn frame_ticks(&self) -> Option<Time> {
        if self.kernel_hz == 0 || self.brr < BRR_MIN || !TICKS_PER_S.is_multiple_of(self.kernel_hz)
        {
            return None;
        }
        let div = PRESC_DIV[self.presc as usize];
        // §38.4.8: one bit = LPUARTDIV / 256 periods of the (prescaled) kernel clock.
        let x256 = BITS_PER_FRAME * self.brr as u64 * div * (TICKS_PER_S / self.kernel_hz);
        Some((x256 + 128) / 256)
    }

    /// The configured rate, baud (exact, from the registers: 256 × f_ck / (PRESC × BRR)).
    pub fn baud(&self) -> Option<f64> {
        self.frame_ticks()?;
        let div = PRESC_DIV[self.presc as usize] as f64;
        Some(256.0 * self.kernel_hz as f64 / (div * self.brr as f64))
    }

    /// Queues `bytes` from the host, back to back at the line rate from `at` (after whatever is
    /// still queued). Before the LPUART is configured the bytes wait. Returns when the last
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

    fn fifo_mode(&self) -> bool {
        self.cr1 & CR1_FIFOEN != 0
    }

    fn depth(&self) -> usize {
        if self.fifo_mode() {
            FIFO_DEPTH
        } else {
            1
        }
    }

    /// TXE (FIFO disabled) / TXFNF (FIFO enabled).
    fn txe(&self) -> bool {
        self.tx_fifo.len() < self.depth()
    }

    /// LPUART_ISR as read now.
    pub fn isr(&self) -> u32 {
        let bit = |on: bool, b: u32| if on { b } else { 0 };
        let on = self.enabled();
        let mut v = self.flags
            | bit(self.txe(), ISR_TXE)
            | bit(!self.rx_fifo.is_empty(), ISR_RXNE)
            | bit(on && self.cr1 & CR1_TE != 0, ISR_TEACK)
            | bit(on && self.cr1 & CR1_RE != 0, ISR_REACK);
        if self.fifo_mode() {
            v |= bit(self.tx_fifo.is_empty(), ISR_TXFE)
                | bit(self.rx_fifo.len() == FIFO_DEPTH, ISR_RXFF);
        }
        v
    }

    fn update_tx_request(&mut self, now: Time, out: &mut Signals) {
        let level =
            self.enabled() && self.cr1 & CR1_TE != 0 && self.cr3 & CR3_DMAT != 0 && self.txe();
        if level != self.tx_request {
            self.tx_request = level;
            out.events.push((
                now,
                Event::DmaLevel {
                    request: Request::Lpuart1Tx,
                    high: level,
                },
            ));
        }
    }

    fn rx_request(&self, now: Time, out: &mut Signals) {
        if self.enabled() && self.cr3 & CR3_DMAR != 0 && !self.rx_fifo.is_empty() {
            out.events
                .push((now, Event::DmaRequest(Request::Lpuart1Rx)));
        }
    }

    /// Starts shifting `byte` (None: an idle frame) at `now`.
    fn start_frame(&mut self, now: Time, byte: Option<u8>) -> Result<(), String> {
        let frame = self
            .frame_ticks()
            .ok_or("LPUART1 transmits with no baud rate (kernel clock or BRR not set)")?;
        self.shifting = Some((byte, now + frame));
        Ok(())
    }

    fn write_tdr(&mut self, now: Time, value: u32, out: &mut Signals) -> Result<(), Unmodelled> {
        if !self.enabled() || self.cr1 & CR1_TE == 0 {
            return Err(Unmodelled::write(
                TDR,
                value,
                "LPUART1_TDR written with UE or TE clear",
            ));
        }
        let byte = value as u8;
        // A TDR write clears TC (§38.7.6 "TC").
        self.flags &= !ISR_TC;
        if self.shifting.is_none() && self.tx_fifo.is_empty() {
            self.start_frame(now, Some(byte))
                .map_err(|e| Unmodelled::write(TDR, value, e))?;
        } else if self.txe() {
            self.tx_fifo.push_back(byte);
        } else {
            return Err(Unmodelled::write(
                TDR,
                value,
                "LPUART1_TDR written with TXE/TXFNF = 0 (a byte would be lost)",
            ));
        }
        // The request is a level: still high, the DMA moves the next item at once.
        if self.tx_request && self.txe() {
            out.events.push((
                now,
                Event::DmaLevel {
                    request: Request::Lpuart1Tx,
                    high: true,
                },
            ));
        }
        self.update_tx_request(now, out);
        out.replan = true;
        Ok(())
    }

    fn read_rdr(&mut self, now: Time, out: &mut Signals) -> u32 {
        if let Some(b) = self.rx_fifo.pop_front() {
            self.rdr_last = b;
            // More waiting in the RXFIFO: RXFNE stays 1, the request again.
            self.rx_request(now, out);
        }
        self.rdr_last as u32
    }

    /// UE cleared: everything in progress is dropped, the flags return to their reset values.
    fn stop(&mut self) {
        self.shifting = None;
        self.tx_fifo.clear();
        self.rx_fifo.clear();
        self.idle_at = None;
        self.flags = ISR_TC;
    }

    fn check_cr1(&self, old: u32, new: u32) -> Result<(), String> {
        if new & !CR1_ALLOWED != 0 {
            return Err(format!(
                "LPUART1_CR1 = {new:#010x}: only UE, RE, TE, FIFOEN and the IDLE/RXNE/TC/TXE/PE/TXFE/RXFF \
                 interrupt enables are modelled (word length, parity, mute, wakeup, DE and reserved bits must stay 0)"
            ));
        }
        if old & CR1_UE != 0 && (old ^ new) & CR1_FIFOEN != 0 {
            return Err(format!(
                "LPUART1_CR1 = {new:#010x}: FIFOEN changed while UE = 1 (§38.7.1: only when the LPUART is disabled)"
            ));
        }
        Ok(())
    }

    fn locked(
        &self,
        offset: u32,
        value: u32,
        old: u32,
        new: u32,
        name: &str,
    ) -> Result<(), Unmodelled> {
        if self.enabled() && old != new {
            return Err(Unmodelled::write(
                offset,
                value,
                format!("LPUART1_{name} changed while UE = 1 (§38.7: written only when the LPUART is disabled)"),
            ));
        }
        Ok(())
    }
}

impl Peripheral for LpuartG4 {
    fn name(&self) -> &'static str {
        "LPUART1"
    }

    fn read(&mut self, now: Time, offset: u32, out: &mut Signals) -> Result<u32, Unmodelled> {
        Ok(match offset {
            CR1 => self.cr1,
            CR2 => self.cr2,
            CR3 => self.cr3,
            BRR => self.brr,
            ISR => self.isr(),
            RDR => {
                let v = self.read_rdr(now, out);
                self.update_tx_request(now, out);
                v
            }
            PRESC => self.presc,
            RQR | ICR => return Err(Unmodelled::read(offset, "LPUART1_RQR/ICR are write-only")),
            TDR => {
                return Err(Unmodelled::read(
                    offset,
                    "LPUART1_TDR read (the model keeps no readable TDR)",
                ))
            }
            _ => return Err(Unmodelled::read(offset, "no LPUART1 register here")),
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
            CR1 => {
                let old = self.cr1;
                let v = merge(old, value, mask);
                self.check_cr1(old, v)
                    .map_err(|e| Unmodelled::write(offset, value, e))?;
                self.cr1 = v;
                if v & CR1_UE == 0 {
                    if old & CR1_UE != 0 {
                        self.stop();
                    }
                } else {
                    let te_rises = v & CR1_TE != 0 && (old & CR1_TE == 0 || old & CR1_UE == 0);
                    if te_rises && self.shifting.is_none() && self.frame_ticks().is_some() {
                        // TE set: an idle frame goes out first (§38.4 "Character transmission
                        // procedure").
                        self.start_frame(now, None)
                            .map_err(|e| Unmodelled::write(offset, value, e))?;
                    }
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
                        "LPUART1_CR2: only one stop bit, no swap/inversion/MSB first is modelled",
                    ));
                }
                self.locked(offset, value, self.cr2, v, "CR2")?;
                self.cr2 = v;
            }
            CR3 => {
                let v = merge(self.cr3, value, mask);
                if v & !CR3_ALLOWED != 0 {
                    return Err(Unmodelled::write(
                        offset,
                        value,
                        "LPUART1_CR3: only EIE, DMAR and DMAT are modelled",
                    ));
                }
                let dmar_rises = v & CR3_DMAR != 0 && self.cr3 & CR3_DMAR == 0;
                self.cr3 = v;
                if dmar_rises {
                    self.rx_request(now, out);
                }
                self.update_tx_request(now, out);
                out.replan = true;
            }
            BRR => {
                let v = merge(self.brr, value, mask);
                if v & !0xF_FFFF != 0 {
                    return Err(Unmodelled::write(
                        offset,
                        value,
                        "LPUART1_BRR reserved bits set",
                    ));
                }
                if v < BRR_MIN {
                    return Err(Unmodelled::write(
                        offset,
                        value,
                        "LPUART1_BRR below 0x300 is forbidden (§38.4.8)",
                    ));
                }
                self.locked(offset, value, self.brr, v, "BRR")?;
                self.brr = v;
            }
            PRESC => {
                let v = merge(self.presc, value, mask);
                if v > 11 {
                    return Err(Unmodelled::write(
                        offset,
                        value,
                        "LPUART1_PRESC above 1011 is reserved (§38.7.11)",
                    ));
                }
                self.locked(offset, value, self.presc, v, "PRESC")?;
                self.presc = v;
            }
            RQR => {
                let v = value & mask;
                if v & (RQR_SBKRQ | RQR_MMRQ) != 0 || v & !0x1F != 0 || v & 1 != 0 {
                    return Err(Unmodelled::write(
                        offset,
                        value,
                        "LPUART1_RQR: only RXFRQ and TXFRQ are modelled",
                    ));
                }
                if v & RQR_RXFRQ != 0 {
                    self.rx_fifo.clear();
                }
                if v & RQR_TXFRQ != 0 {
                    self.tx_fifo.clear();
                }
                self.update_tx_request(now, out);
                out.replan = true;
            }
            ISR => {
                return Err(Unmodelled::write(offset, value, "LPUART1_ISR is read-only"));
            }
            ICR => {
                // Write 1 to clear; bits that clear nothing modelled are ignored (see module doc).
                self.flags &= !(value & mask & ICR_CLEARS);
                out.replan = true;
            }
            RDR => {
                return Err(Unmodelled::write(offset, value, "LPUART1_RDR is read-only"));
            }
            TDR => self.write_tdr(now, value & mask, out)?,
            _ => return Err(Unmodelled::write(offset, value, "no LPUART1 register here")),
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
                match self.tx_fifo.pop_front() {
                    Some(b) => {
                        // TDR/TXFIFO to the shift register: TXE/TXFNF rises.
                        let frame = self.frame_ticks().unwrap_or(0);
                        self.shifting = Some((Some(b), t + frame));
                    }
                    None if byte.is_some() => self.flags |= ISR_TC,
                    None => {}
                }
                self.update_tx_request(t, out);
            } else if next_rx == Some(t) {
                let Some((_, b)) = self.incoming.pop_front() else {
                    break;
                };
                if !self.enabled() || self.cr1 & CR1_RE == 0 {
                    continue; // nobody listening: the byte is gone
                }
                if self.rx_fifo.len() >= self.depth() {
                    self.flags |= ISR_ORE;
                    self.overruns += 1;
                } else {
                    self.rx_fifo.push_back(b);
                    self.rx_request(t, out);
                }
                self.idle_at = self.frame_ticks().map(|f| t + f);
            } else {
                self.idle_at = None;
                self.flags |= ISR_IDLE;
            }
        }
    }

    fn next_event(&self) -> Option<Time> {
        let tx = self.shifting.map(|(_, end)| end);
        let rx = self.incoming.front().map(|&(t, _)| t);
        [tx, rx, self.idle_at].into_iter().flatten().min()
    }

    fn set_clocks(&mut self, _now: Time, clocks: &Clocks) {
        self.kernel_hz = clocks.lpuart1_hz;
    }

    fn irq_lines(&self, raise: &mut dyn FnMut(u16)) {
        let (isr, cr1, cr3) = (self.isr(), self.cr1, self.cr3);
        let up = (cr1 & CR1_IDLEIE != 0 && isr & ISR_IDLE != 0)
            || (cr1 & CR1_RXNEIE != 0 && isr & (ISR_RXNE | ISR_ORE) != 0)
            || (cr1 & CR1_TCIE != 0 && isr & ISR_TC != 0)
            || (cr1 & CR1_TXEIE != 0 && isr & ISR_TXE != 0)
            || (cr1 & CR1_PEIE != 0 && isr & ISR_PE != 0)
            || (cr1 & CR1_TXFEIE != 0 && isr & ISR_TXFE != 0)
            || (cr1 & CR1_RXFFIE != 0 && isr & ISR_RXFF != 0)
            || (cr3 & CR3_EIE != 0 && isr & (ISR_FE | ISR_NE | ISR_ORE) != 0);
        if up && self.enabled() {
            raise(IRQ_LPUART1);
        }
    }

    fn reset(&mut self, _now: Time) {
        let output = std::mem::take(&mut self.output);
        let incoming = std::mem::take(&mut self.incoming);
        let kernel = self.kernel_hz;
        *self = LpuartG4::new();
        self.output = output;
        self.incoming = incoming;
        self.kernel_hz = kernel;
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

    const PCLK1: u64 = 150_000_000;
    /// 256 × 150 MHz / 921 600 = 41 666.7, rounded as embassy's `calculate_brr` does.
    const BRR_921600: u32 = 41_667;
    /// 10 × 41 667 × 24 ticks / 256 = 39 062.8 → 39 063.
    const FRAME: Time = 39_063;

    fn w(u: &mut LpuartG4, at: Time, off: u32, v: u32, s: &mut Signals) -> Result<(), Unmodelled> {
        u.write(at, off, v, 0xFFFF_FFFF, s)
    }

    /// embassy-stm32 0.6's sequence (module doc), FIFO mode.
    fn configured(fifo: bool) -> (LpuartG4, Signals) {
        let mut u = LpuartG4::new();
        let clocks = Clocks {
            pclk1_hz: PCLK1,
            lpuart1_hz: PCLK1,
            ..Clocks::default()
        };
        u.set_clocks(0, &clocks);
        let mut s = Signals::default();
        w(&mut u, 0, CR3, 0, &mut s).unwrap();
        w(&mut u, 0, CR1, 0, &mut s).unwrap();
        w(&mut u, 0, BRR, BRR_921600, &mut s).unwrap();
        w(&mut u, 0, PRESC, 0, &mut s).unwrap();
        w(&mut u, 0, CR2, 0, &mut s).unwrap();
        w(&mut u, 0, CR3, 0, &mut s).unwrap();
        let fifoen = if fifo { CR1_FIFOEN } else { 0 };
        w(&mut u, 0, CR1, CR1_UE | CR1_TE | CR1_RE | fifoen, &mut s).unwrap();
        (u, s)
    }

    #[test]
    fn brr_sets_the_bit_time() {
        let (u, _) = configured(true);
        assert_eq!(u.frame_ticks(), Some(FRAME));
        assert!((u.baud().unwrap() - 921_592.6).abs() < 0.1);
        // PRESC divides the kernel clock: /4 with BRR / 4 gives (nearly) the same rate.
        let mut v = LpuartG4::new();
        v.set_clocks(
            0,
            &Clocks {
                lpuart1_hz: PCLK1,
                ..Clocks::default()
            },
        );
        let mut s = Signals::default();
        w(&mut v, 0, PRESC, 2, &mut s).unwrap();
        w(&mut v, 0, BRR, 10_417, &mut s).unwrap();
        assert!((v.baud().unwrap() - 921_570.5).abs() < 0.1);
    }

    #[test]
    fn reset_isr_and_acknowledge_flags() {
        let u = LpuartG4::new();
        assert_eq!(
            u.isr(),
            ISR_TXE | ISR_TC,
            "reset value 0x0000_00C0 (FIFO disabled)"
        );
        let (u, _) = configured(true);
        assert_eq!(
            u.isr(),
            ISR_TXE | ISR_TC | ISR_TEACK | ISR_REACK | ISR_TXFE,
            "TXFNF, TC, TEACK, REACK, TXFE"
        );
    }

    #[test]
    fn a_byte_takes_ten_bit_times_after_the_idle_frame() {
        let (mut u, mut s) = configured(false);
        // TE set at 0: an idle frame until FRAME; the byte waits in TDR.
        w(&mut u, 5, TDR, 0x41, &mut s).unwrap();
        assert_eq!(
            u.isr() & ISR_TXE,
            0,
            "TDR holds the byte behind the idle frame"
        );
        assert_eq!(u.isr() & ISR_TC, 0, "a TDR write clears TC");
        u.advance(FRAME, &mut s);
        assert_eq!(u.isr() & ISR_TXE, ISR_TXE);
        assert_eq!(u.isr() & ISR_TC, 0, "the byte is shifting");
        u.advance(2 * FRAME, &mut s);
        assert_eq!(u.output(), &[(2 * FRAME, 0x41)]);
        assert_eq!(u.isr() & ISR_TC, ISR_TC);
        // TCCF clears it.
        w(&mut u, 0, ICR, ISR_TC, &mut s).unwrap();
        assert_eq!(u.isr() & ISR_TC, 0);
    }

    #[test]
    fn the_txfifo_holds_eight_behind_the_shifter() {
        let (mut u, mut s) = configured(true);
        u.advance(FRAME, &mut s); // the idle frame is out
        for i in 0..9u32 {
            w(&mut u, FRAME, TDR, i, &mut s).unwrap();
        }
        assert_eq!(
            u.isr() & (ISR_TXE | ISR_TXFE),
            0,
            "TXFIFO full: TXFNF = 0, TXFE = 0"
        );
        assert!(
            w(&mut u, FRAME, TDR, 9, &mut s).is_err(),
            "a tenth byte would be lost"
        );
        u.advance(FRAME + 9 * FRAME, &mut s);
        let bytes: Vec<u8> = u.output().iter().map(|&(_, b)| b).collect();
        assert_eq!(bytes, (0..9).collect::<Vec<u8>>());
        assert_eq!(u.output()[8].0, 10 * FRAME, "back to back");
        assert_eq!(u.isr() & (ISR_TC | ISR_TXFE), ISR_TC | ISR_TXFE);
    }

    #[test]
    fn the_tx_request_is_a_level_that_fills_the_fifo() {
        let (mut u, mut s) = configured(true);
        s.events.clear();
        w(&mut u, 0, CR3, CR3_DMAT, &mut s).unwrap();
        let level = |high| Event::DmaLevel {
            request: Request::Lpuart1Tx,
            high,
        };
        assert_eq!(s.events, vec![(0, level(true))]);
        // The DMA writes while the request is high: eight go into the TXFIFO behind the idle
        // frame; each write but the last leaves it high (another item at once).
        s.events.clear();
        for i in 0..8 {
            w(&mut u, 1, TDR, i, &mut s).unwrap();
        }
        let mut want = vec![(1, level(true)); 7];
        want.push((1, level(false)));
        assert_eq!(s.events, want);
        // The idle frame ends, the first byte moves to the shifter: TXFNF and the request rise.
        s.events.clear();
        u.advance(FRAME, &mut s);
        assert_eq!(s.events, vec![(FRAME, level(true))]);
    }

    #[test]
    fn a_byte_straight_to_the_shifter_keeps_requesting() {
        let (mut u, mut s) = configured(false);
        u.advance(FRAME, &mut s); // the idle frame is out
        w(&mut u, FRAME, CR3, CR3_DMAT, &mut s).unwrap();
        s.events.clear();
        w(&mut u, FRAME, TDR, 0x55, &mut s).unwrap();
        assert_eq!(u.isr() & ISR_TXE, ISR_TXE);
        assert_eq!(
            s.events,
            vec![(
                FRAME,
                Event::DmaLevel {
                    request: Request::Lpuart1Tx,
                    high: true
                }
            )],
            "the request stays up for the next byte"
        );
    }

    #[test]
    fn received_bytes_raise_dma_requests_and_idle_follows() {
        let (mut u, mut s) = configured(true);
        // The ring-buffered receiver: IDLEIE, then EIE | DMAR.
        w(
            &mut u,
            0,
            CR1,
            CR1_UE | CR1_TE | CR1_RE | CR1_FIFOEN | CR1_IDLEIE,
            &mut s,
        )
        .unwrap();
        w(&mut u, 0, CR3, CR3_EIE | CR3_DMAR, &mut s).unwrap();
        u.send(1000, &[1, 2]);
        s.events.clear();
        u.advance(1000 + FRAME, &mut s);
        assert_eq!(
            s.events,
            vec![(1000 + FRAME, Event::DmaRequest(Request::Lpuart1Rx))]
        );
        assert_eq!(u.read(0, RDR, &mut s).unwrap(), 1);
        u.advance(1000 + 2 * FRAME, &mut s);
        assert_eq!(u.read(0, RDR, &mut s).unwrap(), 2);
        assert_eq!(u.isr() & (ISR_IDLE | ISR_RXNE), 0);
        let mut lines = Vec::new();
        u.irq_lines(&mut |n| lines.push(n));
        assert!(lines.is_empty());
        u.advance(1000 + 3 * FRAME, &mut s);
        assert_eq!(
            u.isr() & ISR_IDLE,
            ISR_IDLE,
            "one frame after the last byte"
        );
        u.irq_lines(&mut |n| lines.push(n));
        assert_eq!(lines, vec![IRQ_LPUART1]);
        // embassy clears what it saw by writing the ISR image to ICR.
        let isr = u.read(0, ISR, &mut s).unwrap();
        w(&mut u, 0, ICR, isr, &mut s).unwrap();
        assert_eq!(u.isr() & ISR_IDLE, 0);
        u.advance(1000 + 10 * FRAME, &mut s);
        assert_eq!(u.isr() & ISR_IDLE, 0, "once per burst");
    }

    #[test]
    fn dmar_set_over_waiting_bytes_requests_each() {
        let (mut u, mut s) = configured(true);
        u.send(0, &[7, 8, 9]);
        u.advance(3 * FRAME, &mut s);
        assert_eq!(u.isr() & ISR_RXNE, ISR_RXNE);
        s.events.clear();
        w(&mut u, 3 * FRAME, CR3, CR3_DMAR, &mut s).unwrap();
        let rx = (3 * FRAME, Event::DmaRequest(Request::Lpuart1Rx));
        assert_eq!(s.events, vec![rx]);
        s.events.clear();
        assert_eq!(u.read(3 * FRAME, RDR, &mut s).unwrap(), 7);
        assert_eq!(s.events, vec![rx], "two more wait: RXFNE stays up");
        s.events.clear();
        assert_eq!(u.read(3 * FRAME, RDR, &mut s).unwrap(), 8);
        assert_eq!(u.read(3 * FRAME, RDR, &mut s).unwrap(), 9);
        assert_eq!(s.events, vec![rx], "none after the last");
        assert_eq!(u.isr() & ISR_RXNE, 0);
    }

    #[test]
    fn a_byte_over_a_full_rdr_or_rxfifo_is_an_overrun() {
        let (mut u, mut s) = configured(false);
        u.send(0, &[7, 8]);
        u.advance(3 * FRAME, &mut s);
        assert_eq!(u.isr() & ISR_ORE, ISR_ORE);
        assert_eq!(u.overruns, 1);
        assert_eq!(
            u.read(0, RDR, &mut s).unwrap(),
            7,
            "RDR keeps the first byte"
        );
        w(&mut u, 0, ICR, ISR_ORE, &mut s).unwrap();
        assert_eq!(u.isr() & ISR_ORE, 0, "ORECF clears it");
        let (mut u, mut s) = configured(true);
        u.send(0, &[0, 1, 2, 3, 4, 5, 6, 7, 8]);
        u.advance(10 * FRAME, &mut s);
        assert_eq!(u.isr() & (ISR_ORE | ISR_RXFF), ISR_ORE | ISR_RXFF);
        assert_eq!(u.overruns, 1, "the ninth byte is lost");
        assert_eq!(u.read(0, RDR, &mut s).unwrap(), 0);
    }

    #[test]
    fn ue_cleared_drops_everything_and_resets_the_flags() {
        let (mut u, mut s) = configured(true);
        u.send(0, &[1]);
        w(&mut u, 0, TDR, 0x33, &mut s).unwrap();
        u.advance(FRAME, &mut s);
        assert_eq!(u.isr() & ISR_RXNE, ISR_RXNE);
        w(&mut u, FRAME, CR1, CR1_FIFOEN, &mut s).unwrap();
        assert_eq!(u.isr(), ISR_TXE | ISR_TC | ISR_TXFE);
        u.advance(10 * FRAME, &mut s);
        assert!(
            u.output().is_empty(),
            "the byte behind the idle frame never went out"
        );
    }

    #[test]
    fn locked_and_unmodelled_settings_are_refused() {
        let (mut u, mut s) = configured(true);
        assert!(
            w(&mut u, 0, BRR, BRR_921600 + 1, &mut s).is_err(),
            "BRR with UE = 1"
        );
        assert!(
            w(&mut u, 0, BRR, BRR_921600, &mut s).is_ok(),
            "the same value is no change"
        );
        assert!(w(&mut u, 0, PRESC, 1, &mut s).is_err(), "PRESC with UE = 1");
        assert!(
            w(&mut u, 0, CR1, CR1_UE | CR1_TE | CR1_RE, &mut s).is_err(),
            "FIFOEN with UE = 1"
        );
        assert!(
            w(&mut u, 0, CR1, CR1_UE | CR1_FIFOEN | (1 << 12), &mut s).is_err(),
            "M0"
        );
        assert!(
            w(&mut u, 0, CR1, CR1_UE | CR1_FIFOEN | (1 << 15), &mut s).is_err(),
            "reserved"
        );
        assert!(w(&mut u, 0, CR3, 1 << 12, &mut s).is_err(), "OVRDIS");
        assert!(w(&mut u, 0, RQR, RQR_SBKRQ, &mut s).is_err(), "send break");
        assert!(u.read(0, ICR, &mut s).is_err());
        let mut v = LpuartG4::new();
        assert!(w(&mut v, 0, BRR, 0x2FF, &mut s).is_err(), "below 0x300");
        assert!(w(&mut v, 0, CR2, 0x2000, &mut s).is_err(), "two stop bits");
        assert!(w(&mut v, 0, PRESC, 12, &mut s).is_err());
    }

    #[test]
    fn rqr_flushes() {
        let (mut u, mut s) = configured(true);
        u.send(0, &[1, 2]);
        u.advance(2 * FRAME, &mut s);
        w(&mut u, 2 * FRAME, TDR, 5, &mut s).unwrap();
        w(&mut u, 2 * FRAME, TDR, 6, &mut s).unwrap();
        w(&mut u, 2 * FRAME, RQR, RQR_RXFRQ | RQR_TXFRQ, &mut s).unwrap();
        assert_eq!(u.isr() & (ISR_RXNE | ISR_TXFE), ISR_TXFE);
        u.advance(10 * FRAME, &mut s);
        assert_eq!(
            u.output().len(),
            1,
            "only the byte already shifting went out"
        );
    }
}
