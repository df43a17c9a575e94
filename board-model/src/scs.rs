//! The Cortex-M4 System Control Space: NVIC, SCB, SysTick, FPU control and the debug halting
//! register, and the exception state they hold (pending, active, priorities).
//!
//! Unicorn runs the instructions but has no NVIC: exception entry and return are done by
//! `crate::machine` from the state kept here. References: ARMv7-M Architecture Reference Manual
//! (ARM DDI 0403E) §B1.5 (exception model), §B3.2 (SCS), §B3.3 (SysTick), §B3.4 (NVIC); the
//! Cortex-M4 Devices Generic User Guide (ARM DUI 0553) §4; PM0214 (STM32 Cortex-M4 programming
//! manual) §4: STM32 implements 4 priority bits (the upper nibble of each 8-bit field).

use crate::periph::Unmodelled;

/// Exception numbers (ARMv7-M B1.5.2).
pub mod exc {
    pub const NMI: u16 = 2;
    pub const HARD_FAULT: u16 = 3;
    pub const MEM_MANAGE: u16 = 4;
    pub const BUS_FAULT: u16 = 5;
    pub const USAGE_FAULT: u16 = 6;
    pub const SVCALL: u16 = 11;
    pub const DEBUG_MON: u16 = 12;
    pub const PENDSV: u16 = 14;
    pub const SYSTICK: u16 = 15;
    /// First external interrupt: IRQ n is exception 16 + n.
    pub const IRQ0: u16 = 16;
}

/// Exceptions the model tracks: 16 system + up to 112 external IRQs (F446: 97, G474: 102).
pub const MAX_EXC: usize = 128;

/// SCS base address.
pub const SCS_BASE: u32 = 0xE000_E000;
/// Size of the SCS region (0xE000_E000..0xE000_F000).
pub const SCS_SIZE: u32 = 0x1000;

/// NVIC, SCB, SysTick, FPU and debug registers with the exception state.
#[derive(Clone, Debug)]
pub struct Scs {
    /// Number of external interrupts this chip implements.
    pub irqs: u16,
    enabled: [bool; MAX_EXC],
    pending: [bool; MAX_EXC],
    active: [bool; MAX_EXC],
    /// 8-bit priority fields (only the upper 4 bits are implemented).
    priority: [u8; MAX_EXC],
    /// Active exceptions, innermost last (for RETTOBASE and nesting checks).
    pub active_stack: Vec<u16>,
    vtor: u32,
    aircr_prigroup: u32,
    scr: u32,
    ccr: u32,
    shcsr: u32,
    cpacr: u32,
    fpccr: u32,
    fpcar: u32,
    fpdscr: u32,
    /// Sticky fault status (CFSR, HFSR), set by the machine on a modelled fault.
    pub cfsr: u32,
    pub hfsr: u32,
    /// DHCSR.C_DEBUGEN: a debugger is attached (the machine's option; firmware reads it).
    pub debugger_attached: bool,
    /// DEMCR (TRCENA etc.) as written.
    demcr: u32,
    /// AIRCR.SYSRESETREQ was written with the key.
    pub reset_requested: bool,
    /// A write that can change what is taken next (enable, pend, priority, PRIGROUP).
    pub changed: bool,
}

fn lane_merge(old: u32, value: u32, mask: u32) -> u32 {
    (old & !mask) | (value & mask)
}

impl Scs {
    /// Reset state (ARMv7-M B1.5.5 / B3.2): nothing enabled or pending, all priorities 0,
    /// VTOR 0, CCR.STKALIGN = 1, FPCCR.ASPEN = LSPEN = 1, CPACR = 0 (FPU off).
    pub fn new(irqs: u16) -> Self {
        assert!((irqs as usize) + 16 <= MAX_EXC);
        let mut s = Self {
            irqs,
            enabled: [false; MAX_EXC],
            pending: [false; MAX_EXC],
            active: [false; MAX_EXC],
            priority: [0; MAX_EXC],
            active_stack: Vec::new(),
            vtor: 0,
            aircr_prigroup: 0,
            scr: 0,
            ccr: 0x200,
            shcsr: 0,
            cpacr: 0,
            fpccr: 0xC000_0000,
            fpcar: 0,
            fpdscr: 0,
            cfsr: 0,
            hfsr: 0,
            debugger_attached: false,
            demcr: 0,
            reset_requested: false,
            changed: false,
        };
        // Fixed, always-enabled exceptions.
        for e in [
            exc::NMI,
            exc::HARD_FAULT,
            exc::SVCALL,
            exc::PENDSV,
            exc::SYSTICK,
        ] {
            s.enabled[e as usize] = true;
        }
        s
    }

    /// Back to reset state, keeping the chip's IRQ count and the debugger option.
    pub fn reset(&mut self) {
        let dbg = self.debugger_attached;
        *self = Self::new(self.irqs);
        self.debugger_attached = dbg;
    }

    /// VTOR (vector table base).
    pub fn vtor(&self) -> u32 {
        self.vtor
    }

    /// The exception's priority as a signed value: NMI −2, HardFault −1, configurable ones their
    /// 8-bit field (lower is more urgent).
    pub fn priority_of(&self, e: u16) -> i32 {
        match e {
            exc::NMI => -2,
            exc::HARD_FAULT => -1,
            _ => self.priority[e as usize] as i32,
        }
    }

    /// Group priority (AIRCR.PRIGROUP splits group and sub-priority; B1.5.4): only the group
    /// decides preemption.
    fn group(&self, prio: i32) -> i32 {
        if prio < 0 {
            return prio;
        }
        let sub_bits = self.aircr_prigroup + 1; // PRIGROUP n: bits [n:0] are sub-priority
        (prio >> sub_bits) << sub_bits
    }

    /// Execution priority (B1.5.4): the most urgent of the active exceptions' group priorities
    /// and the masks; 256 in thread mode with nothing active or masked.
    pub fn execution_priority(&self, primask: bool, basepri: u8, faultmask: bool) -> i32 {
        let mut p = 256;
        for &e in &self.active_stack {
            p = p.min(self.group(self.priority_of(e)));
        }
        if basepri != 0 {
            p = p.min(self.group((basepri & 0xF0) as i32));
        }
        if primask {
            p = p.min(0);
        }
        if faultmask {
            p = p.min(-1);
        }
        p
    }

    /// The pending, enabled exception that would be taken at `exec_priority`, if any: most
    /// urgent priority first, lowest number on a tie (B1.5.4).
    pub fn next_to_take(&self, exec_priority: i32) -> Option<u16> {
        let mut best: Option<(i32, u16)> = None;
        for e in 2..(16 + self.irqs as usize) {
            if !(self.pending[e] && self.enabled[e]) || self.active[e] {
                continue;
            }
            let p = self.priority_of(e as u16);
            if self.group(p) >= exec_priority {
                continue;
            }
            if best.is_none_or(|(bp, _)| p < bp) {
                best = Some((p, e as u16));
            }
        }
        best.map(|(_, e)| e)
    }

    /// Any pending and enabled exception at all (WFI wakes on these even when masked).
    pub fn any_pending_enabled(&self) -> bool {
        (2..(16 + self.irqs as usize))
            .any(|e| self.pending[e] && self.enabled[e] && !self.active[e])
    }

    /// Marks a peripheral interrupt line high: the NVIC latches it pending unless it is active
    /// (a level that stays high re-pends on return; B3.4.1, "level-sensitive interrupts").
    /// Returns true when this made it pending (it was neither pending nor active).
    pub fn raise_irq(&mut self, irq: u16) -> bool {
        let e = (exc::IRQ0 + irq) as usize;
        if e < MAX_EXC && !self.active[e] && !self.pending[e] {
            self.pending[e] = true;
            return true;
        }
        false
    }

    /// Fault injection: an interrupt the firmware never enabled is enabled and made pending, as
    /// a stray NVIC_ISER write or a driver enabling a line it bound no handler to would leave it.
    pub fn force_irq(&mut self, irq: u16) {
        let e = (exc::IRQ0 + irq) as usize;
        self.enabled[e] = true;
        self.pending[e] = true;
    }

    /// Sets an exception pending (faults, PendSV, SysTick).
    pub fn set_pending(&mut self, e: u16) {
        self.pending[e as usize] = true;
    }

    pub fn is_pending(&self, e: u16) -> bool {
        self.pending[e as usize]
    }

    pub fn is_enabled(&self, e: u16) -> bool {
        self.enabled[e as usize]
    }

    /// Exception entry bookkeeping: pending → active.
    pub fn activate(&mut self, e: u16) {
        self.pending[e as usize] = false;
        self.active[e as usize] = true;
        self.active_stack.push(e);
    }

    /// Exception return bookkeeping: the innermost active exception is deactivated. Returns it.
    pub fn deactivate(&mut self) -> Option<u16> {
        let e = self.active_stack.pop()?;
        self.active[e as usize] = false;
        Some(e)
    }

    /// SCR.SEVONPEND: a new pending interrupt is a WFE wake-up event.
    pub fn sevonpend(&self) -> bool {
        self.scr & 0x10 != 0
    }

    /// CPACR grants full access to CP10/CP11 (the FPU).
    pub fn fpu_enabled(&self) -> bool {
        (self.cpacr >> 20) & 0xF == 0xF
    }

    fn icsr(&self) -> u32 {
        let vectactive = self.active_stack.last().copied().unwrap_or(0) as u32;
        let mut pend: Option<(i32, u16)> = None;
        for e in 2..(16 + self.irqs as usize) {
            if self.pending[e] && self.enabled[e] {
                let p = self.priority_of(e as u16);
                if pend.is_none_or(|(bp, _)| p < bp) {
                    pend = Some((p, e as u16));
                }
            }
        }
        let vectpending = pend.map_or(0, |(_, e)| e as u32);
        let isrpending = (16..(16 + self.irqs as usize)).any(|e| self.pending[e]) as u32;
        let rettobase = (self.active_stack.len() <= 1) as u32;
        vectactive
            | rettobase << 11
            | vectpending << 12
            | isrpending << 22
            | (self.pending[exc::SYSTICK as usize] as u32) << 26
            | (self.pending[exc::PENDSV as usize] as u32) << 28
    }

    fn bits(&self, arr: &[bool; MAX_EXC], word: u32) -> u32 {
        (0..32).fold(0, |acc, b| {
            let e = 16 + (word * 32 + b) as usize;
            if e < 16 + self.irqs as usize && arr[e] {
                acc | 1 << b
            } else {
                acc
            }
        })
    }

    /// Register read at `offset` from 0xE000_E000.
    pub fn read(&self, offset: u32) -> Result<u32, Unmodelled> {
        let o = offset;
        Ok(match o {
            // ICTR: number of 32-IRQ lines − 1 (B3.4.3).
            0x004 => (self.irqs as u32).div_ceil(32) - 1,
            // SysTick CTRL/LOAD/VAL/CALIB: the firmware never enables it (embassy's time driver
            // is TIM4); reads of a disabled SysTick are modelled as the reset values.
            0x010 => 0,
            0x014 | 0x018 => 0,
            0x01C => 0x4000_0000, // CALIB: NOREF, no TENMS
            0x100..=0x11C => self.bits(&self.enabled, (o - 0x100) / 4),
            0x180..=0x19C => self.bits(&self.enabled, (o - 0x180) / 4),
            0x200..=0x21C => self.bits(&self.pending, (o - 0x200) / 4),
            0x280..=0x29C => self.bits(&self.pending, (o - 0x280) / 4),
            0x300..=0x31C => self.bits(&self.active, (o - 0x300) / 4),
            0x400..=0x4EF => {
                let first = 16 + (o - 0x400) as usize;
                (0..4).fold(0, |acc, i| {
                    acc | (self.priority.get(first + i).copied().unwrap_or(0) as u32) << (8 * i)
                })
            }
            // CPUID: Cortex-M4 r0p1 (ARM DUI 0553 §4.3.1).
            0xD00 => 0x410F_C241,
            0xD04 => self.icsr(),
            0xD08 => self.vtor,
            0xD0C => 0xFA05_0000 | self.aircr_prigroup << 8,
            0xD10 => self.scr,
            0xD14 => self.ccr,
            0xD18..=0xD20 => {
                let first = 4 + (o - 0xD18) as usize;
                (0..4).fold(0, |acc, i| {
                    acc | (self.priority[first + i] as u32) << (8 * i)
                })
            }
            0xD24 => self.shcsr,
            0xD28 => self.cfsr,
            0xD2C => self.hfsr,
            0xD30 | 0xD34 | 0xD38 | 0xD3C => 0, // DFSR, MMFAR, BFAR, AFSR
            0xD88 => self.cpacr,
            // DHCSR: C_DEBUGEN is bit 0 (C1.6.2); S_REGRDY etc. not modelled.
            0xDF0 => self.debugger_attached as u32,
            0xDFC => self.demcr,
            0xF34 => self.fpccr,
            0xF38 => self.fpcar,
            0xF3C => self.fpdscr,
            // MVFR0/1: single precision, FPv4-SP (ARM DUI 0553 §4.6).
            0xF40 => 0x1011_0021,
            0xF44 => 0x1100_0011,
            _ => {
                return Err(Unmodelled::read(
                    o,
                    format!("SCS register 0x{:08X} is not modelled", SCS_BASE + o),
                ))
            }
        })
    }

    /// Register write at `offset` from 0xE000_E000 (`mask` selects the lanes written).
    pub fn write(&mut self, offset: u32, value: u32, mask: u32) -> Result<(), Unmodelled> {
        let o = offset;
        let v = value & mask;
        match o {
            0x010 => {
                if v & 1 != 0 {
                    return Err(Unmodelled::write(
                        o,
                        value,
                        "SysTick enabled (SYST_CSR.ENABLE): SysTick is not modelled",
                    ));
                }
            }
            0x014 | 0x018 => {}
            0x100..=0x11C | 0x180..=0x19C | 0x200..=0x21C | 0x280..=0x29C => {
                let (base, set) = match o {
                    0x100..=0x11C => (0x100, Some(true)),
                    0x180..=0x19C => (0x180, Some(false)),
                    0x200..=0x21C => (0x200, None),
                    _ => (0x280, None),
                };
                let word = (o - base) / 4;
                for b in 0..32 {
                    if v & (1 << b) == 0 {
                        continue;
                    }
                    let e = 16 + (word * 32 + b) as usize;
                    if e >= 16 + self.irqs as usize {
                        continue;
                    }
                    match (base, set) {
                        (_, Some(s)) => self.enabled[e] = s,
                        (0x200, None) => self.pending[e] = true,
                        _ => self.pending[e] = false,
                    }
                }
                self.changed = true;
            }
            0x400..=0x4EF => {
                let first = 16 + (o - 0x400) as usize;
                for i in 0..4 {
                    if mask & (0xFF << (8 * i)) != 0 && first + i < MAX_EXC {
                        // Only the upper 4 bits exist on STM32 (PM0214 §4.3.7).
                        self.priority[first + i] = ((value >> (8 * i)) & 0xF0) as u8;
                    }
                }
                self.changed = true;
            }
            0xD04 => {
                // ICSR: PENDSVSET/CLR, PENDSTSET/CLR, NMIPENDSET.
                if v & (1 << 28) != 0 {
                    self.pending[exc::PENDSV as usize] = true;
                }
                if v & (1 << 27) != 0 {
                    self.pending[exc::PENDSV as usize] = false;
                }
                if v & (1 << 26) != 0 {
                    self.pending[exc::SYSTICK as usize] = true;
                }
                if v & (1 << 25) != 0 {
                    self.pending[exc::SYSTICK as usize] = false;
                }
                if v & (1 << 31) != 0 {
                    self.pending[exc::NMI as usize] = true;
                }
                self.changed = true;
            }
            0xD08 => self.vtor = lane_merge(self.vtor, value, mask) & 0xFFFF_FF80,
            0xD0C => {
                // AIRCR writes need VECTKEY 0x05FA in the upper half (B3.2.6).
                if mask & 0xFFFF_0000 != 0xFFFF_0000 || value >> 16 != 0x05FA {
                    return Ok(());
                }
                self.aircr_prigroup = (value >> 8) & 7;
                if value & 4 != 0 {
                    self.reset_requested = true;
                }
                self.changed = true;
            }
            0xD10 => self.scr = lane_merge(self.scr, value, mask) & 0x16,
            0xD14 => self.ccr = lane_merge(self.ccr, value, mask) & 0x31B | 0x200,
            0xD18..=0xD20 => {
                let first = 4 + (o - 0xD18) as usize;
                for i in 0..4 {
                    if mask & (0xFF << (8 * i)) != 0 {
                        self.priority[first + i] = ((value >> (8 * i)) & 0xF0) as u8;
                    }
                }
                self.changed = true;
            }
            0xD24 => {
                self.shcsr = lane_merge(self.shcsr, value, mask);
                self.enabled[exc::MEM_MANAGE as usize] = self.shcsr & (1 << 16) != 0;
                self.enabled[exc::BUS_FAULT as usize] = self.shcsr & (1 << 17) != 0;
                self.enabled[exc::USAGE_FAULT as usize] = self.shcsr & (1 << 18) != 0;
            }
            0xD28 => self.cfsr &= !v, // write-one-to-clear
            0xD2C => self.hfsr &= !v,
            0xD88 => self.cpacr = lane_merge(self.cpacr, value, mask),
            0xDF0 => {} // DHCSR writes need DBGKEY and only a debugger makes them; ignored.
            0xDFC => self.demcr = lane_merge(self.demcr, value, mask),
            0xF34 => self.fpccr = lane_merge(self.fpccr, value, mask),
            0xF38 => self.fpcar = lane_merge(self.fpcar, value, mask) & !7,
            0xF3C => self.fpdscr = lane_merge(self.fpdscr, value, mask),
            // STIR: software trigger of an IRQ.
            0xF00 => {
                let irq = (v & 0x1FF) as usize;
                if irq < self.irqs as usize {
                    self.pending[16 + irq] = true;
                }
                self.changed = true;
            }
            _ => {
                return Err(Unmodelled::write(
                    o,
                    value,
                    format!("SCS register 0x{:08X} is not modelled", SCS_BASE + o),
                ))
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn enable_pend_and_take_by_priority() {
        let mut s = Scs::new(97);
        // ISER0 bit 28 = IRQ 28 (TIM2 on F446), ISER1 bit 0 = IRQ 32.
        s.write(0x100, 1 << 28, !0).unwrap();
        s.write(0x104, 1, !0).unwrap();
        // IPR: IRQ 28 priority 0x20, IRQ 32 priority 0x10 (more urgent).
        s.write(0x41C, 0x20, 0xFF).unwrap();
        s.write(0x420, 0x10, 0xFF).unwrap();
        s.raise_irq(28);
        s.raise_irq(32);
        assert_eq!(s.next_to_take(256), Some(16 + 32));
        // Under PRIMASK nothing configurable is taken.
        assert_eq!(s.next_to_take(s.execution_priority(true, 0, false)), None);
        // While IRQ 32 (0x10) is active, IRQ 28 (0x20) cannot preempt.
        s.activate(16 + 32);
        assert_eq!(s.next_to_take(s.execution_priority(false, 0, false)), None);
        s.deactivate();
        assert_eq!(s.next_to_take(256), Some(16 + 28));
        // ISPR/ISER read back by bit.
        assert_eq!(s.read(0x200).unwrap(), 1 << 28);
        assert_eq!(s.read(0x100).unwrap(), 1 << 28);
    }

    #[test]
    fn equal_priority_does_not_preempt_and_lowest_number_wins() {
        let mut s = Scs::new(97);
        s.write(0x100, (1 << 28) | (1 << 30), !0).unwrap();
        s.raise_irq(30);
        s.raise_irq(28);
        assert_eq!(s.next_to_take(256), Some(16 + 28));
        s.activate(16 + 28);
        // Same priority (0): no preemption.
        assert_eq!(s.next_to_take(s.execution_priority(false, 0, false)), None);
    }

    #[test]
    fn aircr_needs_the_key() {
        let mut s = Scs::new(97);
        s.write(0xD0C, 0x0000_0004, !0).unwrap();
        assert!(!s.reset_requested);
        s.write(0xD0C, 0x05FA_0004, !0).unwrap();
        assert!(s.reset_requested);
    }

    #[test]
    fn unknown_register_fails_loudly() {
        let s = Scs::new(97);
        let e = s.read(0xE00).unwrap_err();
        assert!(e.why.contains("0xE000EE00"), "{}", e.why);
    }
}
