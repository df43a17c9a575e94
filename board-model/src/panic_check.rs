//! The panic check: the call graph of a firmware image's Thumb code, decoded from the ELF, and
//! every path from the per-sample roots into a panic function (bounds checks, unwrap/expect,
//! overflow and division checks, `panic!`, the panic handler).
//!
//! Edges are the direct branches the ARMv7-M encodings name a target for (ARMv7-M ARM A6.7:
//! BL T1, B T1–T4, CBZ/CBNZ): a BL is a call, a B/CBZ whose target is outside the function is a
//! tail call. Indirect branches (BLX/BX to a register other than LR, MOV PC, a load into PC
//! from anywhere but the stack) cannot be followed: the check counts them and names where they
//! are. Data inside a function (literal pools, TBB/TBH tables) is skipped by the ELF mapping
//! symbols `$d`/`$t` (ELF for the Arm Architecture, "Mapping symbols").
use object::{Object, ObjectSection, ObjectSymbol, SectionKind, SymbolKind};
use std::collections::{BTreeMap, HashMap, VecDeque};
use std::path::Path;

/// One function of the image: its demangled name (hash dropped) and its code range.
#[derive(Clone, Debug)]
pub struct Func {
    pub name: String,
    pub addr: u32,
    pub size: u32,
}

/// How a function leaves for another one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EdgeKind {
    /// BL.
    Call,
    /// B/B.W/CBZ to outside the function.
    TailCall,
}

/// A branch from one function to another, at `site`.
#[derive(Clone, Copy, Debug)]
pub struct Edge {
    pub site: u32,
    pub to: usize,
    pub kind: EdgeKind,
}

/// A branch whose target is in a register: not followed.
#[derive(Clone, Debug)]
pub struct Indirect {
    pub site: u32,
    /// The instruction, e.g. `blx r3`.
    pub what: String,
}

/// The decoded call graph.
pub struct Graph {
    /// Sorted by address.
    pub funcs: Vec<Func>,
    pub edges: Vec<Vec<Edge>>,
    pub indirect: Vec<Vec<Indirect>>,
}

/// What the check found from the roots.
pub struct Finding {
    /// The roots, as function indices.
    pub roots: Vec<usize>,
    /// Functions reachable from the roots (roots included), stopping at panic functions and at
    /// allowed functions.
    pub reachable: usize,
    /// One shortest chain per (caller, panic function) pair: function indices root → … → the
    /// panic function, with the call site of each step (the first entry's site is 0).
    pub panics: Vec<Vec<(usize, u32)>>,
    /// Allowed functions the traversal reached and did not enter.
    pub allowed_reached: Vec<(usize, String)>,
    /// Indirect branch sites in reachable functions.
    pub indirect: Vec<(usize, Indirect)>,
}

/// Whether `name` (demangled, no hash) is a function that panics: `core::panicking::*`,
/// `core::panic*`, unwrap/expect failures, the slice and str index failures, `RefCell` borrow
/// failures, defmt's panic, and the panic handler itself (`rust_begin_unwind`).
pub fn is_panic_fn(name: &str) -> bool {
    let segs: Vec<&str> = name.split("::").collect();
    let path_has = |p: &str| segs.iter().any(|s| s.starts_with(p));
    name.starts_with("core::panicking::")
        || name.starts_with("core::panic::")
        || name.contains("rust_begin_unwind")
        || matches!(
            name,
            "core::option::unwrap_failed"
                | "core::option::expect_failed"
                | "core::result::unwrap_failed"
                | "core::cell::panic_already_borrowed"
                | "core::cell::panic_already_mutably_borrowed"
        )
        || (name.starts_with("core::slice::") && name.ends_with("_fail"))
        || (name.starts_with("core::str::") && name.contains("_fail"))
        // defmt's panic entry points: defmt::export::panic, _defmt_panic, __defmt_default_panic.
        || (name.starts_with("defmt::") && path_has("panic"))
        || matches!(name, "_defmt_panic" | "__defmt_default_panic")
        || segs.last().is_some_and(|s| {
            s.starts_with("panic_bounds_check")
                || s.starts_with("panic_const_")
                || *s == "panic_fmt"
                || *s == "panic"
        })
}

/// Demangled name without the `::h<hash>` suffix.
fn demangle(raw: &str) -> String {
    format!("{:#}", rustc_demangle::demangle(raw))
}

/// Reads the ELF at `path` and decodes its call graph.
pub fn graph(path: &Path) -> Result<Graph, String> {
    let data = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
    graph_of(&data).map_err(|e| format!("{}: {e}", path.display()))
}

/// The call graph of an ELF held in `data`.
pub fn graph_of(data: &[u8]) -> Result<Graph, String> {
    let obj = object::File::parse(data).map_err(|e| format!("not an ELF file: {e}"))?;
    if obj.architecture() != object::Architecture::Arm {
        return Err(format!("not an Arm image ({:?})", obj.architecture()));
    }
    // Code bytes by address.
    let mut code: Vec<(u32, Vec<u8>)> = Vec::new();
    for s in obj.sections() {
        if s.kind() == SectionKind::Text {
            let bytes = s
                .data()
                .map_err(|e| format!("section {:?}: {e}", s.name()))?;
            code.push((s.address() as u32, bytes.to_vec()));
        }
    }
    // Mapping symbols: address → is code. The last one at or below an address decides.
    let mut mapping: BTreeMap<u32, bool> = BTreeMap::new();
    let mut funcs: Vec<Func> = Vec::new();
    for s in obj.symbols() {
        let Ok(name) = s.name() else { continue };
        let addr = s.address() as u32;
        if name == "$t" || name.starts_with("$t.") {
            mapping.insert(addr & !1, true);
        } else if name == "$d" || name.starts_with("$d.") || name == "$a" || name.starts_with("$a.")
        {
            mapping.insert(addr, false);
        } else if s.kind() == SymbolKind::Text && s.size() > 0 {
            funcs.push(Func {
                name: demangle(name),
                addr: addr & !1,
                size: s.size() as u32,
            });
        }
    }
    if funcs.is_empty() {
        return Err("no function symbols (a stripped image cannot be checked)".into());
    }
    funcs.sort_by_key(|f| (f.addr, std::cmp::Reverse(f.size)));
    funcs.dedup_by_key(|f| f.addr);
    let find = |addr: u32| -> Option<usize> {
        let i = funcs.partition_point(|f| f.addr <= addr);
        let f = funcs.get(i.checked_sub(1)?)?;
        (addr < f.addr + f.size).then_some(i - 1)
    };
    let bytes_at = |addr: u32| -> Option<u16> {
        code.iter().find_map(|(base, b)| {
            let o = addr.checked_sub(*base)? as usize;
            let h = b.get(o..o + 2)?;
            Some(u16::from_le_bytes([h[0], h[1]]))
        })
    };
    // BOARD_MODEL_TRACE_FN=<name> prints how every instruction of that function decodes.
    let trace = std::env::var("BOARD_MODEL_TRACE_FN").ok();
    let mut edges = vec![Vec::new(); funcs.len()];
    let mut indirect = vec![Vec::new(); funcs.len()];
    for (fi, f) in funcs.iter().enumerate() {
        let end = f.addr + f.size;
        let mut pc = f.addr;
        while pc < end {
            let is_code = mapping.range(..=pc).next_back().is_none_or(|(_, &c)| c);
            if !is_code {
                // Skip to the next mapping symbol (or the function's end).
                pc = mapping
                    .range(pc + 1..end)
                    .find(|(_, &c)| c)
                    .map_or(end, |(&a, _)| a);
                continue;
            }
            let Some(h1) = bytes_at(pc) else { break };
            let wide = h1 >> 11 >= 0b11101;
            let insn = if wide {
                let Some(h2) = bytes_at(pc + 2) else { break };
                decode32(pc, h1, h2)
            } else {
                decode16(pc, h1)
            };
            if trace.as_deref() == Some(f.name.as_str()) {
                eprintln!("0x{pc:08X} {h1:04X} {insn:?}");
            }
            match insn {
                Insn::Call(t) | Insn::Branch(t) => {
                    let internal = t >= f.addr && t < end;
                    if !internal {
                        if let Some(to) = find(t) {
                            let kind = if matches!(insn, Insn::Call(_)) {
                                EdgeKind::Call
                            } else {
                                EdgeKind::TailCall
                            };
                            edges[fi].push(Edge { site: pc, to, kind });
                        }
                    }
                }
                Insn::Indirect(what) => indirect[fi].push(Indirect { site: pc, what }),
                Insn::Other => {}
            }
            pc += if wide { 4 } else { 2 };
        }
    }
    Ok(Graph {
        funcs,
        edges,
        indirect,
    })
}

/// What one instruction means for the call graph.
#[derive(Debug, PartialEq)]
enum Insn {
    Call(u32),
    Branch(u32),
    Indirect(String),
    Other,
}

fn sign_extend(v: u32, bits: u32) -> u32 {
    (((v << (32 - bits)) as i32) >> (32 - bits)) as u32
}

/// A 16-bit Thumb instruction at `pc` (ARMv7-M ARM A5.2, A6.7.12 B, A6.7.21 CBZ, A6.7.20 BX,
/// A6.7.19 BLX, A6.7.77 MOV).
fn decode16(pc: u32, h: u16) -> Insn {
    let h = h as u32;
    if h & 0xF000 == 0xD000 && (h >> 8) & 0xF < 0xE {
        return Insn::Branch(pc + 4 + sign_extend((h & 0xFF) << 1, 9));
    }
    if h & 0xF800 == 0xE000 {
        return Insn::Branch(pc + 4 + sign_extend((h & 0x7FF) << 1, 12));
    }
    if h & 0xF500 == 0xB100 {
        let imm = ((h >> 9) & 1) << 6 | ((h >> 3) & 0x1F) << 1;
        return Insn::Branch(pc + 4 + imm);
    }
    if h & 0xFF00 == 0x4700 {
        let rm = (h >> 3) & 0xF;
        let link = h & 0x80 != 0;
        if !link && rm == 14 {
            return Insn::Other; // bx lr: a return
        }
        return Insn::Indirect(format!("{} {}", if link { "blx" } else { "bx" }, reg(rm)));
    }
    // MOV pc, Rm (T1, D:Rd = 15).
    if h & 0xFF00 == 0x4600 && (h & 0x87) == 0x87 {
        return Insn::Indirect(format!("mov pc, {}", reg((h >> 3) & 0xF)));
    }
    Insn::Other
}

/// A 32-bit Thumb instruction at `pc` (ARMv7-M ARM A5.3.4, A6.7.18 BL, A6.7.12 B T3/T4,
/// A6.7.42 LDR (immediate) T3/T4, A6.7.43 LDR (literal), A6.7.44 LDR (register), A6.7.40 LDM).
fn decode32(pc: u32, h1: u16, h2: u16) -> Insn {
    let (h1, h2) = (h1 as u32, h2 as u32);
    if h1 & 0xF800 == 0xF000 && h2 & 0x8000 == 0x8000 {
        let s = (h1 >> 10) & 1;
        let (j1, j2) = ((h2 >> 13) & 1, (h2 >> 11) & 1);
        let imm11 = h2 & 0x7FF;
        match h2 & 0x5000 {
            // B T4 (0x1000) and BL (0x5000): I1 = NOT(J1 XOR S), I2 = NOT(J2 XOR S).
            0x1000 | 0x5000 => {
                let (i1, i2) = (!(j1 ^ s) & 1, !(j2 ^ s) & 1);
                let imm = s << 24 | i1 << 23 | i2 << 22 | (h1 & 0x3FF) << 12 | imm11 << 1;
                let t = pc.wrapping_add(4).wrapping_add(sign_extend(imm, 25));
                return if h2 & 0x4000 != 0 {
                    Insn::Call(t)
                } else {
                    Insn::Branch(t)
                };
            }
            // B T3 (conditional); cond 111x is the misc-control space (MSR, hints, …).
            0x0000 if (h1 >> 6) & 0xE != 0xE => {
                let imm = s << 20 | j2 << 19 | j1 << 18 | (h1 & 0x3F) << 12 | imm11 << 1;
                return Insn::Branch(pc.wrapping_add(4).wrapping_add(sign_extend(imm, 21)));
            }
            _ => return Insn::Other,
        }
    }
    // Loads into PC: LDR.W (immediate, register, literal) with Rt = 15.
    if h1 & 0xFF70 == 0xF850 && (h2 >> 12) == 0xF {
        let rn = h1 & 0xF;
        // `ldr pc, [sp], #4` (a one-register pop) is a return.
        if rn == 13 {
            return Insn::Other;
        }
        return Insn::Indirect(format!("ldr pc, [{}…]", reg(rn)));
    }
    if h1 & 0xFF7F == 0xF85F && (h2 >> 12) == 0xF {
        return Insn::Indirect("ldr pc, [pc…]".into());
    }
    // LDM with PC in the list from a register other than SP.
    if h1 & 0xFFD0 == 0xE890 && h2 & 0x8000 != 0 && h1 & 0xF != 13 {
        return Insn::Indirect(format!("ldm {}, {{…, pc}}", reg(h1 & 0xF)));
    }
    Insn::Other
}

fn reg(r: u32) -> String {
    match r {
        13 => "sp".into(),
        14 => "lr".into(),
        15 => "pc".into(),
        r => format!("r{r}"),
    }
}

impl Graph {
    /// Indices of the functions whose name is `pattern`, or (with a trailing `*`) starts with it.
    pub fn matching(&self, pattern: &str) -> Vec<usize> {
        let (p, prefix) = match pattern.strip_suffix('*') {
            Some(p) => (p, true),
            None => (pattern, false),
        };
        (0..self.funcs.len())
            .filter(|&i| {
                let n = &self.funcs[i].name;
                if prefix {
                    n.starts_with(p)
                } else {
                    n == p
                }
            })
            .collect()
    }

    /// Breadth-first from `roots`: stops at panic functions (recorded with the shortest chain to
    /// them) and at functions named in `allowed` (pattern → reason; not entered).
    pub fn check(&self, roots: &[usize], allowed: &[(String, String)]) -> Finding {
        let allowed_reason = |i: usize| -> Option<&String> {
            allowed.iter().find_map(|(p, why)| {
                let n = &self.funcs[i].name;
                let hit = match p.strip_suffix('*') {
                    Some(p) => n.starts_with(p),
                    None => n == p,
                };
                hit.then_some(why)
            })
        };
        // parent[i] = (caller, site).
        let mut parent: HashMap<usize, Option<(usize, u32)>> = HashMap::new();
        let mut queue: VecDeque<usize> = VecDeque::new();
        for &r in roots {
            if parent.insert(r, None).is_none() {
                queue.push_back(r);
            }
        }
        let mut panics = Vec::new();
        let mut allowed_reached = Vec::new();
        let mut indirect = Vec::new();
        let mut seen_panic_edges = std::collections::HashSet::new();
        // (function, the call site in its caller by which it was entered; 0 for the root).
        let chain = |parent: &HashMap<usize, Option<(usize, u32)>>, mut i: usize| {
            let mut c = Vec::new();
            while let Some(Some((p, site))) = parent.get(&i) {
                c.push((i, *site));
                i = *p;
            }
            c.push((i, 0));
            c.reverse();
            c
        };
        while let Some(f) = queue.pop_front() {
            for ind in &self.indirect[f] {
                indirect.push((f, ind.clone()));
            }
            for e in &self.edges[f] {
                let to = e.to;
                if is_panic_fn(&self.funcs[to].name) {
                    if seen_panic_edges.insert((f, to)) {
                        let mut c = chain(&parent, f);
                        c.push((to, e.site));
                        panics.push(c);
                    }
                    continue;
                }
                if parent.contains_key(&to) {
                    continue;
                }
                if let Some(why) = allowed_reason(to) {
                    parent.insert(to, Some((f, e.site)));
                    allowed_reached.push((to, why.clone()));
                    continue;
                }
                parent.insert(to, Some((f, e.site)));
                queue.push_back(to);
            }
        }
        Finding {
            roots: roots.to_vec(),
            reachable: parent.len() - allowed_reached.len(),
            panics,
            allowed_reached,
            indirect,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decodes_bl_and_tail_branches() {
        // bl from the F446 image: 0x080008D4: F004 FACE → 0x08004E74 (as elf.rs's test).
        assert_eq!(
            decode32(0x0800_08D4, 0xF004, 0xFACE),
            Insn::Call(0x0800_4E74)
        );
        // b.w (T4) backwards: F7FF BFFE at 0x1000 branches to itself.
        assert_eq!(decode32(0x1000, 0xF7FF, 0xBFFE), Insn::Branch(0x1000));
        // beq.w (T3) +0x100: S=0, cond=0000, imm6=0, J1=J2=0, imm11=0x80.
        assert_eq!(decode32(0x1000, 0xF000, 0x8080), Insn::Branch(0x1104));
        // b<c>.w with cond 1110 is not a branch (misc control space, e.g. msr).
        assert_eq!(decode32(0x1000, 0xF380, 0x8800), Insn::Other);
    }

    #[test]
    fn decodes_16_bit_branches() {
        // b.n -2 words: E7FE at 0x2000 → itself.
        assert_eq!(decode16(0x2000, 0xE7FE), Insn::Branch(0x2000));
        // bne.n +4: D102 at 0x2000 → 0x2008.
        assert_eq!(decode16(0x2000, 0xD102), Insn::Branch(0x2008));
        // udf (cond 1110) and svc (1111) are not branches.
        assert_eq!(decode16(0x2000, 0xDE00), Insn::Other);
        assert_eq!(decode16(0x2000, 0xDF00), Insn::Other);
        // cbz r0, +8: B110 at 0x2000 → 0x2000 + 4 + 4.
        assert_eq!(decode16(0x2000, 0xB110), Insn::Branch(0x2008));
        // bx lr is a return; blx r3 and bx r2 are indirect.
        assert_eq!(decode16(0x2000, 0x4770), Insn::Other);
        assert_eq!(decode16(0x2000, 0x4798), Insn::Indirect("blx r3".into()));
        assert_eq!(decode16(0x2000, 0x4710), Insn::Indirect("bx r2".into()));
    }

    #[test]
    fn loads_into_pc_from_the_stack_are_returns() {
        // ldr.w pc, [sp], #4 (F85D FB04): pop {pc}.
        assert_eq!(decode32(0, 0xF85D, 0xFB04), Insn::Other);
        // ldr.w pc, [r0, #4] (F8D0 F004): indirect.
        assert!(matches!(decode32(0, 0xF8D0, 0xF004), Insn::Indirect(_)));
        // pop.w {r4, pc} (E8BD 8010): a return.
        assert_eq!(decode32(0, 0xE8BD, 0x8010), Insn::Other);
    }

    #[test]
    fn names_the_panic_functions() {
        for n in [
            "core::panicking::panic_bounds_check",
            "core::panicking::panic_const::panic_const_div_by_zero",
            "core::option::unwrap_failed",
            "core::result::unwrap_failed",
            "core::slice::index::slice_end_index_len_fail",
            "core::slice::index::slice_index_order_fail",
            "core::str::slice_error_fail",
            "core::cell::panic_already_borrowed",
            "rust_begin_unwind",
            "defmt::export::panic",
            "__defmt_default_panic",
        ] {
            assert!(is_panic_fn(n), "{n}");
        }
        for n in [
            "saw_core::controller::Controller::on_sample",
            "core::fmt::write",
            "saw_firmware::rf::emergency_off",
            "core::slice::sort::stable::sort",
        ] {
            assert!(!is_panic_fn(n), "{n}");
        }
    }
}
