//! Store images for the save checks: the flash a board's store is left in by earlier saves,
//! built on the host with the same `saw-store` the firmware runs, over RAM NOR flash with the
//! board's geometry (`saw_boards::StoreLayout`).

use embedded_storage_async::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};
use saw_core::scene::Config;
use saw_store::{Saved, SceneStore};

/// NOR flash in RAM: erased = 0xFF, a write only clears bits; counts erases.
#[derive(Clone)]
struct RamNor<const W: usize, const E: usize> {
    data: Vec<u8>,
    erases: u32,
}

#[derive(Debug, Clone, Copy)]
struct Bounds;

impl NorFlashError for Bounds {
    fn kind(&self) -> NorFlashErrorKind {
        NorFlashErrorKind::OutOfBounds
    }
}

impl<const W: usize, const E: usize> ErrorType for RamNor<W, E> {
    type Error = Bounds;
}

impl<const W: usize, const E: usize> ReadNorFlash for RamNor<W, E> {
    const READ_SIZE: usize = 1;
    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Bounds> {
        let o = offset as usize;
        let src = self.data.get(o..o + bytes.len()).ok_or(Bounds)?;
        bytes.copy_from_slice(src);
        Ok(())
    }
    fn capacity(&self) -> usize {
        self.data.len()
    }
}

impl<const W: usize, const E: usize> NorFlash for RamNor<W, E> {
    const WRITE_SIZE: usize = W;
    const ERASE_SIZE: usize = E;
    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Bounds> {
        self.data
            .get_mut(from as usize..to as usize)
            .ok_or(Bounds)?
            .fill(0xFF);
        self.erases += 1;
        Ok(())
    }
    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Bounds> {
        let o = offset as usize;
        let dst = self.data.get_mut(o..o + bytes.len()).ok_or(Bounds)?;
        for (d, b) in dst.iter_mut().zip(bytes) {
            *d &= *b;
        }
        Ok(())
    }
}

/// The store of `board` after as many saves of `scene(i)` (i = 0, 1, …) as fit before the next
/// one must erase a unit: its bytes (for `board.store.origin`), the last scene saved, and how
/// many saves that took.
pub fn before_an_erase(
    board: &saw_boards::BoardDef,
    scene: impl Fn(usize) -> Config,
) -> Result<(Vec<u8>, Saved, usize), String> {
    fn fill<const W: usize, const E: usize>(
        bytes: usize,
        scene: &dyn Fn(usize) -> Config,
    ) -> Result<(Vec<u8>, Saved, usize), String> {
        let mut flash = RamNor::<W, E> {
            data: vec![0xFF; bytes],
            erases: 0,
        };
        let mut last: Option<Saved> = None;
        for i in 0..100_000 {
            let before = flash.data.clone();
            let config = scene(i);
            let saved = Saved {
                scene_id: saw_link::scene_id(&config),
                config,
            };
            let mut store = SceneStore::new(flash, 0..bytes as u32).map_err(|e| e.to_string())?;
            embassy_futures::block_on(store.save(&saved)).map_err(|e| e.to_string())?;
            flash = store.into_flash();
            if flash.erases > 0 {
                let last = last.ok_or("the first save already erased")?;
                return Ok((before, last, i));
            }
            last = Some(saved);
        }
        Err("no erase after 100 000 saves".into())
    }
    let s = board.store;
    match (s.write_bytes, s.erase_bytes) {
        (4, 0x2_0000) => fill::<4, 0x2_0000>(s.bytes as usize, &scene),
        (8, 0x800) => fill::<8, 0x800>(s.bytes as usize, &scene),
        (w, e) => Err(format!(
            "no RAM flash for {w}-byte writes and {e}-byte units"
        )),
    }
}
