//! The flash interface's programming side, for both chips: the unlock keys, FLASH_CR and
//! FLASH_SR, program and erase operations with their durations, the busy time that stalls a
//! fetch from the bank being written, and the end-of-operation interrupt. The memory itself is
//! the machine's: the model says what a store leaves in a cell and which ranges an erase fills
//! with 0xFF (`Prog::store`, `Prog::take_erases`).
//!
//! F446 (RM0390 §3.5 erase and program operations, §3.8 registers; the same interface as RM0090's
//! F405/F429, whose §3.5 the review could read):
//! - KEYR takes 0x4567_0123 then 0xCDEF_89AB to clear CR.LOCK; any other sequence is a bus error
//!   that keeps CR locked until reset (§3.5.1): reported, as the firmware must never do it.
//! - CR: PG, SER, MER, SNB[6:3], PSIZE[9:8], STRT, EOPIE, ERRIE, LOCK. Writes while locked are
//!   ignored; a write while BSY stalls the bus until BSY clears (§3.5.1 note): reported.
//! - Program: with PG set, a store whose size matches PSIZE (else PGPERR) and which does not
//!   cross a 128-bit row (else PGAERR) programs the cell: bits only go 1 → 0 ("successive
//!   writes are possible ... when changing bits from 1 to 0", §3.5.4), i.e. old AND new. A store
//!   to flash without PG sets PGSERR and changes nothing (§3.8 FLASH_SR).
//! - OPERR is not raised (set only with ERRIE on an operation error the model never makes); the
//!   interrupt line follows EOP with EOPIE and the error flags with ERRIE.
//! - Erase: SER with SNB and STRT erases one sector; MER is not modelled.
//! - SR: EOP (set at the end of an operation only when EOPIE = 1), OPERR, WRPERR, PGAERR,
//!   PGPERR, PGSERR (all write 1 to clear), BSY. IRQ: FLASH global interrupt, position 4, when
//!   EOP with EOPIE or an error with ERRIE.
//! - Single bank: while BSY, every fetch from flash waits (§3.5: "any attempt to read the flash
//!   memory ... while it is being written or erased causes the bus to stall").
//!
//! G474 (RM0440 §5.3 operations, §5.7 registers), dual-bank mode (DBANK = 1, the factory
//! setting; FLASH_OPTR reads it):
//! - KEYR as on the F446. CR: PG, PER, MER1, PNB[9:3] (7 bits on the G474), BKER (bit 11), STRT
//!   (bit 16), EOPIE (24), ERRIE (25), OPTLOCK (30), LOCK (31); reset LOCK | OPTLOCK.
//! - Program: 64 bits at a time, two word stores to one 8-aligned double word, the first at
//!   its lower address (§5.3.7); the first is latched and the operation starts with the second.
//!   A double word whose cells are not erased is not programmed and sets PROGERR, unless it is
//!   all zeros (the flash has ECC); a byte or half-word store sets SIZERR; a second word that is
//!   not the latched one's partner sets PGAERR; a store while one of those flags is still set
//!   sets PGSERR, as does a store without PG.
//! - Erase: PER with PNB (page in its bank) and BKER (bank 2), STRT.
//! - SR: EOP, OPERR, PROGERR, WRPERR, PGAERR, SIZERR, PGSERR, MISERR, FASTERR (w1c), BSY.
//! - Read-while-write: an operation on one bank stalls fetches from that bank only (§5.3).
//!
//! F446 ART data cache (RM0390 §3.4.2 "Data management", §3.8.1 FLASH_ACR), in `DataCache`:
//! CPU data reads of flash (literal pools, constants, the store's bytes) go through 8 lines of
//! 128 bits, filled on a miss, least recently used replaced ("works like the instruction cache
//! memory", whose replacement the section names LRU). The cache has no coherency logic with
//! the flash array: an erase leaves a cached line holding the old bytes, which the CPU reads
//! until DCRST empties the cache (DCRST acts only while DCEN = 0; ST's HAL flushes after every
//! erase for this reason, `FLASH_FlushCaches`). While DCEN = 0 reads bypass it (nothing hit,
//! nothing filled); turning DCEN on again without DCRST finds the old lines. A program updates
//! a cached copy of its row (an assumption: the manual says nothing; ST's HAL flushes only after
//! erases, and ST's F4 EEPROM emulation reads back words it just programmed with the cache on).
//! A system reset empties it (an assumption; the firmware resets it at boot anyway). DMA reads
//! of flash do not pass through it. The G474's data cache (RM0440 §5.3.4) is not modelled.
//!
//! G474 ECC (RM0440 §5.3.2 "Error code correction (ECC)", §5.7.7 FLASH_ECCR): every double word
//! carries 8 ECC bits. A double word whose program or erase was cut by a power loss is marked
//! bad (`mark_ecc_bad`; the model's runs never cut power themselves, the checks build such a
//! flash); a CPU data read of it sets ECCR.ECCD with ADDR_ECC (the double word's byte offset in
//! its bank) and BK_ECC, and the NMI is pended (`Prog::ecc_read`). ECCD is write 1 to clear;
//! "set only if ECCC and ECCD were previously cleared": a second error while ECCD stands is not
//! recorded and raises no second NMI (the manual ties the NMI to the flag being set). The marks
//! belong to the array: kept across a system reset, cleared by an erase of their page and by
//! programming the double word to all zeros (a valid code word). Single errors (ECCC) are never
//! made. The F446 has no flash ECC.
//!
//! Durations are the datasheets' typical figures, named here as the model's assumptions (a
//! review against DS10693 / DS12288 is owed): F446 word program 16 µs, 128 KiB sector erase
//! 1 s, 64 KiB 550 ms, 16 KiB 250 ms (×32 parallelism); G474 double-word program 82 µs, 2 KiB
//! page erase 22 ms.

use super::{Time, TICKS_PER_S};

const KEY1: u32 = 0x4567_0123;
const KEY2: u32 = 0xCDEF_89AB;

pub const F4_KEYR: u32 = 0x04;
pub const F4_SR: u32 = 0x0C;
pub const F4_CR: u32 = 0x10;
pub const F4_OPTCR: u32 = 0x14;

pub const G4_KEYR: u32 = 0x08;
pub const G4_SR: u32 = 0x10;
pub const G4_CR: u32 = 0x14;
pub const G4_OPTR: u32 = 0x20;

const SR_EOP: u32 = 1 << 0;
const SR_OPERR: u32 = 1 << 1;
const SR_BSY: u32 = 1 << 16;
// F4 errors (RM0390 §3.8.4).
const F4_SR_ERRORS: u32 = 0xF2;
const F4_PGAERR: u32 = 1 << 5;
const F4_PGPERR: u32 = 1 << 6;
const F4_PGSERR: u32 = 1 << 7;
// G4 errors (RM0440 §5.7.5).
const G4_SR_ERRORS: u32 = 0xC3FA;
const G4_PROGERR: u32 = 1 << 3;
const G4_PGAERR: u32 = 1 << 5;
const G4_SIZERR: u32 = 1 << 6;
const G4_PGSERR: u32 = 1 << 7;
/// PROGERR, WRPERR, PGAERR, SIZERR, MISSERR, FASTERR: flags that block the next program.
const G4_STALE_ERRORS: u32 = G4_PROGERR | (1 << 4) | G4_PGAERR | G4_SIZERR | (1 << 8) | (1 << 9);
/// FLASH_CR reset value on the G474: LOCK and OPTLOCK (RM0440 §5.7.6).
const G4_CR_RESET: u32 = CR_LOCK | (1 << 30);

const CR_PG: u32 = 1 << 0;
const CR_SER_PER: u32 = 1 << 1;
const CR_MER: u32 = 1 << 2;
const CR_STRT: u32 = 1 << 16;
const CR_EOPIE: u32 = 1 << 24;
const CR_ERRIE: u32 = 1 << 25;
const CR_LOCK: u32 = 1 << 31;
const G4_CR_BKER: u32 = 1 << 11;

/// FLASH global interrupt: position 4 on both chips (RM0390 table 38, RM0440 table 97).
pub const FLASH_IRQ: u16 = 4;

/// Which chip's interface.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    F446,
    G474,
}

/// An operation under way: the bank it occupies and when it ends.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Busy {
    until: Time,
    bank: u8,
}

/// One program or erase, as it happened.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Operation {
    pub start: Time,
    pub end: Time,
    pub erase: bool,
    pub addr: u32,
    /// Bytes the operation covers: the erased range, or the programmed unit (F446: the word
    /// PSIZE selects, G474: 8).
    pub bytes: u32,
    /// A program's value as stored (little-endian, `bytes` of it); 0 for an erase. On the F446
    /// the cells become old AND value; on the G474 the value (into erased cells).
    pub value: u64,
}

/// FLASH_ACR bits of the caches, the same on both chips (RM0390 §3.8.1, RM0440 §5.7.1).
pub const ACR_DCEN: u32 = 1 << 10;
pub const ACR_DCRST: u32 = 1 << 12;

/// The F446 ART accelerator's data cache (see the module doc): 8 lines of 128 bits.
#[derive(Clone, Debug, Default)]
pub struct DataCache {
    /// Cached lines (line address, bytes), least recently used first.
    lines: Vec<(u32, [u8; 16])>,
    /// FLASH_ACR.DCEN.
    enabled: bool,
    /// Reads served (DCEN = 1), and of those the ones that returned bytes other than the
    /// array's (a line an erase had changed).
    pub reads: u64,
    pub stale_reads: u64,
}

impl DataCache {
    /// RM0390 §3.4.2: "limited to 8 rows of 128 bits".
    pub const LINES: usize = 8;
    pub const LINE_BYTES: u32 = 16;

    /// A FLASH_ACR value just written: DCEN, and DCRST with DCEN = 0 empties the cache
    /// (RM0390 §3.8.1: DCRST "can be written only when the D cache is disabled"; the flash
    /// interface model refuses it otherwise).
    pub fn on_acr(&mut self, acr: u32) {
        self.enabled = acr & ACR_DCEN != 0;
        if acr & ACR_DCRST != 0 && !self.enabled {
            self.lines.clear();
        }
    }

    pub fn enabled(&self) -> bool {
        self.enabled
    }

    /// A CPU data read touching the line at `line_addr`, whose cells hold `array`: the bytes the
    /// read sees. A hit returns the cached copy (and makes it the most recently used); a miss
    /// fills a line (replacing the least recently used) with the array's bytes. With DCEN = 0
    /// the array's bytes, the cache untouched.
    pub fn read(&mut self, line_addr: u32, array: [u8; 16]) -> [u8; 16] {
        if !self.enabled {
            return array;
        }
        self.reads += 1;
        if let Some(i) = self.lines.iter().position(|l| l.0 == line_addr) {
            let line = self.lines.remove(i);
            self.lines.push(line);
            if line.1 != array {
                self.stale_reads += 1;
            }
            return line.1;
        }
        if self.lines.len() == Self::LINES {
            self.lines.remove(0);
        }
        self.lines.push((line_addr, array));
        array
    }

    /// A program wrote `new` (the cells' content afterwards) at `addr`: a cached copy of its
    /// row follows (see the module doc for why this is assumed).
    pub fn on_program(&mut self, addr: u32, new: &[u8]) {
        for (i, b) in new.iter().enumerate() {
            let a = addr + i as u32;
            let line = a & !(Self::LINE_BYTES - 1);
            if let Some(l) = self.lines.iter_mut().find(|l| l.0 == line) {
                l.1[(a - line) as usize] = *b;
            }
        }
    }
}

/// G474 FLASH_ECCR (RM0440 §5.7.7): offset and fields.
pub const G4_ECCR: u32 = 0x18;
pub const ECCR_ADDR_ECC: u32 = 0x7_FFFF;
pub const ECCR_BK_ECC: u32 = 1 << 21;
pub const ECCR_SYSF_ECC: u32 = 1 << 22;
pub const ECCR_ECCCIE: u32 = 1 << 24;
pub const ECCR_ECCC2: u32 = 1 << 28;
pub const ECCR_ECCD2: u32 = 1 << 29;
pub const ECCR_ECCC: u32 = 1 << 30;
pub const ECCR_ECCD: u32 = 1 << 31;

/// The programming registers and operation state of one chip's flash interface.
#[derive(Clone, Debug)]
pub struct Prog {
    kind: Kind,
    cr: u32,
    sr: u32,
    /// KEYR sequence: 0 nothing, 1 first key seen.
    key_state: u8,
    busy: Option<Busy>,
    /// G474: the first word of a double word waiting for its second (address, value, the cell's
    /// content).
    half: Option<(u32, u32, u32)>,
    erases: Vec<(u32, u32)>,
    ops: Vec<Operation>,
    /// F446: the ART data cache (None on the G474: not modelled).
    dcache: Option<DataCache>,
    /// G474: double words (8-aligned addresses) whose ECC does not match their data.
    ecc_bad: std::collections::BTreeSet<u32>,
    /// G474: FLASH_ECCR.
    eccr: u32,
    /// G474: double ECC errors detected (ECCD set), since construction.
    ecc_detections: u32,
}

fn ticks_us(us: u64) -> Time {
    us * (TICKS_PER_S / 1_000_000)
}

impl Prog {
    pub fn new(kind: Kind) -> Self {
        Prog {
            kind,
            cr: match kind {
                Kind::F446 => CR_LOCK,
                Kind::G474 => G4_CR_RESET,
            },
            sr: 0,
            key_state: 0,
            busy: None,
            half: None,
            erases: Vec::new(),
            ops: Vec::new(),
            dcache: (kind == Kind::F446).then(DataCache::default),
            ecc_bad: Default::default(),
            ecc_detections: 0,
            eccr: 0,
        }
    }

    pub fn reset(&mut self) {
        let ops = std::mem::take(&mut self.ops);
        let ecc_bad = std::mem::take(&mut self.ecc_bad);
        let detections = self.ecc_detections;
        *self = Prog::new(self.kind);
        // An operation cut by the reset is not modelled (the flash's content would be
        // undefined); the history is kept for the checks. ECC marks are the array's: they stay.
        self.ops = ops;
        self.ecc_bad = ecc_bad;
        self.ecc_detections = detections;
    }

    /// A FLASH_ACR value the firmware just wrote (the data cache follows DCEN and DCRST).
    pub fn on_acr(&mut self, acr: u32) {
        if let Some(c) = &mut self.dcache {
            c.on_acr(acr);
        }
    }

    /// The F446's data cache, if this chip's is modelled.
    pub fn data_cache(&mut self) -> Option<&mut DataCache> {
        self.dcache.as_mut()
    }

    /// G474: marks the double word at `addr` (rounded down to 8) as carrying a bad ECC, as a
    /// program or erase cut by a power loss leaves it. Ignored on the F446 (no flash ECC).
    pub fn mark_ecc_bad(&mut self, addr: u32) {
        if self.kind == Kind::G474 {
            self.ecc_bad.insert(addr & !7);
        }
    }

    /// Whether any double word of `addr..addr + bytes` carries a bad ECC.
    pub fn ecc_bad_in(&self, addr: u32, bytes: u32) -> bool {
        self.ecc_bad
            .range(addr & !7..addr.saturating_add(bytes))
            .next()
            .is_some()
    }

    /// A CPU data read of `bytes` at `addr`: true if it hit a double word with a bad ECC and
    /// raised a double ECC error, which pends the NMI (RM0440 §5.7.7 ECCD: "When this bit is
    /// set, a NMI is generated"). ECCR records the first error until ECCD is cleared.
    pub fn ecc_read(&mut self, addr: u32, bytes: u32) -> bool {
        let Some(&dw) = self
            .ecc_bad
            .range(addr & !7..addr.saturating_add(bytes))
            .next()
        else {
            return false;
        };
        if self.eccr & (ECCR_ECCD | ECCR_ECCC) != 0 {
            return false;
        }
        let (base, bk) = if self.bank_of(dw) == 2 {
            (0x0804_0000, ECCR_BK_ECC)
        } else {
            (0x0800_0000, 0)
        };
        self.eccr = (self.eccr & ECCR_ECCCIE) | ECCR_ECCD | bk | ((dw - base) & ECCR_ADDR_ECC);
        self.ecc_detections += 1;
        true
    }

    /// Double ECC errors detected so far (each pended an NMI).
    pub fn ecc_detections(&self) -> u32 {
        self.ecc_detections
    }

    fn bank_of(&self, addr: u32) -> u8 {
        match self.kind {
            Kind::F446 => 1,
            // Dual-bank mode: bank 2 is the upper 256 KiB.
            Kind::G474 => {
                if addr >= 0x0804_0000 {
                    2
                } else {
                    1
                }
            }
        }
    }

    fn errors(&self) -> u32 {
        match self.kind {
            Kind::F446 => F4_SR_ERRORS,
            Kind::G474 => G4_SR_ERRORS,
        }
    }

    /// Ends an operation whose time has come.
    pub fn advance(&mut self, now: Time) {
        if let Some(b) = self.busy {
            if now >= b.until {
                self.busy = None;
                if self.cr & CR_EOPIE != 0 {
                    self.sr |= SR_EOP;
                }
            }
        }
    }

    pub fn next_event(&self) -> Option<Time> {
        self.busy.map(|b| b.until)
    }

    /// Raises the FLASH interrupt when its line is high.
    pub fn irq_lines(&self, raise: &mut dyn FnMut(u16)) {
        if self.irq_line() {
            raise(FLASH_IRQ);
        }
    }

    pub fn irq_line(&self) -> bool {
        (self.sr & SR_EOP != 0 && self.cr & CR_EOPIE != 0)
            || (self.sr & (self.errors() | SR_OPERR) != 0 && self.cr & CR_ERRIE != 0)
    }

    pub fn read(&self, offset: u32) -> Option<u32> {
        let (keyr, sr, cr) = self.offsets();
        match offset {
            o if o == sr => Some(self.sr | if self.busy.is_some() { SR_BSY } else { 0 }),
            o if o == cr => Some(self.cr),
            o if o == keyr => Some(0),
            // F446 FLASH_OPTCR (RM0390 §3.8.6): its reset value 0x0FFF_AAED (no write
            // protection, read protection level 0, BOR off); embassy's F4 driver does not read
            // it on a single-bank chip, kept so a read is not a fault.
            F4_OPTCR if self.kind == Kind::F446 => Some(0x0FFF_AAED),
            // G474 FLASH_OPTR (RM0440 §5.7.8), the factory value 0xFFEF_F8AA: DBANK (bit 22) = 1.
            G4_OPTR if self.kind == Kind::G474 => Some(0xFFEF_F8AA),
            G4_ECCR if self.kind == Kind::G474 => Some(self.eccr),
            _ => None,
        }
    }

    fn offsets(&self) -> (u32, u32, u32) {
        match self.kind {
            Kind::F446 => (F4_KEYR, F4_SR, F4_CR),
            Kind::G474 => (G4_KEYR, G4_SR, G4_CR),
        }
    }

    /// A register write; Ok(false) if the offset is not one of ours, Err for a write the
    /// hardware forbids or the model does not cover.
    pub fn write(&mut self, now: Time, offset: u32, value: u32, mask: u32) -> Result<bool, String> {
        let (keyr, sr, cr) = self.offsets();
        let v = value & mask;
        if offset == keyr {
            match (self.key_state, v) {
                (0, KEY1) => self.key_state = 1,
                (1, KEY2) => {
                    self.key_state = 0;
                    self.cr &= !CR_LOCK;
                }
                _ => {
                    return Err(format!(
                        "FLASH_KEYR: 0x{v:08X} out of the unlock sequence (a bus error that locks FLASH_CR until reset)"
                    ))
                }
            }
            return Ok(true);
        }
        if self.kind == Kind::G474 && offset == G4_ECCR {
            // ECCD, ECCC (and the ECCD2/ECCC2 the model never sets) are write 1 to clear;
            // ECCCIE is read/write; the address fields are read-only (RM0440 §5.7.7).
            let w1c = ECCR_ECCD | ECCR_ECCC | ECCR_ECCD2 | ECCR_ECCC2;
            self.eccr &= !(v & w1c);
            if mask & ECCR_ECCCIE != 0 {
                self.eccr = (self.eccr & !ECCR_ECCCIE) | (v & ECCR_ECCCIE);
            }
            return Ok(true);
        }
        if offset == sr {
            // Error and EOP flags are write 1 to clear.
            self.sr &= !(v & (self.errors() | SR_EOP | SR_OPERR));
            return Ok(true);
        }
        if offset != cr {
            return Ok(false);
        }
        if self.busy.is_some() {
            return Err(
                "FLASH_CR written while BSY (the bus stalls until the operation ends): not modelled"
                    .into(),
            );
        }
        if self.cr & CR_LOCK != 0 {
            // Locked: only LOCK itself is set by writes; the rest is ignored.
            return Ok(true);
        }
        let new = (self.cr & !mask) | v;
        if new & CR_MER != 0 {
            return Err("FLASH_CR.MER (mass erase) is not modelled".into());
        }
        self.cr = new & !CR_STRT;
        if new & CR_STRT != 0 {
            self.start_erase(now, new)?;
        }
        Ok(true)
    }

    fn start_erase(&mut self, now: Time, cr: u32) -> Result<(), String> {
        if cr & CR_SER_PER == 0 {
            return Err("FLASH_CR.STRT without SER/PER: not modelled".into());
        }
        let (addr, bytes, us) = match self.kind {
            Kind::F446 => {
                // SNB[6:3], sectors 0–7 (RM0390 §3.3 table 4).
                let snb = (cr >> 3) & 0xF;
                let (addr, bytes) = match snb {
                    0..=3 => (0x0800_0000 + snb * 0x4000, 0x4000),
                    4 => (0x0801_0000, 0x1_0000),
                    5..=7 => (0x0802_0000 + (snb - 5) * 0x2_0000, 0x2_0000),
                    _ => return Err(format!("FLASH_CR.SNB = {snb}: no such sector on the F446")),
                };
                let us = match bytes {
                    0x4000 => 250_000,
                    0x1_0000 => 550_000,
                    _ => 1_000_000,
                };
                (addr, bytes, us)
            }
            Kind::G474 => {
                // PNB[9:3] (0–127 in a bank of dual-bank mode), BKER bit 11.
                let pnb = (cr >> 3) & 0x7F;
                if pnb > 127 {
                    return Err(format!(
                        "FLASH_CR.PNB = {pnb}: a bank has 128 pages in dual-bank mode"
                    ));
                }
                let bank_base = if cr & G4_CR_BKER != 0 {
                    0x0804_0000
                } else {
                    0x0800_0000
                };
                (bank_base + pnb * 0x800, 0x800, 22_000)
            }
        };
        let end = now + ticks_us(us);
        self.busy = Some(Busy {
            until: end,
            bank: self.bank_of(addr),
        });
        self.erases.push((addr, bytes));
        // An erase gives every double word of its range a valid code word again.
        let marked: Vec<u32> = self.ecc_bad.range(addr..addr + bytes).copied().collect();
        for a in marked {
            self.ecc_bad.remove(&a);
        }
        self.ops.push(Operation {
            start: now,
            end,
            erase: true,
            addr,
            bytes,
            value: 0,
        });
        Ok(())
    }

    fn program_error(&mut self, flag: u32) -> Result<Vec<(u32, u32)>, String> {
        self.sr |= flag;
        self.half = None;
        Ok(Vec::new())
    }

    /// A CPU store of `size` bytes of `value` at flash address `addr`, whose cells hold `old`
    /// (little-endian). Returns the words it programs (address, new content): none for a word
    /// the G474 only latches or a store refused with an error flag. Err stops the run (a store
    /// the model does not cover).
    pub fn store(
        &mut self,
        now: Time,
        addr: u32,
        size: u8,
        value: u32,
        old: u32,
    ) -> Result<Vec<(u32, u32)>, String> {
        if self.busy.is_some() {
            return Err(format!(
                "store to flash at 0x{addr:08X} while an operation is under way (the bus stalls): not modelled"
            ));
        }
        if self.cr & CR_PG == 0 || self.cr & CR_LOCK != 0 {
            let flag = match self.kind {
                Kind::F446 => F4_PGSERR,
                Kind::G474 => G4_PGSERR,
            };
            return self.program_error(flag);
        }
        match self.kind {
            Kind::F446 => {
                // PSIZE: 0 = x8, 1 = x16, 2 = x32, 3 = x64.
                let psize = (self.cr >> 8) & 3;
                if psize == 3 || u32::from(size) != 1 << psize {
                    return self.program_error(F4_PGPERR);
                }
                if (addr % 16) + u32::from(size) > 16 || !addr.is_multiple_of(u32::from(size)) {
                    return self.program_error(F4_PGAERR);
                }
                let end = now + ticks_us(16);
                self.busy = Some(Busy {
                    until: end,
                    bank: 1,
                });
                self.ops.push(Operation {
                    start: now,
                    end,
                    erase: false,
                    addr,
                    bytes: u32::from(size),
                    value: u64::from(value),
                });
                let new = old & value;
                if let Some(c) = &mut self.dcache {
                    c.on_program(addr, &new.to_le_bytes()[..usize::from(size)]);
                }
                Ok(vec![(addr, new)])
            }
            Kind::G474 => {
                // An error flag left from an earlier program blocks the next: PGSERR (RM0440
                // §5.7.5: "set ... when PROGERR, SIZERR, PGAERR, WRPERR, MISSERR or FASTERR is set
                // due to a previous programming error").
                if self.sr & G4_STALE_ERRORS != 0 {
                    return self.program_error(G4_PGSERR);
                }
                // Only word accesses make up a double word: a byte or half-word is SIZERR.
                if size != 4 {
                    return self.program_error(G4_SIZERR);
                }
                match self.half.take() {
                    // The first word is latched; nothing is programmed until the second.
                    None if addr.is_multiple_of(8) => {
                        self.half = Some((addr, value, old));
                        Ok(Vec::new())
                    }
                    Some((first, first_value, first_old)) if addr == first + 4 => {
                        // ECC: a double word is programmed only into erased cells, except all
                        // zeros, which may be written over anything (RM0440 §5.7.5, PROGERR).
                        // A double word with a bad ECC is not erased, whatever its data bits read.
                        let erased = first_old == 0xFFFF_FFFF
                            && old == 0xFFFF_FFFF
                            && !self.ecc_bad.contains(&first);
                        if !erased && (first_value, value) != (0, 0) {
                            return self.program_error(G4_PROGERR);
                        }
                        // Programmed: into erased cells (never marked), or all zeros, a valid
                        // code word over anything: the double word's ECC is good either way.
                        self.ecc_bad.remove(&first);
                        let end = now + ticks_us(82);
                        self.busy = Some(Busy {
                            until: end,
                            bank: self.bank_of(addr),
                        });
                        self.ops.push(Operation {
                            start: now,
                            end,
                            erase: false,
                            addr: first,
                            bytes: 8,
                            value: u64::from(first_value) | u64::from(value) << 32,
                        });
                        Ok(vec![(first, first_value), (addr, value)])
                    }
                    // Not the second half of the latched double word: PGAERR.
                    _ => self.program_error(G4_PGAERR),
                }
            }
        }
    }
    /// Ranges (address, bytes) an erase has started on since the last call: the machine fills
    /// them with 0xFF (their content during the erase is unreadable anyway: fetches stall).
    pub fn take_erases(&mut self) -> Vec<(u32, u32)> {
        std::mem::take(&mut self.erases)
    }

    /// Until when a fetch or read from `addr` at `now` waits (an operation on its bank).
    pub fn stall_until(&self, now: Time, addr: u32) -> Option<Time> {
        let b = self.busy?;
        (b.until > now && b.bank == self.bank_of(addr)).then_some(b.until)
    }

    /// Every operation so far, for the checks.
    pub fn operations(&self) -> &[Operation] {
        &self.ops
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unlocked(kind: Kind) -> Prog {
        let mut p = Prog::new(kind);
        let keyr = p.offsets().0;
        p.write(0, keyr, KEY1, !0).unwrap();
        p.write(0, keyr, KEY2, !0).unwrap();
        p
    }

    #[test]
    fn locked_at_reset_and_unlocked_only_by_the_two_keys_in_order() {
        let mut p = Prog::new(Kind::F446);
        assert_eq!(p.read(F4_CR), Some(CR_LOCK));
        // A CR write while locked changes nothing.
        p.write(0, F4_CR, CR_PG, !0).unwrap();
        assert_eq!(p.read(F4_CR), Some(CR_LOCK));
        assert!(p.write(0, F4_KEYR, KEY2, !0).is_err());
        let p = unlocked(Kind::F446);
        assert_eq!(p.read(F4_CR), Some(0));
    }

    #[test]
    fn f446_word_program_ands_bits_and_is_busy_16_us() {
        let mut p = unlocked(Kind::F446);
        p.write(0, F4_CR, CR_PG | (2 << 8), !0).unwrap();
        assert_eq!(
            p.store(100, 0x0804_0000, 4, 0x1234_5678, !0).unwrap(),
            vec![(0x0804_0000, 0x1234_5678)]
        );
        assert_eq!(p.read(F4_SR).unwrap() & SR_BSY, SR_BSY);
        // Every fetch stalls: one bank.
        assert_eq!(p.stall_until(100, 0x0800_0100), Some(100 + ticks_us(16)));
        p.advance(100 + ticks_us(16));
        assert_eq!(p.read(F4_SR).unwrap() & SR_BSY, 0);
        // Programming over programmed bits only clears more (1 → 0).
        assert_eq!(
            p.store(200, 0x0804_0000, 4, 0xFF00_FF00, 0x1234_5678)
                .unwrap(),
            vec![(0x0804_0000, 0x1200_5600)]
        );
    }

    #[test]
    fn f446_program_errors_leave_the_cells() {
        let mut p = unlocked(Kind::F446);
        // No PG: PGSERR.
        assert_eq!(p.store(0, 0x0804_0000, 4, 0, !0).unwrap(), vec![]);
        assert_ne!(p.read(F4_SR).unwrap() & F4_PGSERR, 0);
        p.write(0, F4_SR, F4_PGSERR, !0).unwrap();
        // x32 with a byte store: PGPERR.
        p.write(0, F4_CR, CR_PG | (2 << 8), !0).unwrap();
        assert_eq!(p.store(0, 0x0804_0000, 1, 0, 0xFF).unwrap(), vec![]);
        assert_ne!(p.read(F4_SR).unwrap() & F4_PGPERR, 0);
    }

    #[test]
    fn f446_sector_erase_takes_a_second_and_raises_eop_only_with_eopie() {
        let mut p = unlocked(Kind::F446);
        p.write(0, F4_CR, CR_SER_PER | (6 << 3), !0).unwrap();
        p.write(10, F4_CR, CR_STRT, CR_STRT).unwrap();
        assert_eq!(p.take_erases(), vec![(0x0804_0000, 0x2_0000)]);
        assert_eq!(p.next_event(), Some(10 + TICKS_PER_S));
        p.advance(10 + TICKS_PER_S);
        assert_eq!(p.read(F4_SR).unwrap() & (SR_BSY | SR_EOP), 0);
        assert!(!p.irq_line());
        p.write(0, F4_CR, CR_EOPIE | CR_STRT, CR_EOPIE | CR_STRT)
            .unwrap();
        p.advance(u64::MAX);
        assert!(p.irq_line());
        p.write(0, F4_SR, SR_EOP, !0).unwrap();
        assert!(!p.irq_line());
    }

    #[test]
    fn g474_double_word_program_needs_erased_cells_and_stalls_only_its_bank() {
        let mut p = unlocked(Kind::G474);
        assert_eq!(Prog::new(Kind::G474).read(G4_CR), Some(G4_CR_RESET));
        p.write(0, G4_CR, CR_PG, !0).unwrap();
        // The first word only latches: no cell changes, nothing busy.
        assert_eq!(p.store(0, 0x0807_C000, 4, 1, !0).unwrap(), vec![]);
        assert_eq!(p.read(G4_SR).unwrap() & SR_BSY, 0);
        assert_eq!(
            p.store(0, 0x0807_C004, 4, 2, !0).unwrap(),
            vec![(0x0807_C000, 1), (0x0807_C004, 2)]
        );
        assert_eq!(p.read(G4_SR).unwrap() & SR_BSY, SR_BSY);
        assert_eq!(p.stall_until(0, 0x0800_1000), None, "bank 1 reads on");
        assert!(p.stall_until(0, 0x0807_0000).is_some());
        p.advance(u64::MAX);
        // All zeros may be written over programmed cells (ECC allows it).
        assert_eq!(p.store(0, 0x0807_C000, 4, 0, 1).unwrap(), vec![]);
        assert_eq!(
            p.store(0, 0x0807_C004, 4, 0, 2).unwrap(),
            vec![(0x0807_C000, 0), (0x0807_C004, 0)]
        );
        p.advance(u64::MAX);
        // Anything else over programmed cells: PROGERR, nothing programmed, not even the first
        // word.
        assert_eq!(p.store(0, 0x0807_C008, 4, 5, !0).unwrap(), vec![]);
        assert_eq!(p.store(0, 0x0807_C00C, 4, 6, 7).unwrap(), vec![]);
        assert_ne!(p.read(G4_SR).unwrap() & G4_PROGERR, 0);
        // While PROGERR stands, the next program is refused with PGSERR.
        assert_eq!(p.store(0, 0x0807_C010, 4, 5, !0).unwrap(), vec![]);
        assert_ne!(p.read(G4_SR).unwrap() & G4_PGSERR, 0);
        p.write(0, G4_SR, G4_PROGERR | G4_PGSERR, !0).unwrap();
        // A half-word store: SIZERR; a second word that is not the partner: PGAERR.
        assert_eq!(p.store(0, 0x0807_C010, 2, 5, !0).unwrap(), vec![]);
        assert_ne!(p.read(G4_SR).unwrap() & G4_SIZERR, 0);
        p.write(0, G4_SR, G4_SIZERR, !0).unwrap();
        assert_eq!(p.store(0, 0x0807_C010, 4, 5, !0).unwrap(), vec![]);
        assert_eq!(p.store(0, 0x0807_C018, 4, 5, !0).unwrap(), vec![]);
        assert_ne!(p.read(G4_SR).unwrap() & G4_PGAERR, 0);
    }

    #[test]
    fn g474_page_erase_in_bank_2_and_dbank_set() {
        let mut p = unlocked(Kind::G474);
        assert_ne!(p.read(G4_OPTR).unwrap() & (1 << 22), 0);
        p.write(0, G4_CR, CR_SER_PER | (120 << 3) | G4_CR_BKER | CR_STRT, !0)
            .unwrap();
        assert_eq!(p.take_erases(), vec![(0x0807_C000, 0x800)]);
        assert_eq!(p.next_event(), Some(ticks_us(22_000)));
    }

    /// RM0390 §3.4.2: lines filled on read and kept by an erase, so the CPU reads the erased
    /// row's old bytes; DCRST with DCEN = 0 empties the cache (§3.8.1), after which the row
    /// reads 0xFF. Turning DCEN off and on without DCRST keeps the stale line.
    #[test]
    fn f446_data_cache_is_stale_after_an_erase_until_dcrst() {
        let line = 0x0804_0000;
        let mut c = DataCache::default();
        c.on_acr(ACR_DCEN);
        assert_eq!(
            c.read(line, [0x11; 16]),
            [0x11; 16],
            "a miss reads the array"
        );
        // The sector erased: the array now holds 0xFF, the cache its copy.
        assert_eq!(
            c.read(line, [0xFF; 16]),
            [0x11; 16],
            "stale after the erase"
        );
        c.on_acr(0);
        assert_eq!(c.read(line, [0xFF; 16]), [0xFF; 16], "DCEN = 0 bypasses");
        c.on_acr(ACR_DCEN);
        assert_eq!(
            c.read(line, [0xFF; 16]),
            [0x11; 16],
            "re-enabled without DCRST"
        );
        // The flush as RM0390 §3.8.1 allows it: DCEN off, DCRST set and cleared, DCEN on.
        c.on_acr(0);
        c.on_acr(ACR_DCRST);
        c.on_acr(0);
        c.on_acr(ACR_DCEN);
        assert_eq!(c.read(line, [0xFF; 16]), [0xFF; 16], "fresh after DCRST");
    }

    /// Eight lines, least recently used replaced: a ninth line read evicts the oldest, which then
    /// reads the array again; one read just before stays.
    #[test]
    fn f446_data_cache_holds_eight_lines_and_replaces_the_least_recently_used() {
        let mut c = DataCache::default();
        c.on_acr(ACR_DCEN);
        for i in 0..8u32 {
            c.read(0x0800_0000 + 16 * i, [i as u8; 16]);
        }
        // Line 0 used again: line 1 is now the least recently used.
        assert_eq!(c.read(0x0800_0000, [0xEE; 16]), [0; 16]);
        c.read(0x0800_1000, [0x99; 16]);
        assert_eq!(
            c.read(0x0800_0010, [0xEE; 16]),
            [0xEE; 16],
            "line 1 evicted"
        );
        assert_eq!(c.read(0x0800_0000, [0xEE; 16]), [0; 16], "line 0 kept");
        // DCEN = 0: nothing is filled.
        c.on_acr(0);
        c.read(0x0800_2000, [0x55; 16]);
        c.on_acr(ACR_DCEN);
        assert_eq!(c.read(0x0800_2000, [0x66; 16]), [0x66; 16]);
    }

    /// A program through the interface updates a cached copy of its row (the model's
    /// assumption, see the module doc): the word reads back as programmed.
    #[test]
    fn f446_program_updates_the_cached_row() {
        let mut p = unlocked(Kind::F446);
        p.on_acr(ACR_DCEN | 5);
        let line = 0x0804_0010;
        p.data_cache().unwrap().read(line, [0xFF; 16]);
        p.write(0, F4_CR, CR_PG | (2 << 8), !0).unwrap();
        p.store(0, 0x0804_0014, 4, 0x1234_5678, !0).unwrap();
        let mut want = [0xFF; 16];
        want[4..8].copy_from_slice(&[0x78, 0x56, 0x34, 0x12]);
        assert_eq!(p.data_cache().unwrap().read(line, [0xAA; 16]), want);
        assert!(Prog::new(Kind::G474).data_cache().is_none());
    }

    /// RM0440 §5.7.7: a read of a double word with a bad ECC sets ECCD, BK_ECC and ADDR_ECC (its
    /// offset in bank 2: 0x0807_C008 − 0x0804_0000 = 0x3_C008) and raises the NMI once; a second
    /// error while ECCD stands records nothing; ECCD is write 1 to clear; the mark survives a
    /// reset and goes with an erase of its page or a program of zeros.
    #[test]
    fn g474_a_read_of_a_bad_ecc_double_word_sets_eccd_once_until_cleared() {
        let mut p = unlocked(Kind::G474);
        p.mark_ecc_bad(0x0807_C00C);
        assert!(
            !p.ecc_read(0x0807_C004, 4),
            "the double word before is good"
        );
        assert!(p.ecc_read(0x0807_C00C, 4));
        assert_eq!(p.read(G4_ECCR), Some(0x8023_C008));
        assert!(!p.ecc_read(0x0807_C008, 1), "ECCD still set: no second NMI");
        assert_eq!(p.ecc_detections(), 1);
        // Writing 0 changes nothing; writing 1 to ECCD clears it.
        p.write(0, G4_ECCR, 0, !0).unwrap();
        assert_eq!(p.read(G4_ECCR).unwrap() & ECCR_ECCD, ECCR_ECCD);
        p.write(0, G4_ECCR, ECCR_ECCD, !0).unwrap();
        assert_eq!(p.read(G4_ECCR).unwrap() & ECCR_ECCD, 0);
        // The mark is the array's: still there after a reset (ECCR back to 0).
        p.reset();
        assert_eq!(p.read(G4_ECCR), Some(0));
        assert!(p.ecc_read(0x0807_C008, 8));
        p.write(0, G4_ECCR, ECCR_ECCD, !0).unwrap();
        // Not erased: a program of data is refused (PROGERR); zeros are a valid code word.
        let mut p2 = unlocked(Kind::G474);
        p2.mark_ecc_bad(0x0807_C008);
        p2.write(0, G4_CR, CR_PG, !0).unwrap();
        p2.store(0, 0x0807_C008, 4, 5, !0).unwrap();
        p2.store(0, 0x0807_C00C, 4, 6, !0).unwrap();
        assert_ne!(p2.read(G4_SR).unwrap() & G4_PROGERR, 0);
        p2.write(0, G4_SR, G4_PROGERR, !0).unwrap();
        p2.store(0, 0x0807_C008, 4, 0, !0).unwrap();
        p2.store(0, 0x0807_C00C, 4, 0, !0).unwrap();
        assert!(!p2.ecc_bad_in(0x0807_C008, 8), "zeros programmed: good ECC");
        // An erase of the page (bank 2, page 120 = 0x0807_C000) clears its marks (CR locked
        // again by the reset: unlocked first).
        p.write(0, G4_KEYR, KEY1, !0).unwrap();
        p.write(0, G4_KEYR, KEY2, !0).unwrap();
        p.write(0, G4_CR, CR_SER_PER | (120 << 3) | G4_CR_BKER | CR_STRT, !0)
            .unwrap();
        assert!(!p.ecc_read(0x0807_C008, 8));
        // The F446 has no flash ECC.
        let mut f = Prog::new(Kind::F446);
        f.mark_ecc_bad(0x0804_0000);
        assert!(!f.ecc_read(0x0804_0000, 4));
    }
}
