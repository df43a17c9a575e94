//! The two Nucleo boards: each chip's memory map, peripheral instances at their addresses
//! (RM0390 §2.2.2 table 1 for the F446; RM0440 §2.2.2 table 4 for the G474), interrupt numbers
//! (vector tables: RM0390 §10.2 table 38; RM0440 §16.3 table 97), the recorded pins (UM1724 /
//! UM2505 Arduino and Morpho headers) and the rheostat wired to the wiper's ADC input.

use crate::machine::{ChipSpec, Machine, Mapped, PinMode, PinSpec};
use crate::periph::{
    self, adc_f4, adc_g4, dac, dma_f4, dma_g4, gpio, iwdg, lpuart_g4, misc, rcc_f4, rcc_g4, tim,
    usart_f4, ClockDomain, Peripheral, ResetCause, Time,
};
use std::cell::RefCell;
use std::path::Path;
use std::rc::Rc;

/// Which board.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BoardKind {
    F446,
    G474,
}

impl BoardKind {
    pub fn name(self) -> &'static str {
        match self {
            BoardKind::F446 => "nucleo-f446re",
            BoardKind::G474 => "nucleo-g474re",
        }
    }

    pub fn parse(s: &str) -> Result<Self, String> {
        match s {
            "nucleo-f446re" | "f446" => Ok(BoardKind::F446),
            "nucleo-g474re" | "g474" => Ok(BoardKind::G474),
            _ => Err(format!(
                "--board {s:?}: unknown board; use nucleo-f446re or nucleo-g474re"
            )),
        }
    }

    /// The saw-boards definition the firmware was built from.
    pub fn def(self) -> &'static saw_boards::BoardDef {
        match self {
            BoardKind::F446 => &saw_boards::NUCLEO_F446RE,
            BoardKind::G474 => &saw_boards::NUCLEO_G474RE,
        }
    }
}

/// The rheostat wiper as the ADC sees it: one 12-bit conversion at a time (host-sim's model).
pub type Wiper = Box<dyn FnMut(Time) -> u16>;

/// Names of the recorded pins, in `Sim::pins` order.
pub const PIN_BURST_A: usize = 0;
pub const PIN_BURST_B: usize = 1;
pub const PIN_CARRIER: usize = 2;
pub const PIN_RF_ARM: usize = 3;

/// Tells the RCC model why the chip reset (its reset flags).
pub fn note_reset(rcc: &mut dyn Peripheral, cause: ResetCause) {
    if let Some(r) = rcc.as_any_mut().downcast_mut::<rcc_f4::RccF4>() {
        r.note_reset(cause);
    } else if let Some(r) = rcc.as_any_mut().downcast_mut::<rcc_g4::RccG4>() {
        r.note_reset(cause);
    }
}

/// A model's own fault (a behaviour it found but cannot represent), checked after each slice.
pub fn model_fault(p: &dyn Peripheral) -> Option<String> {
    let a = p.as_any();
    if let Some(x) = a.downcast_ref::<adc_f4::AdcF4>() {
        return x.fault();
    }
    if let Some(x) = a.downcast_ref::<adc_g4::AdcG4>() {
        return x.fault();
    }
    None
}

/// After a write to RCC or PWR: the blocks RCC just reset (APBxRSTR/AHBxRSTR), and the backup
/// domain's write protection (PWR_CR.DBP / PWR_CR1.DBP gates RCC_BDCR).
pub fn after_rcc_or_pwr_write(periphs: &mut [Mapped], rcc: usize, now: Time) {
    let dbp = periphs.iter().find_map(|m| {
        let a = m.p.as_any();
        a.downcast_ref::<misc::PwrF4>()
            .map(|p| p.dbp())
            .or_else(|| a.downcast_ref::<misc::PwrG4>().map(|p| p.dbp()))
    });
    let resets = {
        let r = periphs[rcc].p.as_any_mut();
        if let Some(r) = r.downcast_mut::<rcc_f4::RccF4>() {
            if let Some(d) = dbp {
                r.set_backup_domain_writable(d);
            }
            r.take_peripheral_resets()
        } else if let Some(r) = r.downcast_mut::<rcc_g4::RccG4>() {
            if let Some(d) = dbp {
                r.set_backup_domain_writable(d);
            }
            r.take_peripheral_resets()
        } else {
            Vec::new()
        }
    };
    for base in resets {
        if let Some(m) = periphs.iter_mut().find(|m| m.base == base) {
            m.p.reset(now);
        }
    }
}

/// A debug halt starts or ends at `now`: the IWDG freezes while halted only if DBGMCU's
/// DBG_IWDG_STOP is set.
pub fn debug_halt(periphs: &mut [Mapped], now: Time, halted: bool) {
    let stop = periphs.iter().find_map(|m| {
        m.p.as_any()
            .downcast_ref::<misc::DbgMcu>()
            .map(|d| d.iwdg_stop())
    });
    for m in periphs.iter_mut() {
        if let Some(w) = m.p.as_any_mut().downcast_mut::<iwdg::Iwdg>() {
            w.set_frozen(now, halted && stop == Some(true));
        }
    }
}

fn map(base: u32, size: u32, p: impl Peripheral + 'static) -> Mapped {
    Mapped {
        base,
        size,
        p: Box::new(p),
    }
}

fn timer(
    number: u8,
    bits: u8,
    advanced: bool,
    clock: ClockDomain,
    name: &'static str,
    irq_up: u16,
    irq_cc: u16,
) -> tim::Timer {
    tim::Timer::new(tim::TimerConfig {
        number,
        bits,
        advanced,
        clock,
        name,
        irq_up,
        irq_cc,
        // TIM8's ITR1 is TIM2's TRGO on both chips (see `TimerConfig::itr1`).
        itr1: (number == 8).then_some(2),
    })
}

fn pin_mode(p: &dyn Peripheral, pin: u8) -> PinMode {
    let g = p
        .as_any()
        .downcast_ref::<gpio::Gpio>()
        .expect("pin spec names a GPIO port");
    match g.pin_mode(pin) {
        gpio::PinMode::Input => PinMode::Input,
        gpio::PinMode::Output { high } => PinMode::Output { high },
        gpio::PinMode::Alternate(n) => PinMode::Alternate(n),
        gpio::PinMode::Analog => PinMode::Analog,
    }
}

/// Index of the peripheral mapped at `base`.
fn index(periphs: &[Mapped], base: u32) -> usize {
    periphs.iter().position(|m| m.base == base).expect("mapped")
}

/// Builds the machine for `kind` running `elf`, the wiper read through `wiper`.
pub fn build(kind: BoardKind, elf: &Path, wiper: Wiper) -> Result<Machine, String> {
    build_with(kind, elf, wiper, None)
}

/// As [`build`], with the 4-wire overlay (`crate::touch`) on the 2D image's four pins: its
/// channels convert the overlay's nodes, every write to their ports tells it the pins' modes.
pub fn build_with(
    kind: BoardKind,
    elf: &Path,
    mut wiper: Wiper,
    touch: Option<Rc<RefCell<crate::touch::Panel>>>,
) -> Result<Machine, String> {
    let image = crate::elf::Image::load(elf).map_err(|e| format!("--elf {e}"))?;
    // The image must be this board's and carry what the model reads: the defmt table and the
    // RTT control block (a stripped image has neither).
    let other = match kind {
        BoardKind::F446 => BoardKind::G474,
        BoardKind::G474 => BoardKind::F446,
    };
    if !image.contains(kind.name().as_bytes()) && image.contains(other.name().as_bytes()) {
        return Err(format!(
            "--elf {}: the image is built for {}, not --board {}",
            elf.display(),
            other.name(),
            kind.name()
        ));
    }
    if image.symbol("_SEGGER_RTT").is_none() || !image.has_defmt {
        return Err(format!(
            "--elf {}: no RTT control block or defmt table (stripped?); use the image scripts/build-firmware.sh leaves in firmware/target/",
            elf.display()
        ));
    }
    let wiper_channel = kind.def().adc.channel;
    let panel = touch.clone();
    let input = Box::new(move |t: Time, ch: u8| {
        if let Some(code) = panel.as_ref().and_then(|p| p.borrow_mut().convert(t, ch)) {
            return Some(code);
        }
        if ch == wiper_channel {
            Some(wiper(t))
        } else {
            None
        }
    });
    let (periphs, spec) = match kind {
        BoardKind::F446 => f446(input),
        BoardKind::G474 => g474(input),
    };
    let mut m = Machine::new(spec, periphs, image, true)?;
    if let Some(panel) = touch {
        // GPIOB and GPIOC (RM0390 §2.2.2 table 1; RM0440 §2.2.2 table 4).
        let (b, c) = match kind {
            BoardKind::F446 => (0x4002_0400, 0x4002_0800),
            BoardKind::G474 => (0x4800_0400, 0x4800_0800),
        };
        let (ib, ic) = (index(&m.sim().periphs, b), index(&m.sim().periphs, c));
        let pins = crate::touch::Panel::pins(kind.def())
            .map(|(port, pin)| (if port == 'B' { ib } else { ic }, pin));
        m.sim_mut().touch = Some((panel, pins));
    }
    // Keep every write to the burst timer (latency, update sequences) and to TIM3 (trigger).
    m.sim_mut().watch = vec![(0x4000_0000, 0x400), (0x4000_0400, 0x400)];
    // Planted defects, to show the RF level checks fail (comma-separated): `dac-ignore-ten`
    // (DHR → DOR at every write, as with TEN1 = 0), `dac-ignore-en` (EN1 = 0 does not release
    // the output), `tim8-gate-ignored` (gated mode counts whenever CEN = 1), `tim8-ug-no-trgo`
    // (TIM8's EGR.UG makes no TRGO), `tim8-no-cc-dma` (TIM8's CC1DE raises no request). Never
    // set in CI.
    let plants = std::env::var("BOARD_MODEL_PLANT").unwrap_or_default();
    for m in m.sim_mut().periphs.iter_mut() {
        let a = m.p.as_any_mut();
        if let Some(d) = a.downcast_mut::<dac::Dac>() {
            d.plant_ignore_ten = plants.contains("dac-ignore-ten");
            d.plant_ignore_en = plants.contains("dac-ignore-en");
        } else if let Some(t) = a.downcast_mut::<tim::Timer>() {
            if t.name() == "TIM8" {
                if plants.contains("tim8-gate-ignored") {
                    t.plant_gate_ignored = true;
                    t.plant_gate_open();
                }
                t.plant_ug_no_trgo = plants.contains("tim8-ug-no-trgo");
                if plants.contains("tim8-no-cc-dma") {
                    t.plant_no_cc_dma();
                }
            }
        }
    }
    // Record the burst channels always; the carrier only while `record_carrier` is on.
    for t in m.sim_mut().periphs.iter_mut() {
        if let Some(tm) = t.p.as_any_mut().downcast_mut::<tim::Timer>() {
            if tm.name() == "TIM2" {
                tm.record_channel(1, true);
                tm.record_channel(3, true);
            }
        }
    }
    Ok(m)
}

type Input = Box<dyn FnMut(Time, u8) -> Option<u16>>;

fn f446(input: Input) -> (Vec<Mapped>, ChipSpec) {
    use ClockDomain::*;
    let periphs = vec![
        map(
            0x4000_0000,
            0x400,
            timer(2, 32, false, TimApb1, "TIM2", 28, 28),
        ),
        map(
            0x4000_0400,
            0x400,
            timer(3, 16, false, TimApb1, "TIM3", 29, 29),
        ),
        map(
            0x4000_0800,
            0x400,
            timer(4, 16, false, TimApb1, "TIM4", 30, 30),
        ),
        map(0x4000_3000, 0x400, iwdg::Iwdg::new(false)),
        map(0x4000_4400, 0x400, usart_f4::UsartF4::new()),
        map(0x4000_7000, 0x400, misc::PwrF4::new()),
        // DAC (RM0390 §2.2.2 table 1: 0x4000_7400, APB1).
        map(0x4000_7400, 0x400, dac::Dac::new(dac::DacChip::F446)),
        map(
            0x4001_0000,
            0x400,
            timer(1, 16, true, TimApb2, "TIM1", 25, 27),
        ),
        // TIM8 (0x4001_0400, APB2): TIM8_UP_TIM13 = 44, TIM8_CC = 46 (RM0390 table 38).
        map(
            0x4001_0400,
            0x400,
            timer(8, 16, true, TimApb2, "TIM8", 44, 46),
        ),
        map(0x4001_2000, 0x400, adc_f4::AdcF4::new(18, input)),
        map(0x4001_3800, 0x400, misc::Syscfg::new()),
        map(0x4001_3C00, 0x400, misc::Exti::new()),
        map(0x4002_0000, 0x400, gpio::Gpio::new(gpio::Chip::F446, 'A')),
        map(0x4002_0400, 0x400, gpio::Gpio::new(gpio::Chip::F446, 'B')),
        map(0x4002_0800, 0x400, gpio::Gpio::new(gpio::Chip::F446, 'C')),
        map(0x4002_3800, 0x400, rcc_f4::RccF4::new()),
        map(0x4002_3C00, 0x400, misc::FlashF4::new()),
        map(
            0x4002_6000,
            0x400,
            dma_f4::DmaF4::new(1, [11, 12, 13, 14, 15, 16, 17, 47], 0x4002_6000),
        ),
        map(
            0x4002_6400,
            0x400,
            dma_f4::DmaF4::new(2, [56, 57, 58, 59, 60, 68, 69, 70], 0x4002_6400),
        ),
        map(0xE004_2000, 0x400, misc::DbgMcu::new(0x421)),
    ];
    let (gpioa, gpiob) = (index(&periphs, 0x4002_0000), index(&periphs, 0x4002_0400));
    let spec = ChipSpec {
        name: "STM32F446RE",
        irqs: 97,
        flash: (0x0800_0000, 512 * 1024),
        flash_size_reg: 0x1FFF_7A22,
        ram: vec![(0x2000_0000, 128 * 1024)],
        rcc: index(&periphs, 0x4002_3800),
        clocks: |p| p.as_any().downcast_ref::<rcc_f4::RccF4>().unwrap().clocks(),
        clock_enabled: |p, base| {
            p.as_any()
                .downcast_ref::<rcc_f4::RccF4>()
                .unwrap()
                .clock_enabled(base)
        },
        flash_if: index(&periphs, 0x4002_3C00),
        flash_timing: |p| {
            let f = p.as_any().downcast_ref::<misc::FlashF4>().unwrap();
            (f.art_enabled(), f.wait_states())
        },
        flash_prog: |p| &mut p.as_any_mut().downcast_mut::<misc::FlashF4>().unwrap().prog,
        pin_mode,
        // UM1724 §6.11 / RM0390 table 11 (AF map, DS10693): PA0 AF1 = TIM2_CH1, PB10 AF1 =
        // TIM2_CH3, PA8 AF1 = TIM1_CH1, PB5 = RF arm (GPIO output).
        pins: vec![
            PinSpec {
                name: "PA0 burst A (TIM2_CH1)",
                port: gpioa,
                pin: 0,
                af: Some((1, 2, 1)),
            },
            PinSpec {
                name: "PB10 burst B (TIM2_CH3)",
                port: gpiob,
                pin: 10,
                af: Some((1, 2, 3)),
            },
            PinSpec {
                name: "PA8 carrier (TIM1_CH1)",
                port: gpioa,
                pin: 8,
                af: Some((1, 1, 1)),
            },
            PinSpec {
                name: "PB5 RF arm",
                port: gpiob,
                pin: 5,
                af: None,
            },
        ],
    };
    (periphs, spec)
}

fn g474(input: Input) -> (Vec<Mapped>, ChipSpec) {
    use ClockDomain::*;
    let periphs = vec![
        map(
            0x4000_0000,
            0x400,
            timer(2, 32, false, TimApb1, "TIM2", 28, 28),
        ),
        map(
            0x4000_0400,
            0x400,
            timer(3, 16, false, TimApb1, "TIM3", 29, 29),
        ),
        map(
            0x4000_0800,
            0x400,
            timer(4, 16, false, TimApb1, "TIM4", 30, 30),
        ),
        map(0x4000_3000, 0x400, iwdg::Iwdg::new(true)),
        map(0x4000_7000, 0x400, misc::PwrG4::new()),
        // LPUART1 (RM0440 §2.2.2 table 4: 0x4000_8000), the host link (UM2505 §7.9: PA2/PA3 to
        // the STLINK-V3E virtual COM port).
        map(0x4000_8000, 0x400, lpuart_g4::LpuartG4::new()),
        map(0x4001_0000, 0x400, misc::Syscfg::new()),
        map(0x4001_0400, 0x400, misc::Exti::new()),
        map(
            0x4001_2C00,
            0x400,
            timer(1, 16, true, TimApb2, "TIM1", 25, 27),
        ),
        // TIM8 (RM0440 table 4: 0x4001_3400, APB2): TIM8_UP = 44, TIM8_CC = 46 (table 97).
        map(
            0x4001_3400,
            0x400,
            timer(8, 16, true, TimApb2, "TIM8", 44, 46),
        ),
        map(
            0x4002_0000,
            0x400,
            dma_g4::DmaG4::new(1, [11, 12, 13, 14, 15, 16, 17, 96]),
        ),
        map(
            0x4002_0400,
            0x400,
            dma_g4::DmaG4::new(2, [56, 57, 58, 59, 60, 97, 98, 99]),
        ),
        map(0x4002_0800, 0x400, dma_g4::DmaMux::new()),
        map(0x4002_1000, 0x400, rcc_g4::RccG4::new()),
        map(0x4002_2000, 0x400, misc::FlashG4::new()),
        map(0x4800_0000, 0x400, gpio::Gpio::new(gpio::Chip::G474, 'A')),
        map(0x4800_0400, 0x400, gpio::Gpio::new(gpio::Chip::G474, 'B')),
        map(0x4800_0800, 0x400, gpio::Gpio::new(gpio::Chip::G474, 'C')),
        map(0x5000_0000, 0x400, adc_g4::AdcG4::new(18, input)),
        // DAC1 (RM0440 table 4: 0x5000_0800, AHB2).
        map(0x5000_0800, 0x400, dac::Dac::new(dac::DacChip::G474)),
        map(0xE004_2000, 0x400, misc::DbgMcu::new(0x469)),
    ];
    let (gpioa, gpiob) = (index(&periphs, 0x4800_0000), index(&periphs, 0x4800_0400));
    let spec = ChipSpec {
        name: "STM32G474RE",
        irqs: 102,
        flash: (0x0800_0000, 512 * 1024),
        flash_size_reg: 0x1FFF_75E0,
        ram: vec![(0x2000_0000, 96 * 1024), (0x1000_0000, 32 * 1024)],
        rcc: index(&periphs, 0x4002_1000),
        clocks: |p| p.as_any().downcast_ref::<rcc_g4::RccG4>().unwrap().clocks(),
        clock_enabled: |p, base| {
            p.as_any()
                .downcast_ref::<rcc_g4::RccG4>()
                .unwrap()
                .clock_enabled(base)
        },
        flash_if: index(&periphs, 0x4002_2000),
        flash_timing: |p| {
            let f = p.as_any().downcast_ref::<misc::FlashG4>().unwrap();
            (f.art_enabled(), f.wait_states())
        },
        flash_prog: |p| &mut p.as_any_mut().downcast_mut::<misc::FlashG4>().unwrap().prog,
        pin_mode,
        // UM2505 / DS12288 AF map: PA0 AF1 = TIM2_CH1, PB10 AF1 = TIM2_CH3, PA8 AF6 = TIM1_CH1.
        pins: vec![
            PinSpec {
                name: "PA0 burst A (TIM2_CH1)",
                port: gpioa,
                pin: 0,
                af: Some((1, 2, 1)),
            },
            PinSpec {
                name: "PB10 burst B (TIM2_CH3)",
                port: gpiob,
                pin: 10,
                af: Some((1, 2, 3)),
            },
            PinSpec {
                name: "PA8 carrier (TIM1_CH1)",
                port: gpioa,
                pin: 8,
                af: Some((6, 1, 1)),
            },
            PinSpec {
                name: "PB5 RF arm",
                port: gpiob,
                pin: 5,
                af: None,
            },
        ],
    };
    (periphs, spec)
}

#[allow(unused)]
fn _uses(_: periph::Time) {}
