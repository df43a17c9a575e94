//! The firmware image: loadable segments at their load addresses, symbols, and where the
//! instructions the model must watch (SEV, CPSIE) are.
use object::{Object, ObjectSegment, ObjectSymbol};
use std::path::Path;

/// One loadable segment at its physical (load) address: `.data` sits in flash until the reset
/// handler copies it, exactly as a probe would flash it.
#[derive(Clone, Debug)]
pub struct Segment {
    pub addr: u32,
    pub bytes: Vec<u8>,
}

/// A parsed firmware ELF.
#[derive(Clone, Debug)]
pub struct Image {
    pub segments: Vec<Segment>,
    pub symbols: Vec<(String, u32, u32)>,
    /// The image has a `.defmt` section (defmt-print needs it to decode the log).
    pub has_defmt: bool,
}

impl Image {
    /// Reads `path`; an error names the file and what is wrong with it.
    pub fn load(path: &Path) -> Result<Self, String> {
        let data = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let obj = object::File::parse(&*data)
            .map_err(|e| format!("{}: not an ELF file: {e}", path.display()))?;
        if obj.architecture() != object::Architecture::Arm {
            return Err(format!(
                "{}: not an Arm image ({:?})",
                path.display(),
                obj.architecture()
            ));
        }
        let mut segments = Vec::new();
        // Program headers: use the physical address (LMA), as a flash programmer does.
        if let object::File::Elf32(elf) = &obj {
            use object::read::elf::ProgramHeader;
            let endian = elf.endian();
            for ph in elf.elf_program_headers() {
                if ph.p_type(endian) != object::elf::PT_LOAD || ph.p_filesz(endian) == 0 {
                    continue;
                }
                let off = ph.p_offset(endian) as usize;
                let len = ph.p_filesz(endian) as usize;
                segments.push(Segment {
                    addr: ph.p_paddr(endian),
                    bytes: data
                        .get(off..off.saturating_add(len))
                        .ok_or_else(|| {
                            format!("{}: a program header points past the end of the file (corrupt ELF)", path.display())
                        })?
                        .to_vec(),
                });
            }
        } else {
            for s in obj.segments() {
                let bytes = s.data().map_err(|e| e.to_string())?.to_vec();
                if !bytes.is_empty() {
                    segments.push(Segment {
                        addr: s.address() as u32,
                        bytes,
                    });
                }
            }
        }
        if segments.is_empty() {
            return Err(format!("{}: no loadable segments", path.display()));
        }
        let symbols = obj
            .symbols()
            .filter_map(|s| {
                Some((
                    s.name().ok()?.to_string(),
                    s.address() as u32,
                    s.size() as u32,
                ))
            })
            .collect();
        use object::ObjectSection;
        let has_defmt = obj.sections().any(|s| s.name() == Ok(".defmt"));
        Ok(Self {
            segments,
            symbols,
            has_defmt,
        })
    }

    /// Whether the loaded bytes contain `needle` (e.g. the board name the firmware logs).
    pub fn contains(&self, needle: &[u8]) -> bool {
        self.segments
            .iter()
            .any(|s| s.bytes.windows(needle.len()).any(|w| w == needle))
    }

    /// Address of a symbol by exact name.
    pub fn symbol(&self, name: &str) -> Option<u32> {
        self.symbols
            .iter()
            .find(|(n, _, _)| n == name)
            .map(|&(_, a, _)| a)
    }

    /// Address and size of the first symbol whose (mangled) name contains `part`.
    pub fn symbol_containing(&self, part: &str) -> Option<(u32, u32)> {
        self.symbols
            .iter()
            .find(|(n, _, _)| n.contains(part))
            .map(|&(_, a, s)| (a & !1, s))
    }

    /// Reads a little-endian word from the image (flash contents).
    pub fn word(&self, addr: u32) -> Option<u32> {
        for s in &self.segments {
            if addr >= s.addr && (addr - s.addr) as usize + 4 <= s.bytes.len() {
                let i = (addr - s.addr) as usize;
                return Some(u32::from_le_bytes(s.bytes[i..i + 4].try_into().unwrap()));
            }
        }
        None
    }

    /// Every halfword-aligned address in the image holding `halfword` (candidates for a 16-bit
    /// instruction; a code hook there only fires if an instruction really starts there).
    pub fn halfwords(&self, halfword: u16) -> Vec<u32> {
        let mut v = Vec::new();
        for s in &self.segments {
            for (i, c) in s.bytes.chunks_exact(2).enumerate() {
                if u16::from_le_bytes([c[0], c[1]]) == halfword {
                    v.push(s.addr + 2 * i as u32);
                }
            }
        }
        v
    }
}

impl Image {
    /// A call site that panics: `movw r0, #lo; movt r0, #hi; bl <function>` where the symbol
    /// name of `function` contains `callee` (e.g. "panic_const_div_by_zero", whose only
    /// argument, the caller's `&Location`, is loaded into r0 by the two moves). Returns the
    /// address of the `movw`.
    pub fn call_site(&self, callee: &str) -> Option<u32> {
        let (target, _) = self.symbol_containing(callee)?;
        for s in &self.segments {
            let hw = |i: usize| -> Option<u16> {
                s.bytes
                    .get(2 * i..2 * i + 2)
                    .map(|b| u16::from_le_bytes([b[0], b[1]]))
            };
            for i in 4..s.bytes.len() / 2 {
                let (Some(h1), Some(h2)) = (hw(i), hw(i + 1)) else {
                    break;
                };
                if h1 & 0xF800 != 0xF000 || h2 & 0xD000 != 0xD000 {
                    continue;
                }
                let addr = s.addr + 2 * i as u32;
                if bl_target(addr, h1, h2) != target {
                    continue;
                }
                // movw r0 (T3: 11110 i 10 0100 imm4 | 0 imm3 Rd imm8) then movt r0 (…1100…).
                let (Some(w1), Some(w2), Some(t1), Some(t2)) =
                    (hw(i - 4), hw(i - 3), hw(i - 2), hw(i - 1))
                else {
                    continue;
                };
                if w1 & 0xFBF0 == 0xF240
                    && (w2 >> 8) & 0xF == 0
                    && t1 & 0xFBF0 == 0xF2C0
                    && (t2 >> 8) & 0xF == 0
                {
                    return Some(addr - 8);
                }
            }
        }
        None
    }
}

/// Target of a Thumb-2 BL (T1) at `addr` (ARMv7-M A7.7.18): I1 = !(J1 ^ S), I2 = !(J2 ^ S).
fn bl_target(addr: u32, h1: u16, h2: u16) -> u32 {
    let s = ((h1 >> 10) & 1) as u32;
    let imm10 = (h1 & 0x3FF) as u32;
    let j1 = ((h2 >> 13) & 1) as u32;
    let j2 = ((h2 >> 11) & 1) as u32;
    let imm11 = (h2 & 0x7FF) as u32;
    let i1 = !(j1 ^ s) & 1;
    let i2 = !(j2 ^ s) & 1;
    let imm = (s << 24) | (i1 << 23) | (i2 << 22) | (imm10 << 12) | (imm11 << 1);
    let off = ((imm << 7) as i32) >> 7;
    addr.wrapping_add(4).wrapping_add(off as u32)
}

/// Number of Thumb instructions in `bytes` starting at an instruction boundary: a halfword whose
/// top five bits are 0b11101, 0b11110 or 0b11111 starts a 32-bit instruction (ARMv7-M A5.1).
pub fn thumb_instructions(bytes: &[u8]) -> u32 {
    let mut i = 0;
    let mut n = 0;
    while i + 1 < bytes.len() {
        let h = u16::from_le_bytes([bytes[i], bytes[i + 1]]);
        i += if h >> 11 >= 0b11101 { 4 } else { 2 };
        n += 1;
    }
    n
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decodes_a_bl() {
        // From the F446 image: at 0x080008D4, `bl 0x08004E74` is F004 FACE.
        assert_eq!(bl_target(0x0800_08D4, 0xF004, 0xFACE), 0x0800_4E74);
    }

    #[test]
    fn counts_mixed_16_and_32_bit_instructions() {
        // movs r0,#1 (16) ; ldr.w r1,[r2] (32: F8D2 1000) ; bx lr (16)
        let b = [0x01, 0x20, 0xD2, 0xF8, 0x00, 0x10, 0x70, 0x47];
        assert_eq!(thumb_instructions(&b), 3);
    }
}
