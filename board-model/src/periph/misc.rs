//! Small system blocks the init path touches: the flash interface's access control register
//! (FLASH_ACR), the power controller (PWR) and the debug MCU block (DBGMCU), for the STM32F446
//! (RM0390 §3.8, §5.4, §33.16) and the STM32G474 (RM0440 §5.7, §6.4, §46.16).
//!
//! What embassy-stm32 0.6 init and the firmware touch here:
//! - FLASH (F446): `FLASH_ACR.write(LATENCY)` in rcc/f247.rs and a read-back loop; then the
//!   firmware's `board::init` clears ICEN/DCEN, pulses ICRST/DCRST, sets ICEN/DCEN/PRFTEN.
//! - FLASH (G474): `FLASH_ACR.modify(LATENCY)` in rcc/g4.rs and a read-back loop.
//! - PWR (F446): CR VOS = scale 1 (only with a PLL), ODEN then wait CSR.ODRDY, ODSWEN then wait
//!   CSR.ODSWRDY (rcc/f247.rs); CR DBP then wait DBP reads 1 (rcc/bd.rs).
//! - PWR (G474): CR3 UCPD1_DBDIS (ucpd.rs init), CR1 DBP then read back (rcc/bd.rs); CR5 R1MODE
//!   only when `boost` (the firmware's 150 MHz plan does not ask for it).
//! - DBGMCU: CR DBG_SLEEP/DBG_STOP/DBG_STANDBY set (lib.rs init, `enable_debug_during_sleep`),
//!   the firmware's fault path sets the IWDG freeze bit. IDCODE is read only by the F4 flash
//!   driver (dual-bank erase), which the firmware does not use.
//!
//! Registers outside that list return `Unmodelled`. SYSCFG answers a read of MEMRMP (embassy's
//! generated G4 flash layout reads FB_MODE) and EXTI is a block whose every access is `Unmodelled`: init only
//! enables/resets SYSCFG through the RCC and enables the EXTI interrupts in the NVIC.
//!
//! The flash interface's programming side (keys, CR/SR, program, erase) is `flash_prog`.

use super::flash_prog::{Kind, Prog};
use super::gpio::Chip;
use super::{merge, Peripheral, Signals, Time, Unmodelled};
use std::any::Any;

// ------------------------------------------------------------------------------------------
// FLASH_ACR, F446
// ------------------------------------------------------------------------------------------

const ACR_PRFTEN: u32 = 1 << 8;
const ACR_ICEN: u32 = 1 << 9;
const ACR_DCEN: u32 = 1 << 10;
const ACR_ICRST: u32 = 1 << 11;
const ACR_DCRST: u32 = 1 << 12;

/// Wait states the F446 needs at `hclk_hz` with VDD 2.7–3.6 V (the Nucleo's 3.3 V): RM0390 §3.4.1
/// table 5, 30 MHz per wait state up to 5 WS at 180 MHz.
pub fn f446_min_wait_states(hclk_hz: u64) -> u32 {
    (hclk_hz.saturating_sub(1) / 30_000_000) as u32
}

/// One write to FLASH_ACR: when, and the register value it left.
pub type AcrWrite = (Time, u32);

fn acr_cache_reset_check(
    offset: u32,
    old: u32,
    new: u32,
    value: u32,
    chip: &str,
) -> Result<(), Unmodelled> {
    // RM0390 §3.8.1 / RM0440 §5.7.1: ICRST/DCRST "can be written only when the cache is
    // disabled". Setting one while its cache is still on (before this write) is outside what
    // the manuals define, so it is reported.
    if new & ACR_ICRST != 0 && old & ACR_ICRST == 0 && old & ACR_ICEN != 0 {
        return Err(Unmodelled::write(
            offset,
            value,
            format!(
                "{chip} FLASH_ACR.ICRST set while ICEN = 1 (allowed only with the I-cache off)"
            ),
        ));
    }
    if new & ACR_DCRST != 0 && old & ACR_DCRST == 0 && old & ACR_DCEN != 0 {
        return Err(Unmodelled::write(
            offset,
            value,
            format!(
                "{chip} FLASH_ACR.DCRST set while DCEN = 1 (allowed only with the D-cache off)"
            ),
        ));
    }
    Ok(())
}

/// A write to a flash interface register other than ACR: the programming side's, or unmodelled.
#[allow(clippy::too_many_arguments)]
fn prog_write(
    prog: &mut Prog,
    now: Time,
    offset: u32,
    value: u32,
    mask: u32,
    out: &mut Signals,
    chip: &str,
    others: &str,
) -> Result<(), Unmodelled> {
    match prog.write(now, offset, value, mask) {
        Ok(true) => {
            out.replan = true;
            Ok(())
        }
        Ok(false) => Err(Unmodelled::write(
            offset,
            value,
            format!("{chip} FLASH register at offset {offset:#x} {others} is not modelled"),
        )),
        Err(why) => Err(Unmodelled::write(offset, value, why)),
    }
}

/// F446 flash interface: FLASH_ACR (RM0390 §3.8.1) here, the programming registers in `prog`. LATENCY reads back at once (the
/// manual's "read back to check" loop ends on the first read); the caches and prefetch are
/// state for the board to charge fetch time with.
#[derive(Clone, Debug)]
pub struct FlashF4 {
    acr: u32,
    history: Vec<AcrWrite>,
    /// Keys, CR/SR, program and erase (`flash_prog`).
    pub prog: Prog,
}

impl Default for FlashF4 {
    fn default() -> Self {
        Self::new()
    }
}

impl FlashF4 {
    /// Reset value of FLASH_ACR: 0 (0 WS, prefetch and caches off), RM0390 §3.8.1.
    pub const ACR_RESET: u32 = 0;

    pub fn new() -> Self {
        FlashF4 {
            acr: Self::ACR_RESET,
            history: Vec::new(),
            prog: Prog::new(Kind::F446),
        }
    }

    pub fn acr(&self) -> u32 {
        self.acr
    }
    /// LATENCY: flash wait states.
    pub fn wait_states(&self) -> u32 {
        self.acr & 0xF
    }
    /// The ART accelerator's instruction cache (64 lines of 128 bits, RM0390 §3.4.2) is on:
    /// ICEN. Prefetch and the data cache are reported separately.
    pub fn art_enabled(&self) -> bool {
        self.acr & ACR_ICEN != 0
    }
    pub fn prefetch_enabled(&self) -> bool {
        self.acr & ACR_PRFTEN != 0
    }
    pub fn icache_enabled(&self) -> bool {
        self.acr & ACR_ICEN != 0
    }
    pub fn dcache_enabled(&self) -> bool {
        self.acr & ACR_DCEN != 0
    }
    /// Every FLASH_ACR write since construction (kept across resets).
    pub fn acr_history(&self) -> &[AcrWrite] {
        &self.history
    }
}

impl Peripheral for FlashF4 {
    fn name(&self) -> &'static str {
        "FLASH"
    }

    fn read(&mut self, _now: Time, offset: u32, _out: &mut Signals) -> Result<u32, Unmodelled> {
        match offset {
            0x00 => Ok(self.acr),
            _ => self.prog.read(offset).ok_or_else(|| Unmodelled::read(
                offset,
                format!(
                    "F446 FLASH register at offset {offset:#x} (OPTKEYR: option-byte programming) is not modelled"
                ),
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
            0x00 => {
                // LATENCY[3:0], PRFTEN, ICEN, DCEN, ICRST, DCRST (RM0390 §3.8.1).
                let new = merge(self.acr, value, mask & 0x1F0F);
                acr_cache_reset_check(offset, self.acr, new, value, "F446")?;
                self.acr = new;
                self.history.push((now, new));
                Ok(())
            }
            _ => prog_write(
                &mut self.prog,
                now,
                offset,
                value,
                mask,
                out,
                "F446",
                "(OPTKEYR/OPTCR writes)",
            ),
        }
    }

    fn advance(&mut self, now: Time, _out: &mut Signals) {
        self.prog.advance(now);
    }
    fn next_event(&self) -> Option<Time> {
        self.prog.next_event()
    }
    fn irq_lines(&self, raise: &mut dyn FnMut(u16)) {
        self.prog.irq_lines(raise);
    }

    fn reset(&mut self, _now: Time) {
        self.acr = Self::ACR_RESET;
        self.prog.reset();
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}

// ------------------------------------------------------------------------------------------
// FLASH_ACR, G474
// ------------------------------------------------------------------------------------------

const ACR_RUN_PD: u32 = 1 << 13;

/// Dynamic voltage scaling range of the G474 core regulator (PWR_CR1.VOS, PWR_CR5.R1MODE).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum G4Range {
    /// Range 1 boost mode (R1MODE = 0): up to 170 MHz.
    Range1Boost,
    /// Range 1 normal mode (R1MODE = 1, reset): up to 150 MHz.
    Range1Normal,
    /// Range 2: up to 26 MHz.
    Range2,
}

impl G4Range {
    /// Highest HCLK/SYSCLK of the range (RM0440 §6.1.5).
    pub fn max_sysclk_hz(self) -> u64 {
        match self {
            G4Range::Range1Boost => 170_000_000,
            G4Range::Range1Normal => 150_000_000,
            G4Range::Range2 => 26_000_000,
        }
    }
}

/// Wait states the G474 needs at `hclk_hz` in `range`: RM0440 §5.3.3 table 9 (range 1 boost
/// 34 MHz per WS, range 1 normal 30 MHz per WS, range 2 12 MHz per WS up to 26 MHz). None
/// above the range's maximum.
pub fn g474_min_wait_states(hclk_hz: u64, range: G4Range) -> Option<u32> {
    if hclk_hz > range.max_sysclk_hz() {
        return None;
    }
    let step = match range {
        G4Range::Range1Boost => 34_000_000,
        G4Range::Range1Normal => 30_000_000,
        G4Range::Range2 => 12_000_000,
    };
    Some((hclk_hz.saturating_sub(1) / step) as u32)
}

/// G474 flash interface: FLASH_ACR (RM0440 §5.7.1) here, the programming registers in `prog`.
#[derive(Clone, Debug)]
pub struct FlashG4 {
    acr: u32,
    history: Vec<AcrWrite>,
    /// Keys, CR/SR, program and erase (`flash_prog`).
    pub prog: Prog,
}

impl Default for FlashG4 {
    fn default() -> Self {
        Self::new()
    }
}

impl FlashG4 {
    /// Reset value of FLASH_ACR: ICEN, DCEN and DBG_SWEN set (RM0440 §5.7.1 gives 0x0004 0600;
    /// ST's SVD omits DBG_SWEN and says 0x600 — the manual is followed).
    pub const ACR_RESET: u32 = 0x0004_0600;

    pub fn new() -> Self {
        FlashG4 {
            acr: Self::ACR_RESET,
            history: Vec::new(),
            prog: Prog::new(Kind::G474),
        }
    }

    pub fn acr(&self) -> u32 {
        self.acr
    }
    pub fn wait_states(&self) -> u32 {
        self.acr & 0xF
    }
    /// ART accelerator instruction cache (ICEN, RM0440 §5.3.7).
    pub fn art_enabled(&self) -> bool {
        self.acr & ACR_ICEN != 0
    }
    pub fn prefetch_enabled(&self) -> bool {
        self.acr & ACR_PRFTEN != 0
    }
    pub fn icache_enabled(&self) -> bool {
        self.acr & ACR_ICEN != 0
    }
    pub fn dcache_enabled(&self) -> bool {
        self.acr & ACR_DCEN != 0
    }
    pub fn acr_history(&self) -> &[AcrWrite] {
        &self.history
    }
}

impl Peripheral for FlashG4 {
    fn name(&self) -> &'static str {
        "FLASH"
    }

    fn read(&mut self, _now: Time, offset: u32, _out: &mut Signals) -> Result<u32, Unmodelled> {
        match offset {
            0x00 => Ok(self.acr),
            _ => self.prog.read(offset).ok_or_else(|| Unmodelled::read(
                offset,
                format!("G474 FLASH register at offset {offset:#x} (ECC, option-byte keys, PCROP, WRP) is not modelled"),
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
            0x00 => {
                // LATENCY[3:0], PRFTEN, ICEN, DCEN, ICRST, DCRST, RUN_PD, SLEEP_PD, DBG_SWEN.
                let new = merge(self.acr, value, mask & 0x0004_7F0F);
                if new & ACR_RUN_PD != 0 {
                    // Powering the flash down in Run mode needs the PDKEYR unlock and takes the
                    // code memory away: not modelled.
                    return Err(Unmodelled::write(
                        offset,
                        value,
                        "G474 FLASH_ACR.RUN_PD (flash power-down in Run mode) is not modelled",
                    ));
                }
                acr_cache_reset_check(offset, self.acr, new, value, "G474")?;
                self.acr = new;
                self.history.push((now, new));
                Ok(())
            }
            _ => prog_write(
                &mut self.prog,
                now,
                offset,
                value,
                mask,
                out,
                "G474",
                "(ECC/option bytes/PCROP)",
            ),
        }
    }

    fn advance(&mut self, now: Time, _out: &mut Signals) {
        self.prog.advance(now);
    }
    fn next_event(&self) -> Option<Time> {
        self.prog.next_event()
    }
    fn irq_lines(&self, raise: &mut dyn FnMut(u16)) {
        self.prog.irq_lines(raise);
    }

    /// System reset. (RCC_AHB1RSTR.FLASHRST, which embassy pulses at init, "can be activated
    /// only when the flash memory is in power-down mode" (RM0440 §7.4.14): while code runs from
    /// flash it has no effect, so the RCC model does not ask for this reset.)
    fn reset(&mut self, _now: Time) {
        self.acr = Self::ACR_RESET;
        self.prog.reset();
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}

// ------------------------------------------------------------------------------------------
// PWR, F446
// ------------------------------------------------------------------------------------------

const F4_CR_DBP: u32 = 1 << 8;
const F4_CR_ADCDC1: u32 = 1 << 13;
const F4_CR_ODEN: u32 = 1 << 16;
const F4_CR_ODSWEN: u32 = 1 << 17;
const F4_CR_UDEN: u32 = 3 << 18;
const F4_CSR_BRR: u32 = 1 << 3;
const F4_CSR_BRE: u32 = 1 << 9;
const F4_CSR_VOSRDY: u32 = 1 << 14;
const F4_CSR_ODRDY: u32 = 1 << 16;
const F4_CSR_ODSWRDY: u32 = 1 << 17;

/// F446 power controller: PWR_CR and PWR_CSR (RM0390 §5.4.1, §5.4.2).
///
/// Modelled: VOS as stored scale; over-drive (ODEN → ODRDY, ODSWEN → ODSWRDY, both at once:
/// the datasheet's switching times are not modelled; clearing ODEN clears ODSWEN as the manual
/// says); DBP (the RCC model needs it for RCC_BDCR: the board copies `dbp()` into
/// `RccF4::set_backup_domain_writable`); BRE → BRR at once; PVD output low (VDD = 3.3 V is above
/// every PLS threshold). Low-power mode bits are stored for the board's WFI handling.
///
/// Not checked here because PWR cannot see the RCC: "VOS can be modified only when the PLL is
/// OFF" and "ODEN/ODSWEN only with HSI or HSE as system clock" (RM0390 §5.4.1). The resulting
/// state is checked by `RccF4::check_power_and_flash`. VOSRDY reads 1: the scale change after
/// PLL lock is not modelled.
#[derive(Clone, Debug)]
pub struct PwrF4 {
    cr: u32,
    csr: u32,
}

impl Default for PwrF4 {
    fn default() -> Self {
        Self::new()
    }
}

impl PwrF4 {
    /// PWR_CR reset value: VOS = 11 (scale 1), RM0390 §5.4.1.
    pub const CR_RESET: u32 = 0x0000_C000;

    pub fn new() -> Self {
        PwrF4 {
            cr: Self::CR_RESET,
            csr: 0,
        }
    }

    pub fn cr(&self) -> u32 {
        self.cr
    }
    /// Backup domain write access (DBP).
    pub fn dbp(&self) -> bool {
        self.cr & F4_CR_DBP != 0
    }
    /// Regulator voltage scale 1, 2 or 3 (VOS = 00 is "reserved, scale 3 selected").
    pub fn vos_scale(&self) -> u8 {
        match (self.cr >> 14) & 3 {
            3 => 1,
            2 => 2,
            _ => 3,
        }
    }
    /// Over-drive mode active: ODEN and ODSWEN both set and ready.
    pub fn overdrive_active(&self) -> bool {
        self.cr & (F4_CR_ODEN | F4_CR_ODSWEN) == (F4_CR_ODEN | F4_CR_ODSWEN)
    }

    fn csr_read(&self) -> u32 {
        let mut v = self.csr & ((1 << 7) | (1 << 8) | F4_CSR_BRE);
        if self.csr & F4_CSR_BRE != 0 {
            v |= F4_CSR_BRR;
        }
        v |= F4_CSR_VOSRDY;
        if self.cr & F4_CR_ODEN != 0 {
            v |= F4_CSR_ODRDY;
        }
        if self.cr & F4_CR_ODSWEN != 0 {
            v |= F4_CSR_ODSWRDY;
        }
        v
    }
}

impl Peripheral for PwrF4 {
    fn name(&self) -> &'static str {
        "PWR"
    }

    fn read(&mut self, _now: Time, offset: u32, _out: &mut Signals) -> Result<u32, Unmodelled> {
        match offset {
            // CWUF/CSBF read 0 (RM0390 §5.4.1).
            0x00 => Ok(self.cr),
            0x04 => Ok(self.csr_read()),
            _ => Err(Unmodelled::read(
                offset,
                format!("F446 PWR register at offset {offset:#x} does not exist"),
            )),
        }
    }

    fn write(
        &mut self,
        _now: Time,
        offset: u32,
        value: u32,
        mask: u32,
        _out: &mut Signals,
    ) -> Result<(), Unmodelled> {
        match offset {
            0x00 => {
                // Writable: LPDS, PDDS, PVDE, PLS, DBP, FPDS, LPUDS, MRUDS, ADCDC1, VOS, ODEN,
                // ODSWEN, UDEN, FMSSR, FISSR. CWUF/CSBF (bits 2, 3) only clear flags that this
                // model never sets (no Standby, no wakeup pins).
                let mut new = merge(self.cr, value, mask & 0x003F_EFF3);
                if new & F4_CR_UDEN != 0 {
                    return Err(Unmodelled::write(
                        offset,
                        value,
                        "F446 PWR_CR.UDEN (under-drive in Stop mode) is not modelled",
                    ));
                }
                if new & F4_CR_ODSWEN != 0
                    && self.cr & F4_CR_ODSWEN == 0
                    && self.csr_read() & F4_CSR_ODRDY == 0
                {
                    // "The ODSWEN bit must only be set when ODRDY flag is set."
                    return Err(Unmodelled::write(
                        offset,
                        value,
                        "F446 PWR_CR.ODSWEN set while CSR.ODRDY = 0 (the manual requires ODRDY first)",
                    ));
                }
                if new & F4_CR_ADCDC1 != 0 {
                    // RM0390 §5.4.1 ODEN: cleared by hardware when ADCDC1 is set.
                    new &= !F4_CR_ODEN;
                }
                if new & F4_CR_ODEN == 0 {
                    // ODSWEN: cleared when ODEN is reset.
                    new &= !F4_CR_ODSWEN;
                }
                self.cr = new;
                Ok(())
            }
            0x04 => {
                // EWUP2 (7), EWUP1 (8), BRE (9); UDRDY (19:18) is cleared by writing 1 and never set.
                self.csr = merge(self.csr, value, mask & 0x0000_0380);
                Ok(())
            }
            _ => Err(Unmodelled::write(
                offset,
                value,
                format!("F446 PWR register at offset {offset:#x} does not exist"),
            )),
        }
    }

    /// System reset (and RCC PWRRST, which embassy pulses at init). DBP, VOS and the
    /// over-drive bits return to reset. (BRE is in the backup domain on the real chip; the
    /// backup regulator is not used here, so it is simply cleared.)
    fn reset(&mut self, _now: Time) {
        *self = Self::new();
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}

// ------------------------------------------------------------------------------------------
// PWR, G474
// ------------------------------------------------------------------------------------------

const G4_CR1_DBP: u32 = 1 << 8;
const G4_CR1_LPR: u32 = 1 << 14;
const G4_CR3_APC: u32 = 1 << 10;
const G4_CR5_R1MODE: u32 = 1 << 8;

/// G474 power controller: CR1..CR5, SR1, SR2, SCR (RM0440 §6.4).
///
/// Modelled: VOS range (writes of 00/11 are "forbidden by hardware" and leave it unchanged),
/// R1MODE (boost when 0), DBP (copied by the board into `RccG4::set_backup_domain_writable`),
/// LPR with SR2.REGLPF following it at once, SR2.VOSF always 0 (voltage changes complete at
/// once), PVD/PVM outputs low (VDD, VDDA at 3.3 V). CR2, CR3 (UCPD dead-battery disable, wakeup
/// enables, internal wakeup line), CR4 and the low-power mode selection are stored.
/// SR2.REGLPS reads 1 (low-power regulator started, which it is once the chip runs; the
/// register's documented reset value of 0 describes the instant before that — an assumption).
/// APC = 1 (apply PWR_PUCRx/PDCRx pulls) and the PUCR/PDCR registers are not modelled.
#[derive(Clone, Debug)]
pub struct PwrG4 {
    cr1: u32,
    cr2: u32,
    cr3: u32,
    cr4: u32,
    cr5: u32,
}

impl Default for PwrG4 {
    fn default() -> Self {
        Self::new()
    }
}

impl PwrG4 {
    /// Reset values (RM0440 §6.4): CR1 VOS = 01 (range 1); CR3 EIWUL = 1; CR5 R1MODE = 1.
    pub const CR1_RESET: u32 = 0x0000_0200;
    pub const CR3_RESET: u32 = 0x0000_8000;
    pub const CR5_RESET: u32 = 0x0000_0100;

    pub fn new() -> Self {
        PwrG4 {
            cr1: Self::CR1_RESET,
            cr2: 0,
            cr3: Self::CR3_RESET,
            cr4: 0,
            cr5: Self::CR5_RESET,
        }
    }

    pub fn cr1(&self) -> u32 {
        self.cr1
    }
    pub fn cr3(&self) -> u32 {
        self.cr3
    }
    pub fn cr5(&self) -> u32 {
        self.cr5
    }
    pub fn dbp(&self) -> bool {
        self.cr1 & G4_CR1_DBP != 0
    }
    /// Range 1 boost mode selected (R1MODE = 0).
    pub fn boost(&self) -> bool {
        self.cr5 & G4_CR5_R1MODE == 0
    }
    /// The core voltage range the registers select.
    pub fn range(&self) -> G4Range {
        match ((self.cr1 >> 9) & 3, self.boost()) {
            (2, _) => G4Range::Range2,
            (_, true) => G4Range::Range1Boost,
            _ => G4Range::Range1Normal,
        }
    }
    /// Low-power run mode requested (CR1.LPR).
    pub fn low_power_run(&self) -> bool {
        self.cr1 & G4_CR1_LPR != 0
    }
}

impl Peripheral for PwrG4 {
    fn name(&self) -> &'static str {
        "PWR"
    }

    fn read(&mut self, _now: Time, offset: u32, _out: &mut Signals) -> Result<u32, Unmodelled> {
        match offset {
            0x00 => Ok(self.cr1),
            0x04 => Ok(self.cr2),
            0x08 => Ok(self.cr3),
            0x0C => Ok(self.cr4),
            // SR1: no wakeup or standby flag ever set here.
            0x10 => Ok(0),
            // SR2: REGLPS (8) = 1, REGLPF (9) = LPR, VOSF (10) = 0, PVDO/PVMOx = 0.
            0x14 => Ok((1 << 8) | if self.low_power_run() { 1 << 9 } else { 0 }),
            // SCR is write-only.
            0x18 => Ok(0),
            0x80 => Ok(self.cr5),
            _ => Err(Unmodelled::read(
                offset,
                format!("G474 PWR register at offset {offset:#x} (PUCRx/PDCRx or reserved) is not modelled"),
            )),
        }
    }

    fn write(
        &mut self,
        _now: Time,
        offset: u32,
        value: u32,
        mask: u32,
        _out: &mut Signals,
    ) -> Result<(), Unmodelled> {
        match offset {
            0x00 => {
                // LPMS[2:0], FPD_STOP, DBP, VOS[10:9], LPR.
                let mut new = merge(self.cr1, value, mask & 0x0000_470F);
                let vos = (new >> 9) & 3;
                if vos == 0 || vos == 3 {
                    // RM0440 §6.4.1: "00, 11: cannot be written (forbidden by hardware)".
                    new = (new & !(3 << 9)) | (self.cr1 & (3 << 9));
                }
                self.cr1 = new;
                Ok(())
            }
            0x04 => {
                // PVDE, PLS, PVMEN1, PVMEN2.
                self.cr2 = merge(self.cr2, value, mask & 0x0000_00CF);
                Ok(())
            }
            0x08 => {
                // EWUP1..5, RRS, APC, UCPD1_STDBY, UCPD1_DBDIS, EIWUL.
                let new = merge(self.cr3, value, mask & 0x0000_E51F);
                if new & G4_CR3_APC != 0 {
                    return Err(Unmodelled::write(
                        offset,
                        value,
                        "G474 PWR_CR3.APC (apply PWR_PUCRx/PDCRx pulls) is not modelled",
                    ));
                }
                self.cr3 = new;
                Ok(())
            }
            0x0C => {
                // WP1..5, VBE, VBRS.
                self.cr4 = merge(self.cr4, value, mask & 0x0000_031F);
                Ok(())
            }
            0x10 | 0x14 => Err(Unmodelled::write(offset, value, "G474 PWR_SR1/SR2 are read-only")),
            // SCR: clears SR1 flags, which are never set.
            0x18 => Ok(()),
            0x80 => {
                // R1MODE only (RM0440 §6.4.20); the boost switching sequence is the
                // firmware's duty (checked with `RccG4::check_power_and_flash`).
                self.cr5 = merge(self.cr5, value, mask & G4_CR5_R1MODE);
                Ok(())
            }
            _ => Err(Unmodelled::write(
                offset,
                value,
                format!("G474 PWR register at offset {offset:#x} (PUCRx/PDCRx or reserved) is not modelled"),
            )),
        }
    }

    fn reset(&mut self, _now: Time) {
        *self = Self::new();
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}

// ------------------------------------------------------------------------------------------
// SYSCFG, EXTI
// ------------------------------------------------------------------------------------------

/// SYSCFG (RM0390 §8, RM0440 §10): mapped so that an access is reported by name. embassy init
/// only enables and resets it through the RCC; the one register read is SYSCFG_MEMRMP, by the
/// flash layout embassy-stm32 0.6 generates for the dual-bank G474 (`FlashBank::base` in its
/// build's `_generated.rs` reads FB_MODE to place the banks). Every other access (EXTI line
/// muxing, compensation cell, and on the G474 the VREFBUF/COMP/OPAMP registers in the same 1 KB
/// window) is `Unmodelled`.
#[derive(Clone, Debug, Default)]
pub struct Syscfg;

impl Syscfg {
    pub fn new() -> Self {
        Syscfg
    }
}

impl Peripheral for Syscfg {
    fn name(&self) -> &'static str {
        "SYSCFG"
    }
    fn read(&mut self, _now: Time, offset: u32, _out: &mut Signals) -> Result<u32, Unmodelled> {
        match offset {
            // SYSCFG_MEMRMP after a boot from main flash with the banks not swapped (BFB2 = 0):
            // MEM_MODE = 0 and (G474) FB_MODE, bit 8, = 0 (RM0390 §8.2.1; RM0440 SYSCFG_MEMRMP).
            0x00 => Ok(0),
            _ => Err(Unmodelled::read(
                offset,
                format!("SYSCFG register at offset {offset:#x} is not modelled (nothing in the firmware uses it)"),
            )),
        }
    }
    fn write(
        &mut self,
        _now: Time,
        offset: u32,
        value: u32,
        _mask: u32,
        _out: &mut Signals,
    ) -> Result<(), Unmodelled> {
        Err(Unmodelled::write(
            offset,
            value,
            format!("SYSCFG register at offset {offset:#x} is not modelled (nothing in the firmware's init uses it)"),
        ))
    }
    fn reset(&mut self, _now: Time) {}
    fn as_any(&self) -> &dyn Any {
        self
    }
    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}

/// EXTI (RM0390 §10.2, RM0440 §15): mapped so that an access is reported by name. embassy's
/// `exti::init` only enables the EXTI interrupt lines in the NVIC; no EXTI register is read or
/// written (the firmware configures no external interrupt, and the EXTI handlers, which read
/// the pending register, never run because no line can become pending). Every access is
/// `Unmodelled`.
#[derive(Clone, Debug, Default)]
pub struct Exti;

impl Exti {
    pub fn new() -> Self {
        Exti
    }
}

impl Peripheral for Exti {
    fn name(&self) -> &'static str {
        "EXTI"
    }
    fn read(&mut self, _now: Time, offset: u32, _out: &mut Signals) -> Result<u32, Unmodelled> {
        Err(Unmodelled::read(
            offset,
            format!("EXTI register at offset {offset:#x} is not modelled (no EXTI line is used)"),
        ))
    }
    fn write(
        &mut self,
        _now: Time,
        offset: u32,
        value: u32,
        _mask: u32,
        _out: &mut Signals,
    ) -> Result<(), Unmodelled> {
        Err(Unmodelled::write(
            offset,
            value,
            format!("EXTI register at offset {offset:#x} is not modelled (no EXTI line is used)"),
        ))
    }
    fn reset(&mut self, _now: Time) {}
    fn as_any(&self) -> &dyn Any {
        self
    }
    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}

// ------------------------------------------------------------------------------------------
// DBGMCU
// ------------------------------------------------------------------------------------------

/// Debug MCU block at 0xE004_2000 (RM0390 §33.16, RM0440 §46.16): IDCODE, CR and the freeze
/// registers. The freeze bits only matter while the core is halted by a debugger: the board
/// reads them (`iwdg_stop`, `timer_stop`) when it halts the core and freezes the blocks.
///
/// The registers are reset by power-on reset only, not by a system reset (RM0390 §33.16.3/.4:
/// "POR Reset: 0x0000 0000 (not reset by system reset)"; the author reads RM0440 the same
/// way), so `reset` keeps them. Only 32-bit accesses are supported (same sections): a sub-word
/// write is reported.
#[derive(Clone, Debug)]
pub struct DbgMcu {
    chip: Chip,
    idcode: u32,
    cr: u32,
    /// F446: APB1_FZ, APB2_FZ. G474: APB1FZR1, APB1FZR2, APB2FZR.
    fz: [u32; 3],
}

impl DbgMcu {
    /// The chip with DBGMCU_IDCODE.DEV_ID `dev_id`: 0x421 (STM32F446) or 0x469 (STM32G474).
    /// Panics on another id (a board-building mistake, not a firmware value).
    pub fn new(dev_id: u16) -> Self {
        match dev_id {
            0x421 => Self::f446(),
            0x469 => Self::g474(),
            _ => panic!(
                "DbgMcu::new: DEV_ID {dev_id:#x} is neither the F446 (0x421) nor the G474 (0x469)"
            ),
        }
    }

    /// STM32F446: DEV_ID 0x421. REV_ID 0x1000 (revision A) is a plausible value, not read from
    /// a particular board.
    pub fn f446() -> Self {
        Self::with_idcode(Chip::F446, 0x1000_0421)
    }
    /// STM32G474: DEV_ID 0x469. REV_ID 0x1000 is a placeholder revision, not read from a
    /// particular board (real parts report their silicon revision).
    pub fn g474() -> Self {
        Self::with_idcode(Chip::G474, 0x1000_0469)
    }
    /// Any IDCODE (REV_ID[31:16], DEV_ID[11:0]).
    pub fn with_idcode(chip: Chip, idcode: u32) -> Self {
        DbgMcu {
            chip,
            idcode,
            cr: 0,
            fz: [0; 3],
        }
    }

    pub fn idcode(&self) -> u32 {
        self.idcode
    }
    /// DBGMCU_CR (DBG_SLEEP bit 0, DBG_STOP bit 1, DBG_STANDBY bit 2, TRACE bits).
    pub fn cr(&self) -> u32 {
        self.cr
    }
    pub fn dbg_sleep(&self) -> bool {
        self.cr & 1 != 0
    }
    pub fn dbg_stop(&self) -> bool {
        self.cr & 2 != 0
    }
    pub fn dbg_standby(&self) -> bool {
        self.cr & 4 != 0
    }
    /// DBG_IWDG_STOP: bit 12 of APB1_FZ (F446) / APB1FZR1 (G474).
    pub fn iwdg_stop(&self) -> bool {
        self.fz[0] & (1 << 12) != 0
    }
    /// DBG_WWDG_STOP: bit 11 of the same register.
    pub fn wwdg_stop(&self) -> bool {
        self.fz[0] & (1 << 11) != 0
    }
    /// DBG_TIMx_STOP for timer `timer` (1 = TIM1); false for a timer without a freeze bit.
    pub fn timer_stop(&self, timer: u8) -> bool {
        let (reg, bit) = match (self.chip, timer) {
            (_, 2..=5) => (0, timer - 2),
            (Chip::F446, 6) | (Chip::G474, 6) => (0, 4),
            (Chip::F446, 7) | (Chip::G474, 7) => (0, 5),
            (Chip::F446, 12) => (0, 6),
            (Chip::F446, 13) => (0, 7),
            (Chip::F446, 14) => (0, 8),
            (Chip::F446, 1) => (1, 0),
            (Chip::F446, 8) => (1, 1),
            (Chip::F446, 9) => (1, 16),
            (Chip::F446, 10) => (1, 17),
            (Chip::F446, 11) => (1, 18),
            (Chip::G474, 1) => (2, 11),
            (Chip::G474, 8) => (2, 13),
            (Chip::G474, 15) => (2, 16),
            (Chip::G474, 16) => (2, 17),
            (Chip::G474, 17) => (2, 18),
            (Chip::G474, 20) => (2, 20),
            _ => return false,
        };
        self.fz[reg] & (1 << bit) != 0
    }

    /// Freeze-register slot and writable bits for `offset`.
    fn fz_slot(&self, offset: u32) -> Option<(usize, u32)> {
        match (self.chip, offset) {
            // APB1_FZ: TIM2-7, TIM12-14, RTC, WWDG, IWDG, I2C1-3 SMBus timeouts, FMPI2C, CAN1/2.
            (Chip::F446, 0x08) => Some((0, 0x07E0_1DFF)),
            // APB2_FZ: TIM1, TIM8, TIM9-11.
            (Chip::F446, 0x0C) => Some((1, 0x0007_0003)),
            // APB1FZR1: TIM2-7, RTC, WWDG, IWDG, I2C1-3, LPTIM1.
            (Chip::G474, 0x08) => Some((0, 0xC060_1C3F)),
            // APB1FZR2: I2C4.
            (Chip::G474, 0x0C) => Some((1, 0x0000_0002)),
            // APB2FZR: TIM1, TIM8, TIM15-17, TIM20, HRTIM.
            (Chip::G474, 0x10) => Some((2, 0x3C17_2800)),
            _ => None,
        }
    }
}

impl Peripheral for DbgMcu {
    fn name(&self) -> &'static str {
        "DBGMCU"
    }

    fn read(&mut self, _now: Time, offset: u32, _out: &mut Signals) -> Result<u32, Unmodelled> {
        match offset {
            0x00 => Ok(self.idcode),
            0x04 => Ok(self.cr),
            _ => match self.fz_slot(offset) {
                Some((i, _)) => Ok(self.fz[i]),
                None => Err(Unmodelled::read(
                    offset,
                    format!("DBGMCU register at offset {offset:#x} does not exist"),
                )),
            },
        }
    }

    fn write(
        &mut self,
        _now: Time,
        offset: u32,
        value: u32,
        mask: u32,
        _out: &mut Signals,
    ) -> Result<(), Unmodelled> {
        if mask != 0xFFFF_FFFF {
            return Err(Unmodelled::write(
                offset,
                value,
                "DBGMCU sub-word write: only 32-bit accesses are supported",
            ));
        }
        match offset {
            0x00 => Err(Unmodelled::write(
                offset,
                value,
                "DBGMCU_IDCODE is read-only",
            )),
            0x04 => {
                // DBG_SLEEP, DBG_STOP, DBG_STANDBY, TRACE_IOEN, TRACE_MODE.
                let new = value & 0xE7;
                if new & (1 << 5) != 0 {
                    return Err(Unmodelled::write(
                        offset,
                        value,
                        "DBGMCU_CR.TRACE_IOEN (trace port pins) is not modelled",
                    ));
                }
                self.cr = new;
                Ok(())
            }
            _ => match self.fz_slot(offset) {
                Some((i, bits)) => {
                    self.fz[i] = value & bits;
                    Ok(())
                }
                None => Err(Unmodelled::write(
                    offset,
                    value,
                    format!("DBGMCU register at offset {offset:#x} does not exist"),
                )),
            },
        }
    }

    /// Not reset by a system reset (power-on reset only).
    fn reset(&mut self, _now: Time) {}

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

    fn w<P: Peripheral>(p: &mut P, now: Time, off: u32, v: u32) {
        p.write(now, off, v, 0xFFFF_FFFF, &mut Signals::default())
            .unwrap();
    }
    fn r<P: Peripheral>(p: &mut P, off: u32) -> u32 {
        p.read(0, off, &mut Signals::default()).unwrap()
    }

    #[test]
    fn f446_wait_state_table() {
        // RM0390 table 5, 2.7–3.6 V.
        assert_eq!(f446_min_wait_states(16_000_000), 0);
        assert_eq!(f446_min_wait_states(30_000_000), 0);
        assert_eq!(f446_min_wait_states(30_000_001), 1);
        assert_eq!(f446_min_wait_states(150_000_000), 4);
        assert_eq!(f446_min_wait_states(180_000_000), 5);
    }

    #[test]
    fn g474_wait_state_table() {
        assert_eq!(
            g474_min_wait_states(150_000_000, G4Range::Range1Normal),
            Some(4)
        );
        assert_eq!(
            g474_min_wait_states(120_000_000, G4Range::Range1Normal),
            Some(3)
        );
        assert_eq!(
            g474_min_wait_states(170_000_000, G4Range::Range1Boost),
            Some(4)
        );
        assert_eq!(
            g474_min_wait_states(136_000_000, G4Range::Range1Boost),
            Some(3)
        );
        assert_eq!(
            g474_min_wait_states(160_000_000, G4Range::Range1Normal),
            None
        );
        assert_eq!(g474_min_wait_states(16_000_000, G4Range::Range2), Some(1));
    }

    /// What embassy (rcc/f247.rs) and then the firmware's `board::init` write on the F446.
    #[test]
    fn f446_acr_embassy_then_art_enable() {
        let mut f = FlashF4::new();
        assert!(!f.art_enabled());
        // embassy: FLASH.acr().write(|w| w.set_latency(5)), then reads LATENCY back.
        w(&mut f, 100, 0, 5);
        assert_eq!(r(&mut f, 0) & 0xF, 5);
        assert_eq!(f.wait_states(), 5);
        assert!(!f.art_enabled() && !f.prefetch_enabled());
        // firmware: caches off, reset pulse, then ICEN | DCEN | PRFTEN.
        let a = r(&mut f, 0) & !(ACR_ICEN | ACR_DCEN);
        w(&mut f, 200, 0, a);
        w(&mut f, 201, 0, a | ACR_ICRST | ACR_DCRST);
        w(&mut f, 202, 0, a);
        w(&mut f, 203, 0, a | ACR_ICEN | ACR_DCEN | ACR_PRFTEN);
        assert!(f.art_enabled() && f.prefetch_enabled() && f.dcache_enabled());
        assert_eq!(f.acr(), 0x0705);
        let h: Vec<u32> = f.acr_history().iter().map(|&(_, v)| v).collect();
        assert_eq!(h, vec![0x0005, 0x0005, 0x1805, 0x0005, 0x0705]);
        assert_eq!(f.acr_history()[0].0, 100);
        // Resetting a cache that is on is reported.
        assert!(f
            .write(
                300,
                0,
                0x0705 | ACR_ICRST,
                0xFFFF_FFFF,
                &mut Signals::default()
            )
            .is_err());
        // System reset: ACR back to 0, history kept.
        f.reset(400);
        assert_eq!(f.acr(), 0);
        assert_eq!(f.acr_history().len(), 5);
        // The option-byte registers are not modelled (the programming ones are: flash_prog).
        assert!(f.read(0, 0x08, &mut Signals::default()).is_err());
        assert!(f.read(0, 0x0C, &mut Signals::default()).is_ok());
    }

    #[test]
    fn g474_acr_embassy_modify_keeps_caches() {
        let mut f = FlashG4::new();
        assert_eq!(f.acr(), 0x0004_0600);
        assert!(f.art_enabled() && f.dcache_enabled() && !f.prefetch_enabled());
        // embassy: FLASH.acr().modify(|w| w.set_latency(WS4)).
        let v = (r(&mut f, 0) & !0xF) | 4;
        w(&mut f, 10, 0, v);
        assert_eq!(f.wait_states(), 4);
        assert_eq!(f.acr(), 0x0004_0604);
        assert!(f.art_enabled());
        assert!(f
            .write(0, 0, v | ACR_RUN_PD, 0xFFFF_FFFF, &mut Signals::default())
            .is_err());
    }

    /// embassy rcc/f247.rs: VOS = scale 1, ODEN → wait ODRDY, ODSWEN → wait ODSWRDY; bd.rs DBP.
    #[test]
    fn f446_overdrive_sequence() {
        let mut p = PwrF4::new();
        assert_eq!(r(&mut p, 0), 0xC000);
        assert_eq!(p.vos_scale(), 1);
        let cr = r(&mut p, 0) | (3 << 14);
        w(&mut p, 0, 0, cr);
        w(&mut p, 0, 0, cr | F4_CR_ODEN);
        assert_ne!(r(&mut p, 4) & F4_CSR_ODRDY, 0);
        assert!(!p.overdrive_active());
        w(&mut p, 0, 0, cr | F4_CR_ODEN | F4_CR_ODSWEN);
        assert_ne!(r(&mut p, 4) & F4_CSR_ODSWRDY, 0);
        assert!(p.overdrive_active());
        let v = r(&mut p, 0) | F4_CR_DBP;
        w(&mut p, 0, 0, v);
        assert!(p.dbp());
        assert_ne!(r(&mut p, 0) & F4_CR_DBP, 0);
        // Clearing ODEN drops ODSWEN too.
        let v = r(&mut p, 0) & !F4_CR_ODEN;
        w(&mut p, 0, 0, v);
        assert_eq!(r(&mut p, 0) & (F4_CR_ODEN | F4_CR_ODSWEN), 0);
        assert_eq!(r(&mut p, 4) & (F4_CSR_ODRDY | F4_CSR_ODSWRDY), 0);
        // ODSWEN without ODRDY is reported.
        assert!(p
            .write(
                0,
                0,
                0xC000 | F4_CR_ODSWEN,
                0xFFFF_FFFF,
                &mut Signals::default()
            )
            .is_err());
        p.reset(0);
        assert!(!p.dbp());
    }

    #[test]
    fn g474_pwr_embassy_writes() {
        let mut p = PwrG4::new();
        assert_eq!(p.range(), G4Range::Range1Normal);
        assert!(!p.boost());
        // ucpd init: CR3.UCPD1_DBDIS = 1.
        let v = r(&mut p, 0x08) | (1 << 14);
        w(&mut p, 0, 0x08, v);
        assert_eq!(p.cr3(), 0xC000);
        // bd.rs: DBP.
        let v = r(&mut p, 0x00) | G4_CR1_DBP;
        w(&mut p, 0, 0x00, v);
        assert!(p.dbp());
        // VOS = 00 cannot be written.
        w(&mut p, 0, 0x00, G4_CR1_DBP);
        assert_eq!(r(&mut p, 0x00), 0x0200 | G4_CR1_DBP);
        // Range 2, boost.
        w(&mut p, 0, 0x00, 2 << 9);
        assert_eq!(p.range(), G4Range::Range2);
        w(&mut p, 0, 0x00, 1 << 9);
        w(&mut p, 0, 0x80, 0);
        assert_eq!(p.range(), G4Range::Range1Boost);
        assert_eq!(r(&mut p, 0x14) & (1 << 10), 0); // VOSF
        assert!(p.read(0, 0x20, &mut Signals::default()).is_err());
    }

    #[test]
    fn syscfg_and_exti_report_every_access() {
        let mut s = Syscfg::new();
        assert!(s
            .read(0, 0x08, &mut Signals::default())
            .unwrap_err()
            .why
            .contains("SYSCFG"));
        let mut e = Exti::new();
        assert!(e
            .write(0, 0x00, 1, 0xFFFF_FFFF, &mut Signals::default())
            .unwrap_err()
            .why
            .contains("EXTI"));
    }

    #[test]
    fn dbgmcu_idcodes_and_freeze_bits() {
        let mut f = DbgMcu::new(0x421);
        assert_eq!(r(&mut f, 0) & 0xFFF, 0x421);
        let mut g = DbgMcu::new(0x469);
        assert_eq!(r(&mut g, 0) & 0xFFF, 0x469);
        // embassy init: CR |= DBG_SLEEP | DBG_STOP | DBG_STANDBY.
        let v = r(&mut f, 0x04) | 7;
        w(&mut f, 0, 0x04, v);
        assert!(f.dbg_sleep() && f.dbg_stop() && f.dbg_standby());
        // Firmware fault path: IWDG freeze (APB1_FZ / APB1FZR1 bit 12).
        assert!(!f.iwdg_stop());
        w(&mut f, 0, 0x08, 1 << 12);
        assert!(f.iwdg_stop());
        w(&mut g, 0, 0x08, 1 << 12);
        assert!(g.iwdg_stop());
        // Timer freeze bits: F446 TIM1 in APB2_FZ bit 0, G474 TIM1 in APB2FZR bit 11.
        w(&mut f, 0, 0x0C, 1);
        assert!(f.timer_stop(1) && !f.timer_stop(2));
        w(&mut g, 0, 0x10, 1 << 11);
        w(&mut g, 0, 0x08, (1 << 12) | (1 << 2));
        assert!(g.timer_stop(1) && g.timer_stop(4) && !g.timer_stop(3));
        // Survives a system reset.
        f.reset(0);
        assert!(f.iwdg_stop() && f.dbg_sleep());
        // 32-bit only.
        assert!(f.write(0, 0x08, 0, 0xFF, &mut Signals::default()).is_err());
        assert!(f.read(0, 0x10, &mut Signals::default()).is_err());
    }
}
