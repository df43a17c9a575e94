//! The virtual board's flash: a file of NOR flash pages (erased = 0xFF, a write only clears
//! bits), written through after every operation so a killed `host-sim serve` leaves exactly what
//! a power cut leaves; under it the same `saw_store::SceneStore` the firmware uses. An erase
//! takes as long as the board's (`erase_time`), so a save answers as late as on the board.
//!
//! One board owns a flash file: it holds an exclusive lock on it (flock) while it runs, and a
//! second `serve --flash` on the same file is refused instead of writing over the first's
//! saves (the two would each rewrite the whole file from their own copy).

use std::fs::File;
use std::os::unix::fs::FileExt;
use std::path::Path;
use std::time::Duration;

use embedded_storage_async::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};
use nix::errno::Errno;
use nix::fcntl::{Flock, FlockArg};
use saw_core::scene::Config;
use saw_link::msg::StoreFault;
use saw_store::{Saved, SceneStore};

use super::board::Persist;

/// The store's geometry on a board (`saw_boards::StoreLayout`: the F446's sectors 6–7, the
/// G474's last 8 pages of bank 2).
#[derive(Clone, Copy, Debug)]
pub struct Geometry {
    /// Erase unit, bytes.
    pub erase_bytes: u32,
    /// Erase units.
    pub units: u32,
    /// Programming unit, bytes (F446 x32 word: 4; G474 double word: 8).
    pub write_bytes: u32,
    /// How long one erase unit takes to erase, the datasheet's typical figure (`erase_time`).
    pub erase_time: Duration,
}

/// The typical erase time of one erase unit of `erase_bytes`, as the board model times its
/// flash (docs/board-model.md, FLASH programming): a 128 KiB sector of the F446 at ×32
/// parallelism 1 s (DS10693 §6.3.11 t_ERASE128KB: 1 s typical, 2 s max), a 2 KiB page of the
/// G474 22 ms (DS12288 §5.3.10 t_ERASE: 22 ms typical, 40 ms max); other sizes scale with the
/// page's per-byte time. A save that reclaims a unit answers that much later; `saw save` waits
/// for it (`saw::SAVE_TIMEOUT`).
pub fn erase_time(erase_bytes: u32) -> Duration {
    match erase_bytes {
        0x2_0000 => Duration::from_secs(1),
        0x800 => Duration::from_millis(22),
        b => Duration::from_secs_f64(0.022 * b as f64 / 2048.0),
    }
}

/// The store's geometry for `board`.
pub fn geometry(board: &saw_boards::BoardDef) -> Geometry {
    let s = board.store;
    Geometry {
        erase_bytes: s.erase_bytes,
        units: s.bytes / s.erase_bytes,
        write_bytes: s.write_bytes,
        erase_time: erase_time(s.erase_bytes),
    }
}

/// A flash error: the file could not be written, or an access broke the NOR rules.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FileFlashError {
    /// Outside the flash or not aligned.
    Access,
    /// The file could not be written.
    Io,
}

impl NorFlashError for FileFlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            FileFlashError::Access => NorFlashErrorKind::OutOfBounds,
            FileFlashError::Io => NorFlashErrorKind::Other,
        }
    }
}

/// NOR flash in a file.
pub struct FileFlash<const WRITE: usize, const ERASE: usize> {
    /// The file, locked for this board while it lives; every operation is written through it.
    file: Flock<File>,
    data: Vec<u8>,
    /// Time one erase unit takes; the caller (the link, the sample loop) waits it out as the
    /// board's link task does.
    erase_time: Duration,
}

impl<const WRITE: usize, const ERASE: usize> FileFlash<WRITE, ERASE> {
    /// Opens (or creates, erased) `units` erase units in `path`, locked for this board: a file
    /// another board holds is refused.
    pub fn open(path: &Path, units: usize) -> Result<Self, String> {
        let size = units * ERASE;
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(path)
            .map_err(|e| format!("--flash {}: {e}", path.display()))?;
        let file = match Flock::lock(file, FlockArg::LockExclusiveNonblock) {
            Ok(f) => f,
            Err((_, Errno::EWOULDBLOCK)) => {
                return Err(format!(
                    "--flash {}: another host-sim serve is using this flash file; stop it or \
                     choose another file",
                    path.display()
                ))
            }
            Err((_, e)) => return Err(format!("--flash {}: cannot lock it: {e}", path.display())),
        };
        let len = file
            .metadata()
            .map_err(|e| format!("--flash {}: {e}", path.display()))?
            .len() as usize;
        let data = match len {
            // Created just now (or left empty): an erased flash.
            0 => vec![0xFF; size],
            n if n == size => {
                let mut d = vec![0; size];
                file.read_exact_at(&mut d, 0)
                    .map_err(|e| format!("--flash {}: {e}", path.display()))?;
                d
            }
            n => {
                return Err(format!(
                    "--flash {}: {n} bytes, not this board's {size}-byte store",
                    path.display()
                ))
            }
        };
        let f = Self {
            file,
            data,
            erase_time: Duration::ZERO,
        };
        f.persist()
            .map_err(|_| format!("--flash {}: cannot write", path.display()))?;
        Ok(f)
    }

    /// Each erase unit takes `t` to erase from now on.
    pub fn with_erase_time(mut self, t: Duration) -> Self {
        self.erase_time = t;
        self
    }

    fn persist(&self) -> Result<(), FileFlashError> {
        // In place through the locked file: its size never changes, so nothing truncates it.
        self.file
            .write_all_at(&self.data, 0)
            .map_err(|_| FileFlashError::Io)
    }

    fn range(
        &self,
        offset: u32,
        len: usize,
        align: usize,
    ) -> Result<std::ops::Range<usize>, FileFlashError> {
        let start = offset as usize;
        let end = start.checked_add(len).ok_or(FileFlashError::Access)?;
        if end > self.data.len() || !start.is_multiple_of(align) || !len.is_multiple_of(align) {
            return Err(FileFlashError::Access);
        }
        Ok(start..end)
    }
}

impl<const WRITE: usize, const ERASE: usize> ErrorType for FileFlash<WRITE, ERASE> {
    type Error = FileFlashError;
}

impl<const WRITE: usize, const ERASE: usize> ReadNorFlash for FileFlash<WRITE, ERASE> {
    const READ_SIZE: usize = 1;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        let r = self.range(offset, bytes.len(), 1)?;
        bytes.copy_from_slice(&self.data[r]);
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.data.len()
    }
}

impl<const WRITE: usize, const ERASE: usize> NorFlash for FileFlash<WRITE, ERASE> {
    const WRITE_SIZE: usize = WRITE;
    const ERASE_SIZE: usize = ERASE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        let r = self.range(from, to.saturating_sub(from) as usize, ERASE)?;
        // The board answers nothing until the erase ends (the F446's CPU is stalled, the
        // G474's link task awaits it): neither does the virtual board.
        std::thread::sleep(self.erase_time * (r.len() / ERASE) as u32);
        self.data[r].fill(0xFF);
        self.persist()
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        let r = self.range(offset, bytes.len(), WRITE)?;
        // NOR: programming only clears bits.
        for (d, b) in self.data[r].iter_mut().zip(bytes) {
            *d &= *b;
        }
        self.persist()
    }
}

/// The scene store over a flash file.
pub struct FileStore<const WRITE: usize, const ERASE: usize> {
    store: SceneStore<FileFlash<WRITE, ERASE>>,
}

impl<const WRITE: usize, const ERASE: usize> Persist for FileStore<WRITE, ERASE> {
    fn load(&mut self) -> Option<(u32, Config)> {
        match embassy_futures::block_on(self.store.load()) {
            Ok(Some(s)) => Some((s.scene_id, s.config)),
            Ok(None) => None,
            Err(e) => {
                log::warn!("boot: the saved scene cannot be read ({e})");
                None
            }
        }
    }

    fn save(&mut self, scene_id: u32, config: &Config) -> Result<(), StoreFault> {
        let saved = Saved {
            scene_id,
            config: config.clone(),
        };
        embassy_futures::block_on(self.store.save(&saved)).map_err(StoreFault::from)
    }
}

/// Opens the store of `board` in the file at `path`.
pub fn open(path: &Path, board: &saw_boards::BoardDef) -> Result<Box<dyn Persist + Send>, String> {
    let g = geometry(board);
    fn make<const W: usize, const E: usize>(
        path: &Path,
        units: u32,
        erase_time: Duration,
    ) -> Result<Box<dyn Persist + Send>, String> {
        let flash = FileFlash::<W, E>::open(path, units as usize)?.with_erase_time(erase_time);
        let store = SceneStore::new(flash, 0..units * E as u32).map_err(|e| e.to_string())?;
        Ok(Box::new(FileStore { store }))
    }
    match (g.write_bytes, g.erase_bytes) {
        (8, 2048) => make::<8, 2048>(path, g.units, g.erase_time),
        (4, 0x2_0000) => make::<4, 0x2_0000>(path, g.units, g.erase_time),
        (w, e) => Err(format!(
            "{}: no virtual flash for {w}-byte writes and {e}-byte erase units",
            board.name
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A G474-sized flash file in a fresh folder of this test.
    fn scratch(name: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("host-sim-flash-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d.join("flash.bin")
    }

    /// Two boards on one flash file: the second is refused with one line naming the file,
    /// while the first lives; once it is dropped the file opens again, with what it wrote.
    #[test]
    fn a_flash_file_serves_one_board_at_a_time() {
        let path = scratch("one");
        let mut first = FileFlash::<8, 2048>::open(&path, 2).unwrap();
        embassy_futures::block_on(first.write(0, &[0x12; 8])).unwrap();
        let e = FileFlash::<8, 2048>::open(&path, 2).err().unwrap();
        assert_eq!(
            e,
            format!(
                "--flash {}: another host-sim serve is using this flash file; stop it or choose \
                 another file",
                path.display()
            )
        );
        // The store's opener says the same (the lock comes before the size check).
        let e = open(&path, &saw_boards::NUCLEO_G474RE).err().unwrap();
        assert!(
            e.contains("another host-sim serve is using this flash file"),
            "{e}"
        );
        drop(first);
        let mut again = FileFlash::<8, 2048>::open(&path, 2).unwrap();
        let mut got = [0u8; 9];
        embassy_futures::block_on(again.read(0, &mut got)).unwrap();
        assert_eq!(got, [0x12, 0x12, 0x12, 0x12, 0x12, 0x12, 0x12, 0x12, 0xFF]);
        assert_eq!(std::fs::metadata(&path).unwrap().len(), 2 * 2048);
    }
}
