//! The machine: Unicorn running the firmware's instructions, virtual time, the bus that routes
//! register accesses to the peripheral models, exception entry and return, sleep (WFE/WFI), the
//! RTT log buffer and the recorded pins.
//!
//! Time: every executed instruction costs one core clock (HCLK) cycle, plus flash wait states
//! when the ART accelerator is off (see `block_cycles`); exception entry and return cost 12
//! cycles each (Cortex-M4 TRM r0p1 §3.3.1, zero-wait-state memory). Peripherals only act at
//! their own event times; the CPU is never run past the next one, so an interrupt is taken
//! within one translated block (a few instructions) of the moment its flag rises.

use crate::elf::{thumb_instructions, Image};
use crate::periph::{
    micros, ticks_per_cycle, ChannelLevel, Clocks, Peripheral, ResetCause, Signals, Time,
    Unmodelled, TICKS_PER_S,
};
use crate::scs::{exc, Scs, SCS_BASE, SCS_SIZE};
use std::collections::HashMap;
use unicorn_engine::unicorn_const::{uc_error, Arch, Mode, Prot};
use unicorn_engine::{RegisterARM, Unicorn};

/// Cycles the Cortex-M4 spends stacking or unstacking an exception frame.
pub const EXCEPTION_CYCLES: u64 = 12;

/// Longest CPU slice without a peripheral event, so the RTT buffer is drained often enough.
const MAX_SLICE: Time = TICKS_PER_S / 10_000;

/// A peripheral mapped at `base`.
pub struct Mapped {
    pub base: u32,
    pub size: u32,
    pub p: Box<dyn Peripheral>,
}

/// What the chip description tells the machine (filled in by `crate::board`).
pub struct ChipSpec {
    pub name: &'static str,
    /// External interrupts implemented.
    pub irqs: u16,
    pub flash: (u32, u32),
    /// Address of the 16-bit flash size data register (FLASHSIZE, KiB) in system memory.
    pub flash_size_reg: u32,
    /// RAM regions (base, size).
    pub ram: Vec<(u32, u32)>,
    /// Index of the RCC in `periphs`, and how to read its clock tree and clock gates.
    pub rcc: usize,
    pub clocks: fn(&dyn Peripheral) -> Clocks,
    pub clock_enabled: fn(&dyn Peripheral, u32) -> Option<bool>,
    /// Index of the FLASH interface and how to read (ART/caches on, wait states).
    pub flash_if: usize,
    pub flash_timing: fn(&dyn Peripheral) -> (bool, u32),
    /// The flash interface's programming side (keys, program, erase, busy banks).
    pub flash_prog: fn(&mut dyn Peripheral) -> &mut crate::periph::flash_prog::Prog,
    /// How to read a GPIO port's pin mode.
    pub pin_mode: fn(&dyn Peripheral, u8) -> PinMode,
    /// Pins whose level is recorded.
    pub pins: Vec<PinSpec>,
}

/// A GPIO pin's configuration as far as its level is concerned.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PinMode {
    Input,
    Output { high: bool },
    Alternate(u8),
    Analog,
}

/// A recorded pin: which GPIO port (index in `periphs`), pin number, and the timer channel its
/// alternate function carries.
#[derive(Clone, Debug)]
pub struct PinSpec {
    pub name: &'static str,
    pub port: usize,
    pub pin: u8,
    /// (AF number, timer, channel) that drives the pin in alternate-function mode.
    pub af: Option<(u8, u8, u8)>,
}

/// A recorded edge: time, new level, and how many RTT log bytes had been written by then.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PinEdge {
    pub at: Time,
    pub high: bool,
    pub log_bytes: usize,
}

/// A register write the firmware made, kept for the latency and sequence checks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BusWrite {
    pub at: Time,
    pub addr: u32,
    pub value: u32,
    pub mask: u32,
}

/// Why a run stopped early.
#[derive(Clone, Debug, PartialEq)]
pub enum Stop {
    /// The firmware touched something the model does not implement, or the emulator failed.
    Fault(String),
    /// A breakpoint (BKPT) with a debugger attached: the core halts here.
    Breakpoint { pc: u32 },
}

impl std::fmt::Display for Stop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Stop::Fault(s) => write!(f, "{s}"),
            Stop::Breakpoint { pc } => {
                write!(f, "halted by the debugger at a breakpoint, pc 0x{pc:08X}")
            }
        }
    }
}

/// Everything the Unicorn hooks reach: the board's state.
pub struct Sim {
    pub chip: ChipSpec,
    pub now: Time,
    deadline: Time,
    ticks_per_cycle: u64,
    pub instructions: u64,
    /// Instructions executed in each exception (index: exception number; 0 = thread mode).
    pub instructions_in: Vec<u64>,
    pub periphs: Vec<Mapped>,
    pub scs: Scs,
    sig: Signals,
    pub stop: Option<Stop>,
    event_register: bool,
    replan: bool,
    block_cache: HashMap<u32, (u32, u32)>,
    flash_image: Vec<u8>,
    art: (bool, u32),
    pub clocks: Clocks,
    /// Timer channel levels last signalled: (timer, channel) → high.
    channel_levels: HashMap<(u8, u8), bool>,
    pub pins: Vec<Vec<PinEdge>>,
    pub writes: Vec<BusWrite>,
    /// Address ranges whose writes are kept in `writes`.
    pub watch: Vec<(u32, u32)>,
    pub events: Vec<(Time, crate::periph::Event)>,
    /// When this event is delivered, note the instructions executed so far in this exception
    /// (`snapshots`): per-sample cost from the ADC trigger (`Trgo { timer: 3 }`).
    pub snapshot_on: Option<(crate::periph::Event, usize)>,
    pub snapshots: Vec<(Time, u64)>,
    /// RTT: control block address and the bytes read so far with the time each was seen.
    rtt: Option<u32>,
    pub log: Vec<u8>,
    pub log_times: Vec<(Time, usize)>,
    pub resets: Vec<(Time, ResetCause)>,
    pending_reset: Option<ResetCause>,
    pub exceptions_taken: u64,
    pub sleeping_ticks: Time,
    /// RTT bytes written by the firmware but not yet drained, as of the last peripheral write.
    rtt_pending: usize,
    /// The RTT host as `probe-rs run` is: it sets the up channel to block-when-full
    /// (SEGGER_RTT_MODE_BLOCK_IF_FIFO_FULL = 2 in the descriptor's flags) each time it reads.
    pub rtt_host_blocking: bool,
    /// The 4-wire overlay (the 2D image) and its pins X+, X−, Y+, Y− as (GPIO port index in
    /// `periphs`, pin): told the pins' modes after every write to those ports.
    pub touch: Option<(
        std::rc::Rc<std::cell::RefCell<crate::touch::Panel>>,
        [(usize, u8); 4],
    )>,
    /// The RTT host stopped reading (a stalled or killed `probe-rs`): nothing is drained.
    pub rtt_host_stalled: bool,
    /// IRQ lines held high by a fault injection (an interrupt storm).
    pub stuck_irqs: Vec<u16>,
    /// Times of DMA reads from peripheral registers (ADC results reaching memory).
    pub dma_reads: Vec<Time>,
    /// DMA transfers waiting for the Unicorn handle (RAM on one side).
    ram_copies: Vec<RamCopy>,
    /// Print every block executed (BOARD_MODEL_TRACE=blocks): for debugging the model.
    trace_blocks: bool,
    /// The block a slice was stopped in front of (its address is the PC to resume at).
    stopped_at: Option<u32>,
    /// End of the current `run_until`.
    run_end: Time,
    /// Accesses to peripherals whose clock was off (ignored, as on the chip).
    pub unclocked: Vec<String>,
    /// What the core is doing.
    pub core: CoreState,
    /// A BKPT executed with no debugger attached: escalates to HardFault.
    bkpt_escalate: bool,
    /// Flash cells a store programmed in this slice, written again when the slice ends
    /// (address, bytes): Unicorn may complete the store itself after the hook.
    flash_fixups: Vec<(u32, Vec<u8>)>,
    /// Time the core spent waiting for the flash (fetches from a bank being written or erased).
    pub flash_stalled_ticks: Time,
    /// Lockups: time and PC.
    pub lockups: Vec<(Time, u32)>,
}

/// The core's state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CoreState {
    Running,
    /// Halted by a debugger (a BKPT with DHCSR.C_DEBUGEN = 1): peripherals run on, the IWDG
    /// stops only if DBGMCU says so.
    Halted,
    /// Locked up (a fault inside HardFault, ARMv7-M B1.5.15): no instruction runs until a reset.
    Locked,
}

/// A DMA transfer that touches RAM.
#[derive(Clone, Copy, Debug)]
enum RamCopy {
    /// Peripheral value already read: write it to RAM (or a peripheral).
    Write { to: u32, size: u8, value: u32 },
    /// Source in RAM: read and write both wait.
    Copy(crate::periph::Copy),
}

impl Sim {
    fn find(&self, addr: u32) -> Option<usize> {
        self.periphs
            .iter()
            .position(|m| addr >= m.base && addr - m.base < m.size)
    }

    /// Brings every peripheral up to `t`, in global time order, carrying what they signal.
    fn advance_periphs(&mut self, t: Time) {
        let mut last = None;
        let mut repeats = 0;
        loop {
            let next = self.periphs.iter().filter_map(|m| m.p.next_event()).min();
            let Some(n) = next.filter(|&n| n <= t) else {
                break;
            };
            if Some(n) == last {
                repeats += 1;
                if repeats > 1000 {
                    let who: Vec<&str> = self
                        .periphs
                        .iter()
                        .filter(|m| m.p.next_event() == Some(n))
                        .map(|m| m.p.name())
                        .collect();
                    self.stop = Some(Stop::Fault(format!(
                        "{who:?} keep reporting an event at {} µs after handling it (model bug)",
                        micros(n)
                    )));
                    return;
                }
            } else {
                repeats = 0;
            }
            last = Some(n);
            for m in &mut self.periphs {
                m.p.advance(n, &mut self.sig);
            }
            self.settle_local();
            if self.stop.is_some() {
                return;
            }
        }
        for m in &mut self.periphs {
            m.p.advance(t, &mut self.sig);
        }
        self.settle_local();
    }

    /// Carries signals that need no CPU memory: events between peripherals, pin levels, resets,
    /// interrupt lines. DMA copies that touch RAM are left in `sig.copies` for the caller that
    /// holds the Unicorn handle; copies between peripherals are done here.
    fn settle_local(&mut self) {
        let mut guard = 0;
        loop {
            guard += 1;
            if guard > 10_000 {
                self.stop = Some(Stop::Fault(
                    "peripheral signals do not settle (event loop)".into(),
                ));
                return;
            }
            let events = std::mem::take(&mut self.sig.events);
            let levels = std::mem::take(&mut self.sig.levels);
            if let Some(r) = self.sig.reset.take() {
                self.pending_reset.get_or_insert(r);
            }
            if std::mem::take(&mut self.sig.replan) {
                self.replan = true;
            }
            if events.is_empty() && levels.is_empty() {
                break;
            }
            for l in levels {
                self.channel_level(l);
            }
            for (t, e) in events {
                self.events.push((t, e));
                if let Some((on, ex)) = self.snapshot_on {
                    if on == e {
                        let n = self.instructions_in.get(ex).copied().unwrap_or(0);
                        self.snapshots.push((t, n));
                    }
                }
                let Sim { periphs, sig, .. } = self;
                for m in periphs.iter_mut() {
                    m.p.on_event(t, e, sig);
                }
                self.read_copy_sources(t);
            }
        }
        let now = self.now;
        self.read_copy_sources(now);
        if self.sample_irq_lines() {
            self.replan = true;
        }
    }

    /// Samples every interrupt line (peripheral flags and enables, and lines a fault injection
    /// holds high): a line that is high latches its NVIC pending bit unless the exception is
    /// active; one still high when its handler returns pends again (PM0214 §4.3, level-sensitive
    /// interrupts). Returns true if an exception became pending.
    pub(crate) fn sample_irq_lines(&mut self) -> bool {
        let Sim {
            periphs,
            scs,
            stuck_irqs,
            ..
        } = self;
        let mut new = false;
        for m in periphs.iter() {
            m.p.irq_lines(&mut |n| new |= scs.raise_irq(n));
        }
        for &n in stuck_irqs.iter() {
            new |= scs.raise_irq(n);
        }
        new
    }

    /// DMA copies whose source is a peripheral register are read at once, at the moment of the
    /// request (the ADC must see its data register read before its next conversion ends); only
    /// the write to RAM waits for the caller that holds the Unicorn handle.
    fn read_copy_sources(&mut self, t: Time) {
        let copies = std::mem::take(&mut self.sig.copies);
        for c in copies {
            if !Machine::is_periph(c.from) {
                self.ram_copies.push(RamCopy::Copy(c));
                continue;
            }
            self.dma_reads.push(t);
            match self.bus_read_at(c.from, c.size, t) {
                Ok(v) => self.ram_copies.push(RamCopy::Write {
                    to: c.to,
                    size: c.size,
                    value: v,
                }),
                Err(e) => {
                    self.stop
                        .get_or_insert(Stop::Fault(format!("DMA read: {e}")));
                }
            }
        }
    }

    fn channel_level(&mut self, l: ChannelLevel) {
        self.channel_levels.insert((l.timer, l.channel), l.high);
        self.update_pins(l.at);
    }

    /// Recomputes every recorded pin from its GPIO mode and the timer channel it may carry.
    fn update_pins(&mut self, at: Time) {
        for (i, spec) in self.chip.pins.iter().enumerate() {
            let mode = (self.chip.pin_mode)(&*self.periphs[spec.port].p, spec.pin);
            // Input/analog: the board's pull-down holds the line low (boards/README.md).
            let high = match mode {
                PinMode::Output { high } => high,
                PinMode::Alternate(af) => match spec.af {
                    Some((n, tim, ch)) if n == af => self
                        .channel_levels
                        .get(&(tim, ch))
                        .copied()
                        .unwrap_or(false),
                    _ => false,
                },
                PinMode::Input | PinMode::Analog => false,
            };
            // The timer channel drives the pad: GPIOx_IDR reads it back (RM0390 §7.3.11,
            // "the I/O state is read" in alternate-function mode; RM0440 §9.3.11).
            if let (PinMode::Alternate(_), Some(_)) = (mode, spec.af) {
                if let Some(g) = self.periphs[spec.port]
                    .p
                    .as_any_mut()
                    .downcast_mut::<crate::periph::gpio::Gpio>()
                {
                    g.set_alternate_level(spec.pin, Some(high));
                }
            }
            let rec = &mut self.pins[i];
            if rec.last().is_none_or(|e| e.high != high) {
                rec.push(PinEdge {
                    at,
                    high,
                    log_bytes: self.log.len() + self.rtt_pending,
                });
            }
        }
    }

    fn set_clocks(&mut self) {
        let c = (self.chip.clocks)(&*self.periphs[self.chip.rcc].p);
        if c != self.clocks {
            self.clocks = c;
            self.ticks_per_cycle = ticks_per_cycle(c.hclk_hz.max(1));
            let now = self.now;
            for m in &mut self.periphs {
                m.p.set_clocks(now, &c);
            }
            self.replan = true;
        }
    }

    /// Reads a peripheral register as a debugger would (for checks; read side effects apply).
    pub fn peek(&mut self, addr: u32) -> Result<u32, String> {
        self.bus_read(addr, 4)
    }

    /// The F446 ADC's first interleaved conversion starts, (ADC 1 or 2, time); empty on the G474
    /// or when the image never used dual interleaved mode.
    pub fn adc_interleaved_starts(&self) -> Vec<(u8, Time)> {
        self.periphs
            .iter()
            .find_map(|m| {
                m.p.as_any()
                    .downcast_ref::<crate::periph::adc_f4::AdcF4>()
                    .map(|a| a.interleaved_starts().to_vec())
            })
            .unwrap_or_default()
    }

    /// Queues bytes from the host on the link UART (the F446's USART2, the G474's LPUART1),
    /// arriving back to back from `at`; returns when the last one's stop bit ends. Fails on a
    /// board whose link UART is not modelled.
    pub fn uart_send(&mut self, at: Time, bytes: &[u8]) -> Result<Time, String> {
        use crate::periph::{lpuart_g4::LpuartG4, usart_f4::UsartF4};
        let done = self.periphs.iter_mut().find_map(|m| {
            let p = m.p.as_any_mut();
            if let Some(u) = p.downcast_mut::<UsartF4>() {
                Some(u.send(at, bytes))
            } else {
                p.downcast_mut::<LpuartG4>().map(|u| u.send(at, bytes))
            }
        });
        let done = done.ok_or("this board's link UART is not modelled")?;
        self.replan = true;
        Ok(done)
    }

    /// Every byte the firmware sent on the link UART, with the time its stop bit ended.
    pub fn uart_output(&self) -> Vec<(Time, u8)> {
        use crate::periph::{lpuart_g4::LpuartG4, usart_f4::UsartF4};
        self.periphs
            .iter()
            .find_map(|m| {
                let p = m.p.as_any();
                p.downcast_ref::<UsartF4>()
                    .map(|u| u.output().to_vec())
                    .or_else(|| p.downcast_ref::<LpuartG4>().map(|u| u.output().to_vec()))
            })
            .unwrap_or_default()
    }

    /// Turns recording of a timer channel's output on or off.
    pub fn record(&mut self, timer: &str, channel: u8, on: bool) {
        let now = self.now;
        let Sim { periphs, sig, .. } = self;
        for m in periphs.iter_mut() {
            if let Some(t) = m.p.as_any_mut().downcast_mut::<crate::periph::tim::Timer>() {
                if t.name() == timer {
                    t.record_channel_at(now, channel, on, sig);
                }
            }
        }
        self.settle_local();
    }

    /// A CPU read of a peripheral register, now.
    fn bus_read(&mut self, addr: u32, size: u8) -> Result<u32, String> {
        let now = self.now;
        self.bus_read_at(addr, size, now)
    }

    /// A read of a peripheral register at time `now` (a DMA read happens at its request).
    fn bus_read_at(&mut self, addr: u32, size: u8, now: Time) -> Result<u32, String> {
        let i = self
            .find(addr)
            .ok_or_else(|| format!("read of unmapped peripheral address 0x{addr:08X}"))?;
        if !self.clocked(i, addr, None) {
            return Ok(0);
        }
        let m = &mut self.periphs[i];
        let off = addr - m.base;
        let word =
            m.p.read(now, off & !3, &mut self.sig)
                .map_err(|u| describe(m.p.name(), m.base, u))?;
        self.settle_local();
        let shift = 8 * (off & 3);
        Ok(match size {
            1 => (word >> shift) & 0xFF,
            2 => (word >> shift) & 0xFFFF,
            _ => word,
        })
    }

    /// A CPU or DMA write of a peripheral register.
    fn bus_write(&mut self, addr: u32, size: u8, value: u32) -> Result<(), String> {
        let i = self.find(addr).ok_or_else(|| {
            format!("write of 0x{value:X} to unmapped peripheral address 0x{addr:08X}")
        })?;
        if !self.clocked(i, addr, Some(value)) {
            return Ok(());
        }
        let now = self.now;
        let off = addr - self.periphs[i].base;
        let shift = 8 * (off & 3);
        let lane = match size {
            1 => 0xFFu32,
            2 => 0xFFFF,
            _ => 0xFFFF_FFFF,
        };
        let (v, mask) = (value << shift, lane << shift);
        if self.watch.iter().any(|&(b, s)| addr >= b && addr - b < s) {
            self.writes.push(BusWrite {
                at: now,
                addr: addr & !3,
                value: v,
                mask,
            });
        }
        let m = &mut self.periphs[i];
        m.p.write(now, off & !3, v, mask, &mut self.sig)
            .map_err(|u| describe(m.p.name(), m.base, u))?;
        if i == self.chip.rcc || self.periphs[i].p.name().starts_with("PWR") {
            crate::board::after_rcc_or_pwr_write(&mut self.periphs, self.chip.rcc, now);
            self.set_clocks();
        }
        if i == self.chip.flash_if {
            self.art = (self.chip.flash_timing)(&*self.periphs[i].p);
            // The F446's data cache follows FLASH_ACR's DCEN and DCRST (`DataCache`).
            if let Ok(acr) = self.periphs[i].p.read(now, 0, &mut self.sig) {
                (self.chip.flash_prog)(&mut *self.periphs[i].p).on_acr(acr);
            }
        }
        if self.chip.pins.iter().any(|p| p.port == i) {
            self.update_pins(now);
        }
        if let Some((panel, pins)) = &self.touch {
            if pins.iter().any(|(port, _)| *port == i) {
                let modes =
                    pins.map(|(port, pin)| (self.chip.pin_mode)(&*self.periphs[port].p, pin));
                panel.borrow_mut().set_pins(now, modes);
            }
        }
        self.settle_local();
        Ok(())
    }

    /// Whether block `i` has its bus clock on. A real chip ignores writes to, and reads 0 from, a
    /// peripheral whose clock is off (RM0390 §6.3.13; RM0440 §7.4.16); the model does the same
    /// and records the access, which the checks treat as a firmware defect.
    fn clocked(&mut self, i: usize, addr: u32, write: Option<u32>) -> bool {
        if i == self.chip.rcc {
            return true;
        }
        let base = self.periphs[i].base;
        if (self.chip.clock_enabled)(&*self.periphs[self.chip.rcc].p, base) != Some(false) {
            return true;
        }
        let what = match write {
            Some(v) => format!("write of 0x{v:X} to"),
            None => "read of".into(),
        };
        self.unclocked.push(format!(
            "{what} {} at 0x{addr:08X} at {} µs while its clock is off in RCC (lost on the chip)",
            self.periphs[i].p.name(),
            micros(self.now)
        ));
        false
    }

    /// Cycles a translated block of `insns` instructions and `bytes` bytes costs. With the ART
    /// accelerator (prefetch + instruction cache) on, every fetch is assumed to hit: one cycle per
    /// instruction. With it off, each 128-bit flash line costs LATENCY + 1 cycles and a block
    /// starts with a fresh line (RM0390 §3.4.2, "Instruction prefetch"; RM0440 §5.3.4).
    fn block_cycles(&self, addr: u32, insns: u32, bytes: u32) -> u64 {
        let in_flash = addr >= self.chip.flash.0 && addr - self.chip.flash.0 < self.chip.flash.1;
        let (art_on, ws) = self.art;
        if !in_flash || art_on || ws == 0 {
            return insns as u64;
        }
        let lines = (bytes as u64).div_ceil(16).max(1);
        (insns as u64).max(lines * (ws as u64 + 1))
    }
}

/// Hooks every CPU data read of flash (`flash_prog`): on the G474 a double word with a bad ECC
/// raises ECCD and the NMI; on the F446 the read is served through the ART data cache, whose
/// line may hold bytes an erase has since changed — those are put in place for this one load
/// (the hook runs before it) and the array's put back right after it.
fn install_flash_read_hooks(uc: &mut Unicorn<'static, Sim>) -> Result<(), String> {
    let (flash_base, flash_size) = uc.get_data().chip.flash;
    let stale: std::rc::Rc<std::cell::RefCell<Vec<(u32, [u8; 16])>>> = Default::default();
    let put_back = stale.clone();
    uc.add_mem_hook(
        unicorn_engine::unicorn_const::HookType::MEM_READ,
        flash_base as u64,
        (flash_base + flash_size - 1) as u64,
        move |uc: &mut Unicorn<'_, Sim>,
              _kind: unicorn_engine::unicorn_const::MemType,
              addr: u64,
              size: usize,
              _value: i64| {
            flash_data_read(uc, addr as u32, size as u32, &mut stale.borrow_mut());
            true
        },
    )
    .map_err(uc_err)?;
    uc.add_mem_hook(
        unicorn_engine::unicorn_const::HookType::MEM_READ_AFTER,
        flash_base as u64,
        (flash_base + flash_size - 1) as u64,
        move |uc: &mut Unicorn<'_, Sim>,
              _kind: unicorn_engine::unicorn_const::MemType,
              _addr: u64,
              _size: usize,
              _value: i64| {
            for (line, bytes) in put_back.borrow_mut().drain(..) {
                let _ = uc.mem_write(line as u64, &bytes);
            }
            true
        },
    )
    .map_err(uc_err)?;
    Ok(())
}

/// A CPU data read of `size` bytes of flash at `addr`, before the load happens: the G474's ECC
/// check (a double error pends the NMI, RM0440 §5.7.7) and the F446's data cache (RM0390
/// §3.4.2). Lines whose cached bytes differ from the array's are written over the array for
/// the load; `stale` keeps the array's bytes for the after-read hook to put back.
fn flash_data_read(
    uc: &mut Unicorn<'_, Sim>,
    addr: u32,
    size: u32,
    stale: &mut Vec<(u32, [u8; 16])>,
) {
    use crate::periph::flash_prog::DataCache;
    let s = uc.get_data_mut();
    let fi = s.chip.flash_if;
    let prog = (s.chip.flash_prog)(&mut *s.periphs[fi].p);
    if prog.ecc_read(addr, size) {
        s.scs.set_pending(exc::NMI);
        s.replan = true;
    }
    let prog = (s.chip.flash_prog)(&mut *s.periphs[fi].p);
    if !prog.data_cache().is_some_and(|c| c.enabled()) {
        return;
    }
    let first = addr & !(DataCache::LINE_BYTES - 1);
    let last = (addr + size.max(1) - 1) & !(DataCache::LINE_BYTES - 1);
    let mut line = first;
    while line <= last {
        let mut array = [0u8; 16];
        if uc.mem_read(line as u64, &mut array).is_err() {
            return;
        }
        let s = uc.get_data_mut();
        let prog = (s.chip.flash_prog)(&mut *s.periphs[fi].p);
        let Some(cache) = prog.data_cache() else {
            return;
        };
        let served = cache.read(line, array);
        if served != array && uc.mem_write(line as u64, &served).is_ok() {
            stale.push((line, array));
        }
        line += DataCache::LINE_BYTES;
    }
}

fn describe(name: &str, base: u32, u: Unmodelled) -> String {
    let what = match u.write {
        Some(v) => format!("write of 0x{v:08X} to"),
        None => "read of".into(),
    };
    format!("{what} {name} at 0x{:08X}: {}", base + u.offset, u.why)
}

/// The machine: a Unicorn instance whose data is the board.
pub struct Machine {
    pub uc: Unicorn<'static, Sim>,
    pub image: Image,
    /// The main stack's region, painted at construction (`stack.rs`); None if the image lacks
    /// the symbols that bound it.
    pub stack: Option<crate::stack::Region>,
}

fn uc_err(e: uc_error) -> String {
    format!("unicorn: {e:?}")
}

impl Machine {
    /// Builds the machine: memory map from `chip`, the image loaded into flash, every peripheral
    /// mapped, the core reset from the vector table.
    pub fn new(
        chip: ChipSpec,
        periphs: Vec<Mapped>,
        image: Image,
        rtt: bool,
    ) -> Result<Self, String> {
        let irqs = chip.irqs;
        let (flash_base, flash_size) = chip.flash;
        let chip_flash_size_reg = chip.flash_size_reg;
        let mut flash_image = vec![0xFFu8; flash_size as usize];
        for s in &image.segments {
            if s.addr < flash_base
                || (s.addr - flash_base) as usize + s.bytes.len() > flash_size as usize
            {
                return Err(format!(
                    "image segment at 0x{:08X} ({} B) is outside flash",
                    s.addr,
                    s.bytes.len()
                ));
            }
            let o = (s.addr - flash_base) as usize;
            flash_image[o..o + s.bytes.len()].copy_from_slice(&s.bytes);
        }
        let pins = vec![Vec::new(); chip.pins.len()];
        let rtt_addr = if rtt {
            image.symbol("_SEGGER_RTT")
        } else {
            None
        };
        let sim = Sim {
            chip,
            now: 0,
            deadline: 0,
            ticks_per_cycle: 1,
            instructions: 0,
            instructions_in: vec![0; 512],
            periphs,
            scs: Scs::new(irqs),
            sig: Signals::default(),
            stop: None,
            event_register: false,
            replan: false,
            block_cache: HashMap::new(),
            flash_image: flash_image.clone(),
            art: (false, 0),
            clocks: Clocks::default(),
            channel_levels: HashMap::new(),
            pins,
            writes: Vec::new(),
            watch: Vec::new(),
            events: Vec::new(),
            snapshot_on: None,
            snapshots: Vec::new(),
            rtt: rtt_addr,
            log: Vec::new(),
            log_times: Vec::new(),
            resets: Vec::new(),
            pending_reset: None,
            exceptions_taken: 0,
            sleeping_ticks: 0,
            rtt_pending: 0,
            rtt_host_blocking: false,
            touch: None,
            rtt_host_stalled: false,
            stuck_irqs: Vec::new(),
            dma_reads: Vec::new(),
            ram_copies: Vec::new(),
            trace_blocks: std::env::var("BOARD_MODEL_TRACE").is_ok_and(|v| v == "blocks"),
            stopped_at: None,
            run_end: 0,
            unclocked: Vec::new(),
            core: CoreState::Running,
            bkpt_escalate: false,
            flash_fixups: Vec::new(),
            flash_stalled_ticks: 0,
            lockups: Vec::new(),
        };
        let mut uc =
            Unicorn::new_with_data(Arch::ARM, Mode::THUMB | Mode::MCLASS, sim).map_err(uc_err)?;
        uc.ctl_set_cpu_model(unicorn_engine::ArmCpuModel::CORTEX_M4 as i32)
            .map_err(uc_err)?;
        uc.mem_map(
            flash_base as u64,
            flash_size as u64,
            Prot::READ | Prot::EXEC,
        )
        .map_err(uc_err)?;
        uc.mem_write(flash_base as u64, &flash_image)
            .map_err(uc_err)?;
        // The flash size data register, in the system memory's engineering bytes (RM0390
        // §39.2 FLASHSIZE at 0x1FFF_7A22; RM0440 §48.2 at 0x1FFF_75E0): read-only, the part's
        // flash in KiB. Its 4 KiB page is mapped read-only and holds nothing else the model
        // knows (reads of the rest return 0).
        let fs_page = chip_flash_size_reg & !0xFFF;
        uc.mem_map(fs_page as u64, 0x1000, Prot::READ)
            .map_err(uc_err)?;
        uc.mem_write(
            chip_flash_size_reg as u64,
            &((flash_size / 1024) as u16).to_le_bytes(),
        )
        .map_err(uc_err)?;
        // A store to flash is a program operation of the flash interface (`flash_prog`): the
        // model decides what the cells hold afterwards (old AND new on the F446, a double word
        // into erased cells on the G474, nothing on an error) and the slice ends so a busy
        // flash can stall the core.
        uc.add_mem_hook(
            unicorn_engine::unicorn_const::HookType::MEM_WRITE_PROT,
            flash_base as u64,
            (flash_base + flash_size - 1) as u64,
            |uc: &mut Unicorn<'_, Sim>,
             _kind: unicorn_engine::unicorn_const::MemType,
             addr: u64,
             size: usize,
             value: i64| {
                let mut old = [0u8; 4];
                let n = size.min(4);
                let _ = uc.mem_read(addr, &mut old[..n]);
                let s = uc.get_data_mut();
                let now = s.now;
                let fi = s.chip.flash_if;
                let prog = (s.chip.flash_prog)(&mut *s.periphs[fi].p);
                match prog.store(
                    now,
                    addr as u32,
                    n as u8,
                    value as u32,
                    u32::from_le_bytes(old),
                ) {
                    Ok(cells) => {
                        // The store's own cells keep their content unless programmed (Unicorn
                        // may complete the store after this hook: the fix-ups undo it).
                        let mut fix: Vec<(u32, Vec<u8>)> = vec![(addr as u32, old[..n].to_vec())];
                        for (a, w) in cells {
                            fix.retain(|(f, _)| *f != a);
                            fix.push((a, w.to_le_bytes().to_vec()));
                        }
                        for (a, bytes) in &fix {
                            let _ = uc.mem_write(*a as u64, bytes);
                        }
                        let s = uc.get_data_mut();
                        s.flash_fixups.extend(fix);
                        // The slice ends at the next block (never inside this one: see the block
                        // hook), where a busy flash can stall the core.
                        s.replan = true;
                        true
                    }
                    Err(why) => {
                        let s = uc.get_data_mut();
                        s.stop.get_or_insert(Stop::Fault(format!(
                            "{why} (t = {} µs)",
                            micros(s.now)
                        )));
                        false
                    }
                }
            },
        )
        .map_err(uc_err)?;
        // The F446's data cache sees every CPU data read of flash (`install_flash_read_hooks`).
        let f446_data_cache = {
            let s = uc.get_data_mut();
            let fi = s.chip.flash_if;
            (s.chip.flash_prog)(&mut *s.periphs[fi].p)
                .data_cache()
                .is_some()
        };
        if f446_data_cache {
            install_flash_read_hooks(&mut uc)?;
        }
        let ram = uc.get_data().chip.ram.clone();
        for &(b, s) in &ram {
            uc.mem_map(b as u64, s as u64, Prot::ALL).map_err(uc_err)?;
        }
        // The stack painted once, before the first reset: RAM keeps it through system resets,
        // so the high-water mark covers every boot of the run.
        let stack = crate::stack::Region::of(&image, flash_base, &ram).ok();
        if let Some(r) = &stack {
            uc.mem_write(r.bottom as u64, &crate::stack::paint(r))
                .map_err(uc_err)?;
        }
        // Peripheral space (APB/AHB1 at 0x4000_0000, AHB2 at 0x4800_0000 / 0x5000_0000): one
        // MMIO window routed by address; an address nothing claims stops the run.
        uc.mmio_map(
            0x4000_0000,
            0x2000_0000,
            Some(|uc: &mut Unicorn<'_, Sim>, off: u64, size: usize| {
                let addr = 0x4000_0000u32 + off as u32;
                let r = uc.get_data_mut().bus_read(addr, size as u8);
                let v = finish_access(uc, r.map(Some)).unwrap_or(0);
                v as u64
            }),
            Some(
                |uc: &mut Unicorn<'_, Sim>, off: u64, size: usize, value: u64| {
                    let addr = 0x4000_0000u32 + off as u32;
                    let pending = rtt_pending(uc);
                    uc.get_data_mut().rtt_pending = pending;
                    let r = uc.get_data_mut().bus_write(addr, size as u8, value as u32);
                    finish_access(uc, r.map(|_| None));
                },
            ),
        )
        .map_err(uc_err)?;
        // Peripherals outside that window (DBGMCU at 0xE004_2000), one 4 KiB page each.
        let extra: Vec<u32> = uc
            .get_data()
            .periphs
            .iter()
            .map(|m| m.base)
            .filter(|&b| !(0x4000_0000..0x6000_0000).contains(&b))
            .collect();
        for base in extra {
            let page = base & !0xFFF;
            uc.mmio_map(
                page as u64,
                0x1000,
                Some(move |uc: &mut Unicorn<'_, Sim>, off: u64, size: usize| {
                    let r = uc.get_data_mut().bus_read(page + off as u32, size as u8);
                    finish_access(uc, r.map(Some)).unwrap_or(0) as u64
                }),
                Some(
                    move |uc: &mut Unicorn<'_, Sim>, off: u64, size: usize, value: u64| {
                        let r = uc.get_data_mut().bus_write(
                            page + off as u32,
                            size as u8,
                            value as u32,
                        );
                        finish_access(uc, r.map(|_| None));
                    },
                ),
            )
            .map_err(uc_err)?;
        }
        // The System Control Space.
        uc.mmio_map(
            SCS_BASE as u64,
            SCS_SIZE as u64,
            Some(|uc: &mut Unicorn<'_, Sim>, off: u64, _size: usize| {
                let r = uc
                    .get_data()
                    .scs
                    .read(off as u32 & !3)
                    .map_err(|u| describe("SCS", SCS_BASE, u));
                let shift = 8 * (off as u32 & 3);
                finish_access(uc, r.map(|v| Some(v >> shift))).unwrap_or(0) as u64
            }),
            Some(
                |uc: &mut Unicorn<'_, Sim>, off: u64, size: usize, value: u64| {
                    let shift = 8 * (off as u32 & 3);
                    let lane = match size {
                        1 => 0xFFu32,
                        2 => 0xFFFF,
                        _ => !0,
                    };
                    let s = uc.get_data_mut();
                    let r = s
                        .scs
                        .write(off as u32 & !3, (value as u32) << shift, lane << shift)
                        .map_err(|u| describe("SCS", SCS_BASE, u));
                    if std::mem::take(&mut s.scs.changed) {
                        s.replan = true;
                    }
                    finish_access(uc, r.map(|_| None));
                },
            ),
        )
        .map_err(uc_err)?;
        // Debug/trace components the firmware may probe (ITM, DWT, FPB at 0xE000_0000..0xE000_3000;
        // TPIU, ETM, ROM table): none are modelled, any access stops the run.
        uc.mmio_map(
            0xE000_0000,
            0xE000,
            Some(|uc: &mut Unicorn<'_, Sim>, off: u64, _s: usize| {
                let msg = format!(
                    "read of 0x{:08X}: ITM/DWT/FPB are not modelled",
                    0xE000_0000u64 + off
                );
                finish_access(uc, Err(msg)).unwrap_or(0) as u64
            }),
            Some(|uc: &mut Unicorn<'_, Sim>, off: u64, _s: usize, v: u64| {
                let msg = format!(
                    "write of 0x{v:X} to 0x{:08X}: ITM/DWT/FPB are not modelled",
                    0xE000_0000u64 + off
                );
                finish_access(uc, Err(msg));
            }),
        )
        .map_err(uc_err)?;
        // A read, write or fetch that nothing maps: name the address (the run stops).
        uc.add_mem_hook(
            unicorn_engine::unicorn_const::HookType::MEM_UNMAPPED,
            1,
            0,
            |uc: &mut Unicorn<'_, Sim>, kind: unicorn_engine::unicorn_const::MemType, addr: u64, size: usize, value: i64| {
                let r = |reg| uc.reg_read(reg).unwrap_or(0);
                let (pc, lr, sp) = (r(RegisterARM::PC), r(RegisterARM::LR), r(RegisterARM::SP));
                let s = uc.get_data_mut();
                s.stop.get_or_insert(Stop::Fault(format!(
                    "{kind:?} of {size} bytes at unmapped address 0x{addr:08X} (value 0x{value:X}), pc 0x{pc:08X} (block start), lr 0x{lr:08X}, sp 0x{sp:08X}, t = {} µs",
                    micros(s.now)
                )));
                false
            },
        )
        .map_err(uc_err)?;
        // Instruction counting and the slice deadline, per translated block.
        uc.add_block_hook(1, 0, |uc: &mut Unicorn<'_, Sim>, addr: u64, size: u32| {
            let s = uc.get_data_mut();
            let a = addr as u32;
            let (insns, bytes) = match s.block_cache.get(&a) {
                Some(&v) => v,
                None => {
                    let o = a.wrapping_sub(s.chip.flash.0) as usize;
                    let n = if o + size as usize <= s.flash_image.len() {
                        thumb_instructions(&s.flash_image[o..o + size as usize])
                    } else {
                        size / 2
                    };
                    s.block_cache.insert(a, (n, size));
                    (n, size)
                }
            };
            // A stop requested here ends the slice before this block runs (Unicorn checks the
            // request at the block's start), so the block is counted only when it will run. The
            // other hooks only set `replan`/`stop`: an emu_stop from inside a block would leave PC
            // at the block's start with half its effects done.
            if s.now >= s.deadline || s.replan || s.stop.is_some() {
                // Unicorn does not sync PC at a block hook: after this stop, PC would hold the
                // last value an instruction wrote (a branch target earlier on). The run loop sets
                // PC to this block's address (a PC write from inside a hook would restart it).
                s.stopped_at = Some(a);
                let _ = uc.emu_stop();
                return;
            }
            if s.trace_blocks {
                let _ = s;
                let r = |reg| uc.reg_read(reg).unwrap_or(0);
                eprintln!(
                    "block 0x{a:08X} +{size} r0={:X} r1={:X} r2={:X} r4={:X} r5={:X} xpsr={:X}",
                    r(RegisterARM::R0),
                    r(RegisterARM::R1),
                    r(RegisterARM::R2),
                    r(RegisterARM::R4),
                    r(RegisterARM::R5),
                    r(RegisterARM::XPSR)
                );
            }
            let s = uc.get_data_mut();
            let cycles = s.block_cycles(a, insns, bytes);
            s.instructions += insns as u64;
            let ex = s.scs.active_stack.last().copied().unwrap_or(0) as usize;
            if let Some(n) = s.instructions_in.get_mut(ex) {
                *n += insns as u64;
            }
            s.now += cycles * s.ticks_per_cycle;
        })
        .map_err(uc_err)?;
        // SEV sets the event register (Unicorn executes it as a NOP); CPSIE may unmask a pending
        // interrupt, which must be taken now, not at the next peripheral event.
        for a in image.halfwords(0xBF40) {
            uc.add_code_hook(
                a as u64,
                a as u64,
                |uc: &mut Unicorn<'_, Sim>, _a: u64, _s: u32| {
                    uc.get_data_mut().event_register = true;
                },
            )
            .map_err(uc_err)?;
        }
        for a in image.halfwords(0xB662) {
            uc.add_code_hook(
                a as u64,
                a as u64,
                |uc: &mut Unicorn<'_, Sim>, _a: u64, _s: u32| {
                    let s = uc.get_data_mut();
                    if s.scs.any_pending_enabled() {
                        s.replan = true;
                    }
                },
            )
            .map_err(uc_err)?;
        }
        uc.add_intr_hook(|uc: &mut Unicorn<'_, Sim>, intno: u32| {
            // EXCP_EXCEPTION_EXIT (8): a branch to an EXC_RETURN value in handler mode.
            // EXCP_BKPT (7): a debugger would halt.
            match intno {
                8 => {
                    if let Err(e) = exception_return(uc) {
                        uc.get_data_mut().stop = Some(Stop::Fault(e));
                        let _ = uc.emu_stop();
                    }
                }
                7 => {
                    // BKPT: a debugger halts the core (C1.6); without one it is a debug event
                    // that escalates to HardFault (B1.5.14), handled by the run loop.
                    let pc = uc.reg_read(RegisterARM::PC).unwrap_or(0) as u32;
                    let s = uc.get_data_mut();
                    if s.scs.debugger_attached {
                        s.core = CoreState::Halted;
                        s.stop = Some(Stop::Breakpoint { pc });
                    } else {
                        s.bkpt_escalate = true;
                    }
                    // The run ends here: PC precision does not matter, and the CPU would
                    // otherwise re-raise the exception without reaching a block hook.
                    let _ = uc.emu_stop();
                }
                n => {
                    let pc = uc.reg_read(RegisterARM::PC).unwrap_or(0) as u32;
                    uc.get_data_mut().stop =
                        Some(Stop::Fault(format!("CPU exception {n} at pc 0x{pc:08X}")));
                    let _ = uc.emu_stop();
                }
            }
        })
        .map_err(uc_err)?;
        let mut m = Machine { uc, image, stack };
        m.reset_core()?;
        {
            let s = m.uc.get_data_mut();
            s.set_clocks();
            s.art = (s.chip.flash_timing)(&*s.periphs[s.chip.flash_if].p);
            s.update_pins(0);
        }
        Ok(m)
    }

    /// Core reset: SP and PC from the vector table at the start of flash (boot from main flash,
    /// BOOT0 = 0: flash is aliased at 0 and VTOR reads 0; RM0390 §2.4).
    fn reset_core(&mut self) -> Result<(), String> {
        let base = self.uc.get_data().chip.flash.0;
        let sp = self
            .image
            .word(base)
            .ok_or("no vector table at the start of flash")?;
        let pc = self.image.word(base + 4).ok_or("no reset vector")?;
        let uc = &mut self.uc;
        uc.reg_write(RegisterARM::CONTROL, 0).map_err(uc_err)?;
        uc.reg_write(RegisterARM::IPSR, 0).map_err(uc_err)?;
        uc.reg_write(RegisterARM::PRIMASK, 0).map_err(uc_err)?;
        uc.reg_write(RegisterARM::BASEPRI, 0).map_err(uc_err)?;
        uc.reg_write(RegisterARM::FAULTMASK, 0).map_err(uc_err)?;
        uc.reg_write(RegisterARM::MSP, sp as u64).map_err(uc_err)?;
        uc.reg_write(RegisterARM::SP, sp as u64).map_err(uc_err)?;
        uc.reg_write(RegisterARM::LR, 0xFFFF_FFFF).map_err(uc_err)?;
        uc.reg_write(RegisterARM::PC, (pc | 1) as u64)
            .map_err(uc_err)?;
        Ok(())
    }

    /// System reset (IWDG, SYSRESETREQ): peripherals and the SCS to reset values, RAM kept, the
    /// core restarted from the vector table; the RCC learns the cause (reset flags).
    fn system_reset(&mut self, cause: ResetCause) -> Result<(), String> {
        let s = self.uc.get_data_mut();
        let now = s.now;
        s.resets.push((now, cause));
        for m in &mut s.periphs {
            m.p.reset(now);
        }
        crate::board::note_reset(&mut *s.periphs[s.chip.rcc].p, cause);
        s.scs.reset();
        s.stuck_irqs.clear();
        s.core = CoreState::Running;
        s.bkpt_escalate = false;
        s.channel_levels.clear();
        s.event_register = false;
        s.pending_reset = None;
        s.clocks = Clocks::default();
        s.set_clocks();
        s.art = (s.chip.flash_timing)(&*s.periphs[s.chip.flash_if].p);
        s.update_pins(now);
        // The RTT control block is rebuilt by the new boot; read from its start again.
        self.reset_core()
    }

    /// Makes this a part with less flash (a G474RB/RC, an F446RC): FLASHSIZE reads `kib` and
    /// the flash above it is not there (an access faults). Before a run.
    pub fn set_flash_kib(&mut self, kib: u16) -> Result<(), String> {
        let (base, size) = self.uc.get_data().chip.flash;
        let have = kib as u32 * 1024;
        if have == 0 || have > size || !have.is_multiple_of(4096) {
            return Err(format!(
                "flash size {kib} KiB: the model's chip has {} KiB; give a multiple of 4 up to it",
                size / 1024
            ));
        }
        let reg = self.uc.get_data().chip.flash_size_reg;
        self.uc
            .mem_write(reg as u64, &kib.to_le_bytes())
            .map_err(|e| format!("{e:?}"))?;
        if have < size {
            self.uc
                .mem_unmap((base + have) as u64, (size - have) as u64)
                .map_err(|e| format!("{e:?}"))?;
        }
        Ok(())
    }

    /// Marks the flash double word at `addr` as carrying a bad ECC (G474, `flash_prog`), as a
    /// program or erase cut by a power loss leaves it; before the first run only. The first
    /// mark installs the data-read hook that checks it: a machine with a read hook sends every
    /// load down Unicorn's slow path (~40 % of a run), so only runs that need it pay.
    pub fn mark_flash_ecc_bad(&mut self, addr: u32) -> Result<(), String> {
        if self.sim().instructions > 0 {
            return Err("flash ECC marks are set before the first run (translated code would miss the read hook)".into());
        }
        let s = self.uc.get_data_mut();
        let fi = s.chip.flash_if;
        let prog = (s.chip.flash_prog)(&mut *s.periphs[fi].p);
        let hooked = prog.data_cache().is_some() || prog.ecc_bad_in(0, u32::MAX);
        prog.mark_ecc_bad(addr);
        if !hooked && prog.ecc_bad_in(0, u32::MAX) {
            install_flash_read_hooks(&mut self.uc)?;
        }
        Ok(())
    }

    /// Writes `bytes` into flash at `addr` before a run, as a probe would have programmed them.
    pub fn preload_flash(&mut self, addr: u32, bytes: &[u8]) -> Result<(), String> {
        let (base, size) = self.uc.get_data().chip.flash;
        if addr < base || (addr - base) as usize + bytes.len() > size as usize {
            return Err(format!(
                "flash preload at 0x{addr:08X} ({} B) is outside flash",
                bytes.len()
            ));
        }
        self.uc
            .mem_write(addr as u64, bytes)
            .map_err(|e| format!("{e:?}"))
    }

    /// The deepest the main stack has reached since the machine was built (its paint).
    pub fn stack_use(&self) -> Option<crate::stack::Use> {
        let r = self.stack?;
        let mut mem = vec![0u8; r.reserved() as usize];
        self.uc.mem_read(r.bottom as u64, &mut mem).ok()?;
        Some(crate::stack::measure(&r, &mem))
    }

    /// Virtual time now.
    pub fn now(&self) -> Time {
        self.uc.get_data().now
    }

    pub fn sim(&self) -> &Sim {
        self.uc.get_data()
    }

    pub fn sim_mut(&mut self) -> &mut Sim {
        self.uc.get_data_mut()
    }

    /// Runs until virtual time `until`, or until something stops the run (returned).
    pub fn run_until(&mut self, until: Time) -> Option<Stop> {
        self.uc.get_data_mut().run_end = until;
        while self.now() < until {
            if let Some(s) = self.uc.get_data_mut().stop.take() {
                return Some(s);
            }
            if self.uc.get_data().core != CoreState::Running {
                if let Err(e) = self.idle_until(until) {
                    return Some(Stop::Fault(e));
                }
                continue;
            }
            // A fetch from a bank being written or erased waits for the operation, and so does
            // an exception's vector fetch: nothing runs until the flash is free.
            let pc = self.uc.reg_read(RegisterARM::PC).unwrap_or(0) as u32;
            if let Some(t) = self.flash_stall(pc) {
                // The core waits as it does halted or asleep; peripherals run on.
                let before = self.now();
                if let Err(e) = self.idle_until(t.min(until)) {
                    return Some(Stop::Fault(e));
                }
                let s = self.uc.get_data_mut();
                s.flash_stalled_ticks += s.now.saturating_sub(before);
                continue;
            }
            if let Err(e) = self.take_exceptions() {
                return Some(Stop::Fault(e));
            }
            let s = self.uc.get_data_mut();
            s.replan = false;
            let next = s
                .periphs
                .iter()
                .filter_map(|m| m.p.next_event())
                .min()
                .unwrap_or(Time::MAX);
            s.deadline = next.min(until).min(s.now + MAX_SLICE).max(s.now + 1);
            let pc = self.uc.reg_read(RegisterARM::PC).unwrap_or(0);
            if std::env::var("BOARD_MODEL_TRACE").is_ok_and(|v| v == "slices") {
                let s = self.uc.get_data();
                let evs: Vec<String> = s
                    .periphs
                    .iter()
                    .filter_map(|m| m.p.next_event().map(|t| format!("{}@{}", m.p.name(), t)))
                    .collect();
                eprintln!(
                    "slice pc=0x{pc:08X} now={} deadline={} next={:?}",
                    s.now, s.deadline, evs
                );
            }
            self.uc.get_data_mut().stopped_at = None;
            let r = self.uc.emu_start(pc | 1, 0, 0, 0);
            if let Some(a) = self.uc.get_data_mut().stopped_at.take() {
                if r.is_ok() {
                    let _ = self.uc.reg_write(RegisterARM::PC, (a | 1) as u64);
                }
            }
            if let Err(e) = r {
                if let Some(stop) = self.on_cpu_error(e) {
                    return Some(stop);
                }
            }
            if std::mem::take(&mut self.uc.get_data_mut().bkpt_escalate) {
                let pc = self.uc.reg_read(RegisterARM::PC).unwrap_or(0) as u32;
                // HFSR.DEBUGEVT: a debug event escalated to HardFault.
                self.uc.get_data_mut().scs.hfsr |= 1 << 31;
                if let Err(e) = self.fault(exc::HARD_FAULT, pc, 0) {
                    return Some(Stop::Fault(e));
                }
            }
            self.copy_dma();
            let s = self.uc.get_data_mut();
            let now = s.now;
            s.advance_periphs(now);
            self.copy_dma();
            self.drain_rtt();
            // A behaviour a model found but cannot represent (e.g. an ADC DMA mode) ends the run.
            if let Some(f) = self
                .uc
                .get_data()
                .periphs
                .iter()
                .find_map(|m| crate::board::model_fault(&*m.p))
            {
                return Some(Stop::Fault(f));
            }
            if let Some(cause) = self.uc.get_data_mut().pending_reset.take() {
                if let Err(e) = self.system_reset(cause) {
                    return Some(Stop::Fault(e));
                }
            }
            if self.uc.get_data().scs.reset_requested {
                if let Err(e) = self.system_reset(ResetCause::Software) {
                    return Some(Stop::Fault(e));
                }
            }
        }
        self.uc.get_data_mut().stop.take()
    }

    /// Unicorn stopped on an error: WFE/WFI (which it reports as invalid instructions), UDF
    /// (a permanently undefined instruction: UsageFault, escalated to HardFault since the
    /// firmware does not enable UsageFault; ARMv7-M B1.5.14), or a real fault.
    fn on_cpu_error(&mut self, e: uc_error) -> Option<Stop> {
        if let Some(s) = self.uc.get_data_mut().stop.take() {
            return Some(s);
        }
        let pc = self.uc.reg_read(RegisterARM::PC).unwrap_or(0) as u32;
        let half = |uc: &Unicorn<'_, Sim>, a: u32| -> u16 {
            let mut b = [0u8; 2];
            uc.mem_read(a as u64, &mut b)
                .map(|_| u16::from_le_bytes(b))
                .unwrap_or(0)
        };
        if e == uc_error::INSN_INVALID {
            // Unicorn leaves PC after WFE/WFI.
            let prev = half(&self.uc, pc.wrapping_sub(2));
            if prev == 0xBF20 || prev == 0xBF30 {
                let wfi = prev == 0xBF30;
                // The sleep itself costs its instruction.
                let s = self.uc.get_data_mut();
                s.instructions += 1;
                s.now += s.ticks_per_cycle;
                return self.sleep(wfi).err().map(Stop::Fault);
            }
            let at = half(&self.uc, pc);
            if at & 0xFF00 == 0xDE00 {
                return self
                    .fault(exc::HARD_FAULT, pc, 1 << 16)
                    .err()
                    .map(Stop::Fault);
            }
        }
        Some(Stop::Fault(format!(
            "emulation stopped at pc 0x{pc:08X}: {e:?}"
        )))
    }

    /// Takes a fault: HardFault entry with the status registers set, or lockup when already in
    /// HardFault.
    fn fault(&mut self, e: u16, pc: u32, cfsr: u32) -> Result<(), String> {
        let s = self.uc.get_data_mut();
        s.scs.cfsr |= cfsr;
        s.scs.hfsr |= 1 << 30; // FORCED: escalated to HardFault
        if s.scs.active_stack.contains(&exc::HARD_FAULT) || s.scs.active_stack.contains(&exc::NMI) {
            // Lockup (ARMv7-M B1.5.15): the core stops executing; only a reset (the IWDG)
            // brings it back. Peripherals run on.
            s.core = CoreState::Locked;
            s.lockups.push((s.now, pc));
            return Ok(());
        }
        let _ = e;
        s.scs.set_pending(exc::HARD_FAULT);
        self.enter(exc::HARD_FAULT)
    }

    /// The core is halted or locked up: no instruction runs, peripherals go on until `until` or
    /// a reset. Under a debug halt the IWDG stops only if DBGMCU's DBG_IWDG_STOP is set
    /// (RM0390 §33.16.4; RM0440 §46.16.4).
    fn idle_until(&mut self, until: Time) -> Result<(), String> {
        let s = self.uc.get_data_mut();
        let halted = s.core == CoreState::Halted;
        let now = s.now;
        crate::board::debug_halt(&mut s.periphs, now, halted);
        let next = s.periphs.iter().filter_map(|m| m.p.next_event()).min();
        let t = next.unwrap_or(until).min(until).max(s.now);
        s.now = t;
        s.advance_periphs(t);
        self.copy_dma();
        self.drain_rtt();
        if let Some(cause) = self.uc.get_data_mut().pending_reset.take() {
            self.system_reset(cause)?;
        }
        Ok(())
    }

    /// WFE/WFI: sleep until something would wake the core (ARMv7-M B1.5.18/19).
    fn sleep(&mut self, wfi: bool) -> Result<(), String> {
        if !wfi && std::mem::take(&mut self.uc.get_data_mut().event_register) {
            return Ok(());
        }
        loop {
            if self.takeable()?.is_some() {
                return Ok(());
            }
            let s = self.uc.get_data_mut();
            if wfi && s.scs.any_pending_enabled() {
                return Ok(());
            }
            if let Some(stop) = &s.stop {
                return Err(format!("{stop:?}"));
            }
            let next = s.periphs.iter().filter_map(|m| m.p.next_event()).min();
            // Never sleep past the end of this run: the caller may change something then
            // (record a pin, inject a fault). The core wakes there as from a spurious event
            // (ARMv7-M B1.5.18 allows WFE to return at any time) and sleeps again.
            let limit = s.run_end;
            let t = next.unwrap_or(limit).min(limit).max(s.now);
            s.sleeping_ticks += t - s.now;
            s.now = t;
            s.advance_periphs(t);
            self.copy_dma();
            self.drain_rtt();
            let s = self.uc.get_data_mut();
            if next.is_none_or(|n| n > limit) {
                return Ok(());
            }
            if s.pending_reset.is_some() || s.scs.reset_requested {
                return Ok(());
            }
            if !wfi && s.scs.sevonpend() && s.scs.any_pending_enabled() {
                return Ok(());
            }
        }
    }

    fn takeable(&mut self) -> Result<Option<u16>, String> {
        self.uc.get_data_mut().sample_irq_lines();
        let uc = &self.uc;
        let primask = uc.reg_read(RegisterARM::PRIMASK).map_err(uc_err)? & 1 != 0;
        let basepri = uc.reg_read(RegisterARM::BASEPRI).map_err(uc_err)? as u8;
        let faultmask = uc.reg_read(RegisterARM::FAULTMASK).map_err(uc_err)? & 1 != 0;
        let s = uc.get_data();
        Ok(s.scs
            .next_to_take(s.scs.execution_priority(primask, basepri, faultmask)))
    }

    /// Takes every exception that can preempt now (nested ones stack on top).
    fn take_exceptions(&mut self) -> Result<(), String> {
        while let Some(e) = self.takeable()? {
            self.enter(e)?;
        }
        Ok(())
    }

    /// Exception entry (ARMv7-M B1.5.6 PushStack / ExceptionTaken): stack the basic or, with
    /// CONTROL.FPCA, the extended frame (the lazy-stacking reservation filled eagerly), realign
    /// to 8 bytes (CCR.STKALIGN), EXC_RETURN in LR, handler mode on the main stack.
    fn enter(&mut self, e: u16) -> Result<(), String> {
        let uc = &mut self.uc;
        let r = |uc: &Unicorn<'_, Sim>, reg| uc.reg_read(reg).map(|v| v as u32).map_err(uc_err);
        let xpsr = r(uc, RegisterARM::XPSR)?;
        let control = r(uc, RegisterARM::CONTROL)?;
        let handler = xpsr & 0x1FF != 0;
        let psp = !handler && control & 2 != 0;
        let fpca = control & 4 != 0;
        let sp = r(uc, RegisterARM::SP)?;
        let frame_size = if fpca { 0x68 } else { 0x20 };
        let align = sp & 4 != 0;
        let frame = (sp - frame_size) & !4;
        let pc = r(uc, RegisterARM::PC)? & !1;
        let mut words = vec![
            r(uc, RegisterARM::R0)?,
            r(uc, RegisterARM::R1)?,
            r(uc, RegisterARM::R2)?,
            r(uc, RegisterARM::R3)?,
            r(uc, RegisterARM::R12)?,
            r(uc, RegisterARM::LR)?,
            pc,
            (xpsr & !(1 << 9)) | (align as u32) << 9 | 1 << 24,
        ];
        if fpca {
            for i in 0..16 {
                words.push(r(uc, s_reg(i))?);
            }
            words.push(r(uc, RegisterARM::FPSCR)?);
            words.push(0);
        }
        let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
        uc.mem_write(frame as u64, &bytes).map_err(|err| {
            format!("exception {e}: stacking at 0x{frame:08X} failed ({err:?}): stack overflow?")
        })?;
        let exc_return = 0xFFFF_FFE1u32
            | if handler { 0 } else { 8 }
            | if psp { 4 } else { 0 }
            | if fpca { 0 } else { 0x10 };
        uc.reg_write(RegisterARM::SP, frame as u64)
            .map_err(uc_err)?;
        // Leave thread mode's stack selection while still in thread mode (an MSR CONTROL in
        // handler mode ignores SPSEL), then enter handler mode.
        if !handler {
            uc.reg_write(RegisterARM::CONTROL, (control & !6) as u64)
                .map_err(uc_err)?;
        } else {
            uc.reg_write(RegisterARM::CONTROL, (control & !4) as u64)
                .map_err(uc_err)?;
        }
        let s = uc.get_data();
        let vtor = s.scs.vtor();
        let table = if vtor == 0 { s.chip.flash.0 } else { vtor };
        let mut v = [0u8; 4];
        uc.mem_read((table + 4 * e as u32) as u64, &mut v)
            .map_err(uc_err)?;
        let vector = u32::from_le_bytes(v);
        // ExceptionTaken (ARMv7-M ARM B1.5.6): IPSR = the exception, EPSR.T = 1 and
        // EPSR.IT = 0. Unicorn keeps its If-Then state in the XPSR it exposes: an interrupt
        // taken inside an IT block (its stacked xPSR holds the IT bits, restored on return)
        // otherwise starts the handler under the interrupted code's conditions, and its
        // first instructions (a push of the return state) run or skip by stale flags.
        // The whole xPSR, IPSR included (`writing_the_xpsr_sets_the_ipsr`).
        uc.reg_write(RegisterARM::XPSR, entry_xpsr(xpsr, e) as u64)
            .map_err(uc_err)?;
        uc.reg_write(RegisterARM::LR, exc_return as u64)
            .map_err(uc_err)?;
        uc.reg_write(RegisterARM::PC, (vector | 1) as u64)
            .map_err(uc_err)?;
        let s = uc.get_data_mut();
        s.scs.activate(e);
        s.exceptions_taken += 1;
        s.now += EXCEPTION_CYCLES * s.ticks_per_cycle;
        Ok(())
    }

    /// Until when a fetch from `pc` waits for the flash.
    fn flash_stall(&mut self, pc: u32) -> Option<Time> {
        let s = self.uc.get_data_mut();
        let (now, fi) = (s.now, s.chip.flash_if);
        (s.chip.flash_prog)(&mut *s.periphs[fi].p).stall_until(now, pc)
    }

    /// Programmed cells written again (see `flash_fixups`), erased ranges filled with 0xFF.
    fn apply_flash(&mut self) {
        let s = self.uc.get_data_mut();
        let fixups = std::mem::take(&mut s.flash_fixups);
        let fi = s.chip.flash_if;
        let erases = (s.chip.flash_prog)(&mut *s.periphs[fi].p).take_erases();
        for (addr, bytes) in fixups {
            let _ = self.uc.mem_write(addr as u64, &bytes);
        }
        for (addr, len) in erases {
            let _ = self.uc.mem_write(addr as u64, &vec![0xFF; len as usize]);
        }
    }

    /// Carries out DMA transfers that touch RAM (and, first, what the flash interface did).
    fn copy_dma(&mut self) {
        self.apply_flash();
        loop {
            let copies = std::mem::take(&mut self.uc.get_data_mut().ram_copies);
            if copies.is_empty() {
                return;
            }
            for c in copies {
                let (to, size, value) = match c {
                    RamCopy::Write { to, size, value } => (to, size, value),
                    RamCopy::Copy(c) => match self.read_any(c.from, c.size) {
                        Ok(v) => (c.to, c.size, v),
                        Err(e) => {
                            self.uc.get_data_mut().stop =
                                Some(Stop::Fault(format!("DMA read: {e}")));
                            return;
                        }
                    },
                };
                if std::env::var("BOARD_MODEL_TRACE").is_ok_and(|v| v == "slices") {
                    eprintln!("dma write 0x{to:08X} <- 0x{value:X} ({size} B)");
                }
                if let Err(e) = self.write_any(to, size, value) {
                    self.uc.get_data_mut().stop = Some(Stop::Fault(format!("DMA write: {e}")));
                    return;
                }
            }
            self.uc.get_data_mut().settle_local();
        }
    }

    pub(crate) fn is_periph(addr: u32) -> bool {
        (0x4000_0000..0x6000_0000).contains(&addr) || (0xE004_0000..0xE010_0000).contains(&addr)
    }

    fn read_any(&mut self, addr: u32, size: u8) -> Result<u32, String> {
        if Self::is_periph(addr) {
            return self.uc.get_data_mut().bus_read(addr, size);
        }
        let mut b = [0u8; 4];
        self.uc
            .mem_read(addr as u64, &mut b[..size as usize])
            .map_err(|e| format!("0x{addr:08X}: {e:?}"))?;
        Ok(u32::from_le_bytes(b))
    }

    fn write_any(&mut self, addr: u32, size: u8, v: u32) -> Result<(), String> {
        if Self::is_periph(addr) {
            return self.uc.get_data_mut().bus_write(addr, size, v);
        }
        self.uc
            .mem_write(addr as u64, &v.to_le_bytes()[..size as usize])
            .map_err(|e| format!("0x{addr:08X}: {e:?}"))
    }

    /// Reads what the firmware wrote to RTT up-channel 0 since the last call, as a probe does:
    /// the control block's first up-buffer descriptor (name, buffer, size, write, read, flags) is
    /// at +24 (SEGGER RTT layout, as defmt-rtt defines it); the read offset is advanced.
    pub fn drain_rtt(&mut self) {
        let Some(cb) = self.uc.get_data().rtt else {
            return;
        };
        if self.uc.get_data().rtt_host_stalled {
            return;
        }
        let mut d = [0u8; 24];
        if self.uc.mem_read(cb as u64 + 24, &mut d).is_err() {
            return;
        }
        let w = |i: usize| u32::from_le_bytes(d[i..i + 4].try_into().unwrap());
        if self.uc.get_data().rtt_host_blocking && w(4) != 0 {
            // probe-rs's RTT attach: flags' mode bits (1:0) = 2, block if full.
            let flags = (w(20) & !3) | 2;
            let _ = self.uc.mem_write(cb as u64 + 24 + 20, &flags.to_le_bytes());
        }
        let (buf, size, write, read) = (w(4), w(8), w(12), w(16));
        if buf == 0 || size == 0 || write >= size || read >= size || write == read {
            return;
        }
        let mut out = Vec::new();
        let mut r = read;
        while r != write {
            let end = if write > r { write } else { size };
            let mut chunk = vec![0u8; (end - r) as usize];
            if self.uc.mem_read((buf + r) as u64, &mut chunk).is_err() {
                return;
            }
            out.extend_from_slice(&chunk);
            r = if end == size { 0 } else { end };
        }
        let _ = self.uc.mem_write(cb as u64 + 24 + 16, &write.to_le_bytes());
        let s = self.uc.get_data_mut();
        s.log_times.push((s.now, s.log.len()));
        s.log.extend_from_slice(&out);
    }

    /// The RTT host stops reading for good, leaving the up buffer full: its read offset one past
    /// the write offset, as if it had read nothing of the last buffer's worth. That is where a
    /// stalled host ends up once the firmware has logged a buffer's worth (1 KiB: ~10 s of this
    /// firmware's log at the default scene's rate), fast-forwarded: the next log write finds no
    /// room at once.
    pub fn stall_rtt_host_full(&mut self) {
        self.drain_rtt();
        self.uc.get_data_mut().rtt_host_stalled = true;
        let Some(cb) = self.uc.get_data().rtt else {
            return;
        };
        let mut d = [0u8; 12];
        if self.uc.mem_read(cb as u64 + 24 + 8, &mut d).is_err() {
            return;
        }
        let w = |i: usize| u32::from_le_bytes(d[i..i + 4].try_into().unwrap());
        let (size, write) = (w(0), w(4));
        if size == 0 {
            return;
        }
        let read = (write + 1) % size;
        let _ = self.uc.mem_write(cb as u64 + 24 + 16, &read.to_le_bytes());
    }

    /// The core executes nothing for `ticks` while the peripherals run on, then takes whatever
    /// became pending: an interrupt held off that long, as by a critical section (defmt-rtt
    /// holds PRIMASK while it encodes a line) or a slower core than the model's one cycle an
    /// instruction. Thread code is delayed as much, which a real critical section's own code
    /// would be too.
    pub fn hold_core(&mut self, ticks: Time) -> Option<Stop> {
        let until = self.now() + ticks;
        while self.now() < until {
            if let Err(e) = self.idle_until(until) {
                return Some(Stop::Fault(e));
            }
        }
        None
    }

    /// Runs in short steps until the core is in thread mode (IPSR = 0), then sets PC to `addr`.
    pub fn divert_in_thread_mode(&mut self, addr: u32) -> Option<Stop> {
        for _ in 0..10_000 {
            let ipsr = self.uc.reg_read(RegisterARM::IPSR).unwrap_or(1) & 0x1FF;
            if ipsr == 0 {
                let _ = self.uc.reg_write(RegisterARM::PC, (addr | 1) as u64);
                return None;
            }
            let t = self.now() + TICKS_PER_S / 10_000_000;
            if let Some(s) = self.run_until(t) {
                return Some(s);
            }
        }
        Some(Stop::Fault("the core never returned to thread mode".into()))
    }

    /// Microseconds of virtual time now.
    pub fn now_us(&self) -> u64 {
        micros(self.now())
    }
}

/// Bytes in the RTT up-buffer not yet read (write − read offsets, modulo its size).
/// xPSR's APSR part kept across exception entry: N, Z, C, V, Q (bits 31–27) and GE (19–16).
const XPSR_APSR_BITS: u32 = 0xF80F_0000;
/// xPSR's EPSR.T bit (Thumb state, always 1 on an M-profile core).
const XPSR_T: u32 = 1 << 24;
/// xPSR's EPSR.IT bits (If-Then state: 26–25 and 15–10).
#[cfg(test)]
const XPSR_IT_BITS: u32 = 0x0600_FC00;

/// The xPSR a handler for exception `e` starts with, from the interrupted code's: its APSR
/// flags, Thumb state, no If-Then state, IPSR = `e` (ExceptionTaken, ARMv7-M ARM B1.5.6).
fn entry_xpsr(xpsr: u32, e: u16) -> u32 {
    (xpsr & XPSR_APSR_BITS) | XPSR_T | (e as u32 & 0x1FF)
}

fn rtt_pending(uc: &Unicorn<'_, Sim>) -> usize {
    let Some(cb) = uc.get_data().rtt else {
        return 0;
    };
    let mut d = [0u8; 12];
    if uc.mem_read(cb as u64 + 24 + 8, &mut d).is_err() {
        return 0;
    }
    let w = |i: usize| u32::from_le_bytes(d[i..i + 4].try_into().unwrap()) as usize;
    let (size, write, read) = (w(0), w(4), w(8));
    if size == 0 || write >= size || read >= size {
        return 0;
    }
    (write + size - read) % size
}

fn s_reg(i: u32) -> RegisterARM {
    use RegisterARM::*;
    [
        S0, S1, S2, S3, S4, S5, S6, S7, S8, S9, S10, S11, S12, S13, S14, S15,
    ][i as usize]
}

/// After a bus access from a hook: a failed access stops the run with its sentence; a schedule
/// change stops the slice so the board re-plans.
fn finish_access(uc: &mut Unicorn<'_, Sim>, r: Result<Option<u32>, String>) -> Option<u32> {
    match r {
        Ok(v) => v,
        Err(msg) => {
            let pc = uc.reg_read(RegisterARM::PC).unwrap_or(0);
            let s = uc.get_data_mut();
            if s.stop.is_none() {
                s.stop = Some(Stop::Fault(format!(
                    "{msg} (pc 0x{pc:08X}, t = {} µs)",
                    micros(s.now)
                )));
            }
            None
        }
    }
}

/// Exception return (ARMv7-M B1.5.8 ExceptionReturn / PopStack), from the EXC_RETURN value the
/// handler branched to.
fn exception_return(uc: &mut Unicorn<'_, Sim>) -> Result<(), String> {
    let pc = uc.reg_read(RegisterARM::PC).map_err(uc_err)? as u32;
    // PC holds the EXC_RETURN value with bit 0 cleared (an interworking branch target).
    let exc_return = if pc >= 0xFFFF_FF00 {
        pc | 1
    } else {
        uc.reg_read(RegisterARM::LR).map_err(uc_err)? as u32
    };
    if exc_return & 0xFFFF_FFE1 != 0xFFFF_FFE1 {
        return Err(format!(
            "exception return with invalid EXC_RETURN 0x{exc_return:08X}"
        ));
    }
    let to_thread = exc_return & 8 != 0;
    let psp = exc_return & 4 != 0;
    let fp = exc_return & 0x10 == 0;
    {
        let s = uc.get_data_mut();
        s.scs.deactivate();
        s.event_register = true;
        s.now += EXCEPTION_CYCLES * s.ticks_per_cycle;
    }
    // The frame is on the stack EXC_RETURN names; in handler mode SP is MSP.
    let frame = if psp {
        uc.reg_read(RegisterARM::PSP).map_err(uc_err)? as u32
    } else {
        uc.reg_read(RegisterARM::SP).map_err(uc_err)? as u32
    };
    let n = if fp { 26 } else { 8 };
    let mut b = vec![0u8; 4 * n];
    uc.mem_read(frame as u64, &mut b)
        .map_err(|e| format!("unstacking at 0x{frame:08X}: {e:?}"))?;
    let w = |i: usize| u32::from_le_bytes(b[4 * i..4 * i + 4].try_into().unwrap());
    let xpsr = w(7);
    let sp_after = frame + 4 * n as u32 + if xpsr & (1 << 9) != 0 { 4 } else { 0 };
    for (i, reg) in [
        RegisterARM::R0,
        RegisterARM::R1,
        RegisterARM::R2,
        RegisterARM::R3,
        RegisterARM::R12,
        RegisterARM::LR,
    ]
    .into_iter()
    .enumerate()
    {
        uc.reg_write(reg, w(i) as u64).map_err(uc_err)?;
    }
    if fp {
        for i in 0..16 {
            uc.reg_write(s_reg(i), w(8 + i as usize) as u64)
                .map_err(uc_err)?;
        }
        uc.reg_write(RegisterARM::FPSCR, w(24) as u64)
            .map_err(uc_err)?;
    }
    // Back to the interrupted mode first (IPSR from the frame: the xPSR write sets it,
    // `writing_the_xpsr_sets_the_ipsr`), then its stack selection.
    uc.reg_write(RegisterARM::XPSR, (xpsr & !(1 << 9)) as u64)
        .map_err(uc_err)?;
    if !to_thread && xpsr & 0x1FF == 0 {
        return Err(format!(
            "EXC_RETURN 0x{exc_return:08X} returns to handler mode but the frame holds thread mode"
        ));
    }
    let control = uc.reg_read(RegisterARM::CONTROL).map_err(uc_err)? as u32;
    let control = (control & !6) | if to_thread && psp { 2 } else { 0 } | if fp { 4 } else { 0 };
    if psp {
        uc.reg_write(RegisterARM::PSP, sp_after as u64)
            .map_err(uc_err)?;
        uc.reg_write(RegisterARM::CONTROL, control as u64)
            .map_err(uc_err)?;
    } else {
        uc.reg_write(RegisterARM::CONTROL, control as u64)
            .map_err(uc_err)?;
        uc.reg_write(RegisterARM::SP, sp_after as u64)
            .map_err(uc_err)?;
    }
    uc.reg_write(RegisterARM::PC, (w(6) | 1) as u64)
        .map_err(uc_err)?;
    // Tail-chaining: whatever can be taken now is taken before returning to the interrupted code.
    let primask = uc.reg_read(RegisterARM::PRIMASK).map_err(uc_err)? & 1 != 0;
    let basepri = uc.reg_read(RegisterARM::BASEPRI).map_err(uc_err)? as u8;
    uc.get_data_mut().sample_irq_lines();
    let s = uc.get_data();
    if s.scs
        .next_to_take(s.scs.execution_priority(primask, basepri, false))
        .is_some()
    {
        uc.get_data_mut().replan = true;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A handler entered inside an If-Then block runs unconditionally: Unicorn keeps the IT
    /// state in the XPSR it exposes, and writing the entry xPSR clears it. Runs `cmp r0, r0;
    /// ite eq` (Z set: the block's first instruction runs, its second not), stops inside the
    /// block, "enters" as `Machine::enter` does and runs the block's two moves: both write.
    /// Left as it was (IPSR written alone, as the model did before), the second is skipped.
    /// That is how the stream-cost run crashed on a G474 image (stop 28): a DMA interrupt
    /// taken between `it lo` and `blo.w` in `__aeabi_memcpy8` started its handler under the
    /// stale condition, and the handler returned to a data address.
    #[test]
    fn a_handler_entered_in_an_it_block_runs_unconditionally() {
        // cmp r0, r0; ite eq; moveq r1, #1; movne r2, #2 (llvm-mc, thumbv7em).
        const CODE: [u8; 8] = [0x80, 0x42, 0x0c, 0xbf, 0x01, 0x21, 0x02, 0x22];
        const BASE: u64 = 0x0800_0000;
        let run = |clear_it: bool| -> (u32, u32, u32) {
            let mut uc = Unicorn::new(Arch::ARM, Mode::THUMB | Mode::MCLASS).unwrap();
            uc.ctl_set_cpu_model(unicorn_engine::ArmCpuModel::CORTEX_M4 as i32)
                .unwrap();
            uc.mem_map(BASE, 0x1000, Prot::ALL).unwrap();
            uc.mem_write(BASE, &CODE).unwrap();
            // The compare and the IT, stopped inside the block before its first move (as the
            // model stops at a block's start for an interrupt).
            uc.emu_start(BASE | 1, BASE + 4, 0, 0).unwrap();
            let xpsr = uc.reg_read(RegisterARM::XPSR).unwrap() as u32;
            if clear_it {
                uc.reg_write(RegisterARM::XPSR, entry_xpsr(xpsr, 27) as u64)
                    .unwrap();
            } else {
                uc.reg_write(RegisterARM::IPSR, 27).unwrap();
            }
            let pc = uc.reg_read(RegisterARM::PC).unwrap();
            uc.emu_start(pc | 1, BASE + 8, 0, 2).unwrap();
            let r = |reg| uc.reg_read(reg).unwrap() as u32;
            (xpsr, r(RegisterARM::R1), r(RegisterARM::R2))
        };
        let (xpsr, r1, r2) = run(true);
        assert_ne!(
            xpsr & XPSR_IT_BITS,
            0,
            "stopped inside the IT block: {xpsr:08X}"
        );
        assert_eq!((r1, r2), (1, 2), "both moves run in the handler");
        // The defect the entry xPSR fixes: the IT state carried into the handler.
        let (_, r1, r2) = run(false);
        assert_eq!((r1, r2), (1, 0), "with the IT state kept, movne is skipped");
    }

    /// Unicorn's xPSR write carries the exception number too (its `xpsr_write` under the full
    /// mask), so exception entry and return set IPSR with the one write. Both directions, and
    /// a value the old IPSR did not hold.
    #[test]
    fn writing_the_xpsr_sets_the_ipsr() {
        let mut uc = Unicorn::new(Arch::ARM, Mode::THUMB | Mode::MCLASS).unwrap();
        uc.ctl_set_cpu_model(unicorn_engine::ArmCpuModel::CORTEX_M4 as i32)
            .unwrap();
        let ipsr = |uc: &Unicorn<'_, ()>| uc.reg_read(RegisterARM::IPSR).unwrap() as u32 & 0x1FF;
        assert_eq!(ipsr(&uc), 0);
        for e in [27u16, 68, 15] {
            uc.reg_write(RegisterARM::XPSR, entry_xpsr(XPSR_T, e) as u64)
                .unwrap();
            assert_eq!(ipsr(&uc), e as u32, "entry to exception {e}");
        }
        // A return to thread mode: a frame's xPSR with IPSR 0.
        uc.reg_write(RegisterARM::XPSR, XPSR_T as u64).unwrap();
        assert_eq!(ipsr(&uc), 0, "return to thread mode");
    }

    #[test]
    fn the_entry_xpsr_keeps_the_flags_and_nothing_of_the_it_state() {
        // N Z C V Q set, GE 0b1010, IT bits all set, an old IPSR 0x1B.
        let x = 0xF80A_0000 | XPSR_IT_BITS | XPSR_T | 0x1B;
        assert_eq!(entry_xpsr(x, 52 + 16), 0xF80A_0000 | XPSR_T | 68);
    }
}
