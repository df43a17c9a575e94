//! One GPIO port (GPIOA, GPIOB, …): mode, output type, speed, pull, alternate-function
//! registers, ODR with its atomic set/reset registers (BSRR, G4 BRR), the LCKR lock sequence,
//! and IDR computed from what drives each pin (RM0390 §7 for the STM32F446, RM0440 §9 for the
//! STM32G474).
//!
//! What embassy-stm32 0.6 and the firmware do with it: `Output::new` (BSRR, PUPDR, OTYPER,
//! OSPEEDR, MODER by read-modify-write), `PwmPin::new` (BSRR, AFRL/AFRH, PUPDR, OTYPER,
//! OSPEEDR, MODER), ADC pins to analog (MODER, PUPDR), `set_high/low` (BSRR), the panic path
//! (BSRR, MODER). Nothing reads IDR.
//!
//! Pin levels that come from outside the port are the board's to tell: `set_input_level` for
//! an external driver, `set_alternate_level` for the peripheral output behind an alternate
//! function (a timer channel). An IDR read of a pin whose level nobody defined (floating input
//! without pull) is reported as `Unmodelled` rather than invented.

use super::{merge, Peripheral, Signals, Time, Unmodelled};
use std::any::Any;

/// Which chip's GPIO: the register sets are the same except G4's BRR, but reset values differ.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Chip {
    F446,
    G474,
}

/// What a pin is configured as (MODER, with ODR or AFR for the details).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PinMode {
    Input,
    /// General-purpose output; `high` is the ODR bit (for open-drain, high = released).
    Output {
        high: bool,
    },
    /// Alternate function number (AFRL/AFRH, 0..=15).
    Alternate(u8),
    Analog,
}

const OFF_MODER: u32 = 0x00;
const OFF_OTYPER: u32 = 0x04;
const OFF_OSPEEDR: u32 = 0x08;
const OFF_PUPDR: u32 = 0x0C;
const OFF_IDR: u32 = 0x10;
const OFF_ODR: u32 = 0x14;
const OFF_BSRR: u32 = 0x18;
const OFF_LCKR: u32 = 0x1C;
const OFF_AFRL: u32 = 0x20;
const OFF_AFRH: u32 = 0x24;
const OFF_BRR: u32 = 0x28;

const LCKK: u32 = 1 << 16;

/// One GPIO port.
#[derive(Clone, Debug)]
pub struct Gpio {
    chip: Chip,
    port: char,
    moder: u32,
    otyper: u32,
    ospeedr: u32,
    pupdr: u32,
    odr: u32,
    afr: [u32; 2],
    /// LCKR[15:0] as written.
    lck: u32,
    /// LCKK: configuration frozen until reset (RM0390 §7.4.8).
    locked: bool,
    /// Progress through the lock key sequence: 0 idle, 1..=3 writes done (3 = waiting for the
    /// read that activates the lock), with the LCK value the sequence started with.
    lock_step: u8,
    lock_value: u32,
    /// Level driven from outside on each pin (None: nothing drives it).
    ext_in: [Option<bool>; 16],
    /// Level of the peripheral output routed by the alternate function (None: unknown).
    af_level: [Option<bool>; 16],
}

impl Gpio {
    /// Port `port` ('A'..='H' on the F446, 'A'..='G' on the G474) at its reset state.
    pub fn new(chip: Chip, port: char) -> Self {
        let last = match chip {
            Chip::F446 => 'H',
            Chip::G474 => 'G',
        };
        assert!(
            ('A'..=last).contains(&port),
            "{chip:?} has no GPIO port {port}"
        );
        let mut g = Gpio {
            chip,
            port,
            moder: 0,
            otyper: 0,
            ospeedr: 0,
            pupdr: 0,
            odr: 0,
            afr: [0; 2],
            lck: 0,
            locked: false,
            lock_step: 0,
            lock_value: 0,
            ext_in: [None; 16],
            af_level: [None; 16],
        };
        g.reset_registers();
        g
    }

    /// Reset values (RM0390 §7.4.1–7.4.4, RM0440 §9.4.1–9.4.4): the debug pins PA13 (SWDIO,
    /// pull-up), PA14 (SWCLK, pull-down), PA15 (JTDI, pull-up), PB3 (JTDO/SWO) and PB4 (NJTRST,
    /// pull-up) start in alternate function 0; on the G474 every other pin starts analog, on the
    /// F446 as input.
    fn reset_registers(&mut self) {
        let (moder, ospeedr, pupdr) = match (self.chip, self.port) {
            // GPIOA_OSPEEDR 0x0C00_0000 (PA13 very high speed) per RM0390 §7.4.3; ST's
            // STM32F446 SVD gives 0 for port A, the manual is followed.
            (Chip::F446, 'A') => (0xA800_0000, 0x0C00_0000, 0x6400_0000),
            (Chip::F446, 'B') => (0x0000_0280, 0x0000_00C0, 0x0000_0100),
            (Chip::F446, _) => (0, 0, 0),
            (Chip::G474, 'A') => (0xABFF_FFFF, 0x0C00_0000, 0x6400_0000),
            // GPIOB_OSPEEDR: 0xC0 (PB3 very high speed) as in ST's STM32G474 SVD; the author is
            // not certain RM0440 §9.4.3 lists it for port B as well.
            (Chip::G474, 'B') => (0xFFFF_FEBF, 0x0000_00C0, 0x0000_0100),
            (Chip::G474, _) => (0xFFFF_FFFF, 0, 0),
        };
        self.moder = moder;
        self.ospeedr = ospeedr;
        self.pupdr = pupdr;
        self.otyper = 0;
        self.odr = 0;
        self.afr = [0; 2];
        self.lck = 0;
        self.locked = false;
        self.lock_step = 0;
        self.lock_value = 0;
    }

    pub fn port(&self) -> char {
        self.port
    }

    /// How `pin` (0..=15) is configured.
    pub fn pin_mode(&self, pin: u8) -> PinMode {
        let n = (pin & 15) as u32;
        match (self.moder >> (2 * n)) & 3 {
            0 => PinMode::Input,
            1 => PinMode::Output {
                high: self.odr & (1 << n) != 0,
            },
            2 => PinMode::Alternate(self.af(n)),
            _ => PinMode::Analog,
        }
    }

    /// OTYPER: the pin's output stage is open-drain.
    pub fn is_open_drain(&self, pin: u8) -> bool {
        self.otyper & (1 << (pin & 15)) != 0
    }

    /// The ODR register.
    pub fn odr(&self) -> u32 {
        self.odr
    }

    /// The configuration is locked by the LCKR sequence.
    pub fn is_locked(&self) -> bool {
        self.locked
    }

    /// Level the port itself drives on `pin`: Some for a push-pull output (ODR) and for an
    /// open-drain output pulling low; for an alternate-function output the level the board set
    /// with `set_alternate_level` (open-drain: only its low level); None when the port does not
    /// drive the pin.
    pub fn driven_level(&self, pin: u8) -> Option<bool> {
        let n = (pin & 15) as usize;
        let od = self.is_open_drain(pin);
        let level = match self.pin_mode(pin) {
            PinMode::Output { high } => Some(high),
            PinMode::Alternate(_) => self.af_level[n],
            _ => None,
        }?;
        if od && level {
            None
        } else {
            Some(level)
        }
    }

    /// An external circuit drives `pin` to `level` (None: released).
    pub fn set_input_level(&mut self, pin: u8, level: Option<bool>) {
        self.ext_in[(pin & 15) as usize] = level;
    }

    /// The peripheral output behind `pin`'s alternate function is at `level` (the board routes
    /// timer channel levels here only when `pin_mode` is the channel's alternate function).
    pub fn set_alternate_level(&mut self, pin: u8, level: Option<bool>) {
        self.af_level[(pin & 15) as usize] = level;
    }

    fn af(&self, n: u32) -> u8 {
        ((self.afr[(n / 8) as usize] >> (4 * (n % 8))) & 0xF) as u8
    }

    fn pull(&self, n: u32) -> Option<bool> {
        // PUPDR: 01 pull-up, 10 pull-down, 00/11 none (11 is reserved).
        match (self.pupdr >> (2 * n)) & 3 {
            1 => Some(true),
            2 => Some(false),
            _ => None,
        }
    }

    /// The input data bit of pin `n` (RM0390 §7.3.9–7.3.12): the Schmitt trigger samples the
    /// pad; in analog mode it is off and reads 0.
    fn input_bit(&self, n: u32) -> Result<bool, String> {
        let pin = n as u8;
        if self.pin_mode(pin) == PinMode::Analog {
            return Ok(false);
        }
        if let Some(level) = self.driven_level(pin) {
            return Ok(level);
        }
        if let Some(level) = self.ext_in[n as usize] {
            return Ok(level);
        }
        if let Some(level) = self.pull(n) {
            return Ok(level);
        }
        Err(format!(
            "GPIO{}_IDR bit {n}: P{}{n} floats (no driver, no pull) and its level is not modelled",
            self.port, self.port
        ))
    }

    fn idr(&self) -> Result<u32, String> {
        let mut v = 0;
        for n in 0..16 {
            if self.input_bit(n)? {
                v |= 1 << n;
            }
        }
        Ok(v)
    }

    /// Bits of a 2-bit-per-pin register that the lock freezes.
    fn locked_mask2(&self) -> u32 {
        if !self.locked {
            return 0;
        }
        (0..16)
            .filter(|n| self.lck & (1 << n) != 0)
            .fold(0, |m, n| m | (3 << (2 * n)))
    }

    /// Bits of AFRL (`half` 0) or AFRH (1) that the lock freezes.
    fn locked_mask_afr(&self, half: u32) -> u32 {
        if !self.locked {
            return 0;
        }
        (0..8)
            .filter(|i| self.lck & (1 << (8 * half + i)) != 0)
            .fold(0, |m, i| m | (0xF << (4 * i)))
    }

    /// Atomic set/reset (RM0390 §7.4.7 BSRR: "If both BSx and BRx are set, BSx has priority";
    /// RM0440 §9.4.7 the same).
    fn set_reset(&mut self, set: u32, reset: u32) {
        self.odr = ((self.odr & !reset) | set) & 0xFFFF;
    }

    fn lckr_write(&mut self, value: u32, mask: u32) -> Result<(), Unmodelled> {
        if self.locked {
            // RM0390 §7.4.8: LCKR is frozen until the next reset.
            return Ok(());
        }
        if mask != 0xFFFF_FFFF {
            // RM0390 §7.4.8 note: the sequence needs LCKK and LCK[15:0] in one word write.
            return Err(Unmodelled::write(
                OFF_LCKR,
                value,
                format!(
                    "GPIO{}_LCKR sub-word write: the lock sequence is defined for word writes only",
                    self.port
                ),
            ));
        }
        let lck = value & 0xFFFF;
        let key = value & LCKK != 0;
        // WR LCKK=1+LCK, WR LCKK=0+LCK, WR LCKK=1+LCK, RD: LCK must not change; any other
        // write aborts the sequence.
        self.lock_step = match (self.lock_step, key) {
            (0, true) => 1,
            (1, false) if lck == self.lock_value => 2,
            (2, true) if lck == self.lock_value => 3,
            (_, true) => 1,
            _ => 0,
        };
        self.lock_value = lck;
        self.lck = lck;
        Ok(())
    }
}

impl Peripheral for Gpio {
    fn name(&self) -> &'static str {
        const NAMES: [&str; 8] = [
            "GPIOA", "GPIOB", "GPIOC", "GPIOD", "GPIOE", "GPIOF", "GPIOG", "GPIOH",
        ];
        NAMES[(self.port as u8 - b'A') as usize]
    }

    fn read(&mut self, _now: Time, offset: u32, _out: &mut Signals) -> Result<u32, Unmodelled> {
        match offset {
            OFF_MODER => Ok(self.moder),
            OFF_OTYPER => Ok(self.otyper),
            OFF_OSPEEDR => Ok(self.ospeedr),
            OFF_PUPDR => Ok(self.pupdr),
            OFF_IDR => self.idr().map_err(|why| Unmodelled::read(offset, why)),
            OFF_ODR => Ok(self.odr),
            // Write-only, reads 0 (RM0390 §7.4.7, RM0440 §9.4.7 / §9.4.12).
            OFF_BSRR => Ok(0),
            OFF_BRR if self.chip == Chip::G474 => Ok(0),
            OFF_LCKR => {
                if self.lock_step == 3 {
                    // The read that completes the lock key sequence.
                    self.locked = true;
                    self.lock_step = 0;
                }
                Ok(self.lck | if self.locked { LCKK } else { 0 })
            }
            OFF_AFRL => Ok(self.afr[0]),
            OFF_AFRH => Ok(self.afr[1]),
            _ => Err(Unmodelled::read(
                offset,
                format!(
                    "GPIO{} register at offset {offset:#x} does not exist",
                    self.port
                ),
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
            OFF_MODER => {
                let m = mask & !self.locked_mask2();
                self.moder = merge(self.moder, value, m);
            }
            OFF_OTYPER => {
                let lock = if self.locked { self.lck } else { 0 };
                self.otyper = merge(self.otyper, value, mask & 0xFFFF & !lock);
            }
            OFF_OSPEEDR => {
                let m = mask & !self.locked_mask2();
                self.ospeedr = merge(self.ospeedr, value, m);
            }
            OFF_PUPDR => {
                let m = mask & !self.locked_mask2();
                self.pupdr = merge(self.pupdr, value, m);
            }
            OFF_IDR => {
                return Err(Unmodelled::write(
                    offset,
                    value,
                    format!("GPIO{}_IDR is read-only", self.port),
                ))
            }
            OFF_ODR => self.odr = merge(self.odr, value, mask & 0xFFFF),
            OFF_BSRR => {
                let v = value & mask;
                self.set_reset(v & 0xFFFF, v >> 16);
            }
            OFF_BRR if self.chip == Chip::G474 => {
                let v = value & mask;
                self.set_reset(0, v & 0xFFFF);
            }
            OFF_LCKR => self.lckr_write(value, mask)?,
            OFF_AFRL => {
                let m = mask & !self.locked_mask_afr(0);
                self.afr[0] = merge(self.afr[0], value, m);
            }
            OFF_AFRH => {
                let m = mask & !self.locked_mask_afr(1);
                self.afr[1] = merge(self.afr[1], value, m);
            }
            _ => {
                return Err(Unmodelled::write(
                    offset,
                    value,
                    format!(
                        "GPIO{} register at offset {offset:#x} does not exist",
                        self.port
                    ),
                ))
            }
        }
        Ok(())
    }

    /// System reset or the port's RCC reset bit: registers back to reset values. External and
    /// alternate-function levels belong to the outside world and stay.
    fn reset(&mut self, _now: Time) {
        self.reset_registers();
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

    fn w(g: &mut Gpio, off: u32, v: u32) {
        g.write(0, off, v, 0xFFFF_FFFF, &mut Signals::default())
            .unwrap();
    }
    fn r(g: &mut Gpio, off: u32) -> u32 {
        g.read(0, off, &mut Signals::default()).unwrap()
    }

    #[test]
    fn f446_reset_values_and_debug_pins() {
        let mut a = Gpio::new(Chip::F446, 'A');
        assert_eq!(r(&mut a, OFF_MODER), 0xA800_0000);
        assert_eq!(r(&mut a, OFF_OSPEEDR), 0x0C00_0000);
        assert_eq!(r(&mut a, OFF_PUPDR), 0x6400_0000);
        assert_eq!(a.pin_mode(13), PinMode::Alternate(0));
        assert_eq!(a.pin_mode(14), PinMode::Alternate(0));
        assert_eq!(a.pin_mode(15), PinMode::Alternate(0));
        assert_eq!(a.pin_mode(0), PinMode::Input);
        let mut b = Gpio::new(Chip::F446, 'B');
        assert_eq!(r(&mut b, OFF_MODER), 0x0000_0280);
        assert_eq!(r(&mut b, OFF_OSPEEDR), 0x0000_00C0);
        assert_eq!(r(&mut b, OFF_PUPDR), 0x0000_0100);
        assert_eq!(b.pin_mode(3), PinMode::Alternate(0));
        assert_eq!(b.pin_mode(4), PinMode::Alternate(0));
        assert_eq!(b.pin_mode(5), PinMode::Input);
        let mut c = Gpio::new(Chip::F446, 'C');
        assert_eq!(r(&mut c, OFF_MODER), 0);
        assert_eq!(c.name(), "GPIOC");
    }

    #[test]
    fn g474_reset_values_are_analog() {
        let mut a = Gpio::new(Chip::G474, 'A');
        assert_eq!(r(&mut a, OFF_MODER), 0xABFF_FFFF);
        assert_eq!(a.pin_mode(0), PinMode::Analog);
        assert_eq!(a.pin_mode(13), PinMode::Alternate(0));
        let mut b = Gpio::new(Chip::G474, 'B');
        assert_eq!(r(&mut b, OFF_MODER), 0xFFFF_FEBF);
        assert_eq!(b.pin_mode(5), PinMode::Analog);
        assert_eq!(b.pin_mode(4), PinMode::Alternate(0));
        let mut c = Gpio::new(Chip::G474, 'C');
        assert_eq!(r(&mut c, OFF_MODER), 0xFFFF_FFFF);
        // Analog pins read 0.
        assert_eq!(r(&mut c, OFF_IDR), 0);
    }

    #[test]
    fn bsrr_set_wins_over_reset() {
        let mut g = Gpio::new(Chip::F446, 'B');
        w(&mut g, OFF_BSRR, 1 << 5);
        assert_eq!(g.odr(), 1 << 5);
        // BS5 and BR5 together: set has priority.
        w(&mut g, OFF_ODR, 0);
        w(&mut g, OFF_BSRR, (1 << 5) | (1 << 21));
        assert_eq!(g.odr(), 1 << 5);
        // BR alone clears, other bits untouched.
        w(&mut g, OFF_BSRR, (1 << 0) | (1 << 1));
        w(&mut g, OFF_BSRR, 1 << 21);
        assert_eq!(g.odr(), 0b11);
        // Reads as 0.
        assert_eq!(r(&mut g, OFF_BSRR), 0);
    }

    #[test]
    fn bsrr_halfword_store_only_touches_its_lanes() {
        let mut g = Gpio::new(Chip::F446, 'B');
        w(&mut g, OFF_ODR, 0xFFFF);
        // A halfword store to BSRR+2 (the BR half): lanes 31:16 only.
        g.write(
            0,
            OFF_BSRR,
            0x0020_0000,
            0xFFFF_0000,
            &mut Signals::default(),
        )
        .unwrap();
        assert_eq!(g.odr(), 0xFFDF);
    }

    #[test]
    fn brr_exists_on_g4_only() {
        let mut g = Gpio::new(Chip::G474, 'A');
        w(&mut g, OFF_ODR, 0x00FF);
        w(&mut g, OFF_BRR, 0x0003);
        assert_eq!(g.odr(), 0x00FC);
        let mut f = Gpio::new(Chip::F446, 'A');
        assert!(f
            .write(0, OFF_BRR, 1, 0xFFFF_FFFF, &mut Signals::default())
            .is_err());
    }

    /// embassy `Output::new(PB5, Level::Low, Speed::Low)`: BSRR BR5, PUPDR none, OTYPER push-pull,
    /// OSPEEDR low, MODER output.
    #[test]
    fn embassy_output_sequence() {
        let mut g = Gpio::new(Chip::F446, 'B');
        w(&mut g, OFF_BSRR, 1 << (16 + 5));
        let pupdr = r(&mut g, OFF_PUPDR) & !(3 << 10);
        w(&mut g, OFF_PUPDR, pupdr);
        let ot = r(&mut g, OFF_OTYPER) & !(1 << 5);
        w(&mut g, OFF_OTYPER, ot);
        let sp = r(&mut g, OFF_OSPEEDR) & !(3 << 10);
        w(&mut g, OFF_OSPEEDR, sp);
        let m = (r(&mut g, OFF_MODER) & !(3 << 10)) | (1 << 10);
        w(&mut g, OFF_MODER, m);
        assert_eq!(g.pin_mode(5), PinMode::Output { high: false });
        assert_eq!(g.driven_level(5), Some(false));
        w(&mut g, OFF_BSRR, 1 << 5);
        assert_eq!(g.pin_mode(5), PinMode::Output { high: true });
        // The debug pins are untouched.
        assert_eq!(g.pin_mode(3), PinMode::Alternate(0));
    }

    /// `PwmPin::new(PA8)` on the G474: AF6 in AFRH, MODER alternate.
    #[test]
    fn alternate_function_mux() {
        let mut g = Gpio::new(Chip::G474, 'A');
        let afrh = (r(&mut g, OFF_AFRH) & !0xF) | 6;
        w(&mut g, OFF_AFRH, afrh);
        let m = (r(&mut g, OFF_MODER) & !(3 << 16)) | (2 << 16);
        w(&mut g, OFF_MODER, m);
        assert_eq!(g.pin_mode(8), PinMode::Alternate(6));
        // PA0 AF1 via AFRL.
        w(&mut g, OFF_AFRL, 1);
        let m = (r(&mut g, OFF_MODER) & !3) | 2;
        w(&mut g, OFF_MODER, m);
        assert_eq!(g.pin_mode(0), PinMode::Alternate(1));
        // The timer channel level shows on the pin and in IDR.
        assert_eq!(g.driven_level(8), None);
        g.set_alternate_level(8, Some(true));
        assert_eq!(g.driven_level(8), Some(true));
    }

    #[test]
    fn idr_reflects_drivers_and_pulls() {
        let mut g = Gpio::new(Chip::F446, 'C');
        // All inputs, no pull, nothing driving: not modelled.
        assert!(g.read(0, OFF_IDR, &mut Signals::default()).is_err());
        // Pull-downs everywhere: 0; an external driver on PC13: 1.
        w(&mut g, OFF_PUPDR, 0xAAAA_AAAA);
        g.set_input_level(13, Some(true));
        assert_eq!(r(&mut g, OFF_IDR), 1 << 13);
        // PC0 push-pull output high reads back high.
        w(&mut g, OFF_MODER, 1);
        w(&mut g, OFF_ODR, 1);
        assert_eq!(r(&mut g, OFF_IDR), (1 << 13) | 1);
        // Open-drain released: the pull-down wins.
        w(&mut g, OFF_OTYPER, 1);
        assert_eq!(g.driven_level(0), None);
        assert_eq!(r(&mut g, OFF_IDR), 1 << 13);
        // Analog: 0 whatever drives it.
        w(&mut g, OFF_MODER, 3 << 26);
        assert_eq!(r(&mut g, OFF_IDR), 0);
    }

    #[test]
    fn lock_sequence_freezes_configuration() {
        let mut g = Gpio::new(Chip::F446, 'A');
        w(&mut g, OFF_MODER, 0xA800_0001); // PA0 output
        let key = LCKK | 1;
        w(&mut g, OFF_LCKR, key);
        w(&mut g, OFF_LCKR, 1);
        w(&mut g, OFF_LCKR, key);
        assert!(!g.is_locked());
        assert_eq!(r(&mut g, OFF_LCKR), key);
        assert!(g.is_locked());
        // PA0's mode is frozen, PA1's is not.
        w(&mut g, OFF_MODER, 0xA800_0008);
        assert_eq!(r(&mut g, OFF_MODER), 0xA800_0009);
        // ODR is not part of the lock.
        w(&mut g, OFF_BSRR, 1);
        assert_eq!(g.odr(), 1);
        // Reset unlocks.
        g.reset(0);
        assert!(!g.is_locked());
        assert_eq!(r(&mut g, OFF_MODER), 0xA800_0000);
    }

    #[test]
    fn broken_lock_sequence_does_not_lock() {
        let mut g = Gpio::new(Chip::F446, 'A');
        w(&mut g, OFF_LCKR, LCKK | 1);
        w(&mut g, OFF_LCKR, 3); // LCK changed
        w(&mut g, OFF_LCKR, LCKK | 3);
        r(&mut g, OFF_LCKR);
        assert!(!g.is_locked());
        // Skipping the LCKK = 0 write: no lock either.
        w(&mut g, OFF_LCKR, LCKK | 1);
        w(&mut g, OFF_LCKR, LCKK | 1);
        r(&mut g, OFF_LCKR);
        assert!(!g.is_locked());
    }
}
