//! The stack's high-water mark: the stack region of an image (from its vector table and the
//! linker's symbols), painted with a pattern before the core leaves reset, and the lowest word
//! a run overwrote. Test tooling's job, not the firmware's: nothing in the image changes.
use crate::elf::Image;
use serde::Serialize;
use std::sync::Mutex;

/// The paint. Any value the firmware is unlikely to store as the last word of its deepest frame;
/// one that it does store there would only make the measurement one word shallower per hit.
pub const PAINT: u32 = 0xC0FF_EE5A;

/// Where the main stack may grow: `[bottom, top)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Region {
    /// The lowest address the stack may reach: the start of RAM when the statics sit above the
    /// stack (flip-link's layout), else the end of the statics.
    pub bottom: u32,
    /// The initial SP (the vector table's first word).
    pub top: u32,
    /// `.data + .bss + .uninit` of the image, bytes.
    pub static_bytes: u32,
    /// The statics sit above the stack: an overflow runs off the start of RAM (a bus fault,
    /// hence HardFault) instead of into them.
    pub flipped: bool,
}

impl Region {
    /// The stack region of `image` in the RAM blocks `ram` (base, size). An error names what
    /// the image lacks.
    pub fn of(image: &Image, flash_base: u32, ram: &[(u32, u32)]) -> Result<Self, String> {
        let top = image
            .word(flash_base)
            .ok_or("no vector table at the start of flash")?;
        let sym = |n: &str| {
            image.symbol(n).ok_or_else(|| {
                format!("the image has no `{n}` symbol (cortex-m-rt's link.x defines it)")
            })
        };
        let (sdata, ebss) = (sym("__sdata")?, sym("__ebss")?);
        // `.uninit` follows `.bss` in cortex-m-rt 0.7's link.x; older images have none.
        let end_statics = image.symbol("__euninit").unwrap_or(ebss).max(ebss);
        let &(base, _) = ram
            .iter()
            .find(|&&(b, s)| top > b && top <= b + s)
            .ok_or_else(|| format!("the initial SP 0x{top:08X} is in no RAM block"))?;
        let flipped = sdata >= top;
        let bottom = if flipped { base } else { end_statics };
        if bottom >= top {
            return Err(format!(
                "no room for a stack: the statics end at 0x{end_statics:08X}, the initial SP is 0x{top:08X}"
            ));
        }
        Ok(Self {
            bottom,
            top,
            static_bytes: end_statics - sdata,
            flipped,
        })
    }

    /// Bytes reserved for the stack.
    pub fn reserved(&self) -> u32 {
        self.top - self.bottom
    }
}

/// The deepest stack of a run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Use {
    pub region: Region,
    /// The lowest overwritten word's address (`region.top` if none was).
    pub lowest: u32,
}

impl Use {
    /// Bytes between the initial SP and the lowest overwritten word.
    pub fn deepest(&self) -> u32 {
        self.region.top - self.lowest
    }

    /// Bytes never reached.
    pub fn headroom(&self) -> u32 {
        self.lowest - self.region.bottom
    }
}

/// The painted words of `region`, as bytes to write at `region.bottom`.
pub fn paint(region: &Region) -> Vec<u8> {
    PAINT.to_le_bytes().repeat((region.reserved() / 4) as usize)
}

/// The lowest word of `mem` (the region's bytes, read back from `region.bottom`) that no longer
/// holds the paint.
pub fn measure(region: &Region, mem: &[u8]) -> Use {
    let lowest = mem
        .chunks_exact(4)
        .position(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]]) != PAINT)
        .map_or(region.top, |i| region.bottom + 4 * i as u32);
    Use {
        region: *region,
        lowest,
    }
}

/// The deepest use over every run in this process (`run::run` records each), for the summary
/// of `board-model check`.
static DEEPEST: Mutex<Option<Use>> = Mutex::new(None);

/// Keeps `u` if it is deeper than what was recorded.
pub fn record(u: Use) {
    let mut d = DEEPEST.lock().unwrap_or_else(|p| p.into_inner());
    if d.is_none_or(|d| u.lowest < d.lowest || d.region != u.region) {
        *d = Some(u);
    }
}

/// The deepest use recorded so far, and forgets it.
pub fn take_deepest() -> Option<Use> {
    DEEPEST.lock().unwrap_or_else(|p| p.into_inner()).take()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn region() -> Region {
        Region {
            bottom: 0x2000_0000,
            top: 0x2000_0100,
            static_bytes: 0,
            flipped: true,
        }
    }

    #[test]
    fn the_lowest_overwritten_word_is_the_depth() {
        let r = region();
        let mut mem = paint(&r);
        assert_eq!(mem.len(), 0x100);
        assert_eq!(measure(&r, &mem).deepest(), 0);
        // A frame 0x40 bytes deep, with a word inside it that happens to keep the paint.
        for b in &mut mem[0xC0..0x100] {
            *b = 0;
        }
        mem[0xC4..0xC8].copy_from_slice(&PAINT.to_le_bytes());
        let u = measure(&r, &mem);
        assert_eq!((u.deepest(), u.headroom()), (0x40, 0xC0));
        // One byte written deeper counts its whole word.
        mem[0x11] = 7;
        assert_eq!(measure(&r, &mem).lowest, 0x2000_0010);
    }
}
