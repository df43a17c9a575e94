//! The saved scene in flash. One item (key 0) of a `sequential-storage` map over two or more
//! erase units: a new save is written after the old one and only then counts, and a page is
//! erased only once its items live on elsewhere, so a power cut at any write or erase leaves the
//! old scene or the new one, whole (`tests/power_cut.rs` cuts at every byte).
//!
//! Why the map rather than the queue: the map keeps the newest value of a key and migrates it
//! when it reclaims a page; a queue would need the reader to skip to its last item and the
//! writer to pop old ones, two steps a cut could separate.
//!
//! The board can wrap the flash in [`Hooks`]: work after every erase (the F446 flushes its flash
//! caches, which an erase leaves stale) and a verdict on every read (the G474 refuses bytes a
//! double ECC error was reported in), two things sequential-storage cannot see.
//!
//! A write unit the board refuses to read (on the G474, a double word whose program or erase a
//! power loss cut: its ECC is bad) is repaired by [`SceneStore::zero_unreadable`], which
//! programs it to all zeros — a valid ECC code word, which the G474 programs over any content
//! (RM0440 §5.7.5 PROGERR: "except if the data to write is 0x0000 0000"); ST's EEPROM emulation
//! neutralises a word a power loss corrupted the same way. sequential-storage then sees a torn
//! write of its own kind: a zeroed item header fails its length CRC and is stepped over a word at
//! a time, a zeroed word inside an item's data fails the item's CRC and the item is skipped (the
//! load finds the item saved before it), a zeroed page marker is a written marker (markers are
//! written as zeros), and a page whose erase was cut, zeroed throughout, is a closed page
//! without live items, which the next save's repair erases (`tests/ecc_repair.rs`).
//!
//! The item is `FORMAT ‖ postcard(scene_id, Config)`. A stored item of another format, or one
//! that does not decode (or leaves bytes after the scene), is reported, never returned: the
//! caller boots the embedded or default scene, and the next save replaces the item. A decoded
//! scene is not checked here; the caller compiles it and falls back to the default if the
//! controller refuses it. `FORMAT` must change with `Config`'s encoding (`tests/foreign.rs` pins
//! format 1's bytes); it did not when `limits.max_level_percent` was added, so a scene saved by
//! firmware from before that is format 1 of an older layout, which is reported as not decoding.
//!
//! A 2D scene (issue #36, feature `plane`: windows on the touch overlay) is an item under the
//! same key, `FORMAT_2D ‖ postcard(scene_id, PlaneScene)`: one board reads one sensor and boots
//! one scene, so a save of either kind replaces the other. The tag keeps them apart: a 1D load
//! of a 2D item (or the reverse) is [`StoreError::WrongKind`], never decoded. A 2D scene encodes
//! to up to ~1 460 bytes (the largest a scene file allows), so a 2D store's item buffer is
//! [`ITEM_BYTES_2D`] (`SceneStore<F, ITEM_BYTES_2D>`); a 1D store keeps its 768 bytes.

#![no_std]

use core::ops::Range;

use embedded_storage_async::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};
use saw_core::scene::Config;
use sequential_storage::cache::key_pointers::ArrayKeyPointers;
use sequential_storage::cache::{Cache, Uncached};
use sequential_storage::map::{MapConfig, MapStorage};

/// The item's layout version: bump it when `Config`'s encoding changes.
pub const FORMAT: u8 = 1;
/// A 2D item's tag (`FORMAT_2D ‖ postcard(scene_id, PlaneScene)`): 0x80 | its layout version,
/// far from the 1D versions, which count up from 1. Bump it when `PlaneScene`'s encoding
/// changes.
pub const FORMAT_2D: u8 = 0x81;
/// The largest item, bytes: a format byte, the id and the largest `Config` (8 regions of the
/// widest texture and 16 lines encode to under 500 bytes, `tests::largest_scene_fits`), with
/// room for the map's key and word alignment.
pub const ITEM_BYTES: usize = 768;
/// A 2D store's item buffer: the link's whole payload (`saw_link::frame::MAX_PAYLOAD`), so any
/// 2D scene the link accepts fits the buffer (the largest a scene file allows encodes to ~1 460
/// bytes, `tests/plane.rs`). The flash's erase unit bounds an item too: on the G474's 2 KiB
/// pages sequential-storage takes items up to 2 024 bytes; a larger one is `TooLarge`.
pub const ITEM_BYTES_2D: usize = 2048;
const KEY: u8 = 0;

/// A scene as stored.
#[derive(Clone, Debug, PartialEq)]
pub struct Saved {
    /// Its id (`saw_link::scene_id`).
    pub scene_id: u32,
    /// The scene.
    pub config: Config,
}

/// A 2D scene as stored.
#[cfg(feature = "plane")]
#[derive(Clone, Debug, PartialEq)]
pub struct Saved2d {
    /// Its id (`saw_link::plane_scene_id`).
    pub scene_id: u32,
    /// The scene and its plate.
    pub scene: saw_link::msg::PlaneScene,
}

/// Why the store could not be read or written. Nothing is lost on any of these: a failed save
/// leaves the previous scene readable.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum StoreError {
    /// The range is not whole erase units, or fewer than two.
    BadRange,
    /// The flash refused a read, write or erase (or power went during one).
    Flash,
    /// The store's bookkeeping is inconsistent (erase it to recover).
    Corrupted,
    /// A stored item of another layout version.
    OtherFormat {
        /// The version found.
        found: u8,
    },
    /// A stored 2D item of another layout version (a 2D load).
    OtherFormat2d {
        /// The tag found.
        found: u8,
    },
    /// The stored scene is of the other kind: a 2D scene on a board that runs 1D scenes
    /// (`saved_2d`), or a 1D scene on one that runs 2D scenes.
    WrongKind {
        /// The stored scene is 2D (the load was 1D).
        saved_2d: bool,
    },
    /// A stored item that does not decode.
    Undecodable,
    /// The scene does not fit an item.
    TooLarge,
    /// The board reported bytes read from the store as corrupted (on the G474, a double ECC
    /// error: a write cut by a power loss); `zero_unreadable` repairs the store, or erase it.
    Unreadable,
    /// The save wrote its item but reads back another scene or none (the store's free space
    /// held bytes that were not erased); erase the store.
    NotStored,
}

impl core::fmt::Display for StoreError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            StoreError::BadRange => write!(
                f,
                "the store's flash range is not two or more whole erase units"
            ),
            StoreError::Flash => write!(f, "the flash refused a read, write or erase"),
            StoreError::Corrupted => write!(
                f,
                "the store's bookkeeping is inconsistent; erase it to recover"
            ),
            StoreError::OtherFormat { found } => {
                write!(
                    f,
                    "the saved scene has layout version {found}, this firmware reads {FORMAT}"
                )
            }
            StoreError::OtherFormat2d { found } => write!(
                f,
                "the saved 2D scene has layout tag {found:#04x}, this firmware reads {FORMAT_2D:#04x}"
            ),
            StoreError::WrongKind { saved_2d: true } => write!(
                f,
                "the saved scene is a 2D scene (windows on the touch overlay) and this firmware runs 1D scenes; the next save replaces it"
            ),
            StoreError::WrongKind { saved_2d: false } => write!(
                f,
                "the saved scene is a 1D scene (regions along the slide rheostat) and this firmware runs 2D scenes; the next save replaces it"
            ),
            StoreError::Undecodable => write!(f, "the saved scene does not decode"),
            StoreError::TooLarge => write!(
                f,
                "the scene does not fit the store's item ({ITEM_BYTES} bytes for a 1D scene, {ITEM_BYTES_2D} for a 2D one, at most an erase unit)"
            ),
            StoreError::Unreadable => write!(
                f,
                "the flash reported bytes read from the store as corrupted (ECC)"
            ),
            StoreError::NotStored => write!(
                f,
                "the scene read back after the save is not the one written (the store's free flash was not erased); erase the store"
            ),
        }
    }
}

/// What the link answers for a save that failed with this error.
impl From<StoreError> for saw_link::msg::StoreFault {
    fn from(e: StoreError) -> Self {
        match e {
            StoreError::TooLarge => saw_link::msg::StoreFault::TooLarge,
            _ => saw_link::msg::StoreFault::Flash,
        }
    }
}

fn from_ss<E>(e: sequential_storage::Error<HookedError<E>>) -> StoreError {
    match e {
        sequential_storage::Error::Storage {
            value: HookedError::Corrupted,
            ..
        } => StoreError::Unreadable,
        sequential_storage::Error::Corrupted { .. }
        | sequential_storage::Error::LogicBug { .. } => StoreError::Corrupted,
        sequential_storage::Error::BufferTooSmall(_)
        | sequential_storage::Error::ItemTooBig
        | sequential_storage::Error::SerializationError(_) => StoreError::TooLarge,
        _ => StoreError::Flash,
    }
}

/// What the board does around the store's flash operations.
#[derive(Clone, Copy, Debug)]
pub struct Hooks {
    /// Runs after every erase, whether it succeeded or not (the F446 flushes its ART caches
    /// here: a line cached before the erase would otherwise still read the old bytes).
    pub after_erase: fn(),
    /// Runs after every successful read with the range read (offset in the flash, length in
    /// bytes): true if those bytes cannot be trusted, and the read then fails with
    /// [`StoreError::Unreadable`] (the G474: a double ECC error was reported inside them).
    pub read_corrupted: fn(u32, usize) -> bool,
    /// Runs after [`SceneStore::zero_unreadable`] programmed the write unit at the offset (its
    /// length the second argument) to zeros: the board forgets the corruption it reported there
    /// (the G474 clears its record of the double ECC error, so the next one is recorded).
    pub zeroed: fn(u32, usize),
}

impl Hooks {
    /// Nothing after an erase, every read trusted.
    pub const NONE: Hooks = Hooks {
        after_erase: || {},
        read_corrupted: |_, _| false,
        zeroed: |_, _| {},
    };
}

/// What [`SceneStore::zero_unreadable`] did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Zeroed {
    /// The first write unit zeroed (offset in the flash).
    pub first: u32,
    /// Write units zeroed.
    pub count: u32,
}

/// The largest write unit `zero_unreadable` handles (the G474's double word is 8 bytes).
const MAX_ZERO_UNIT: usize = 32;

/// The flash with the board's [`Hooks`] around it: what sequential-storage reads, writes and
/// erases.
pub struct HookedFlash<F> {
    flash: F,
    hooks: Hooks,
}

/// A flash error, or bytes the board reported as corrupted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HookedError<E> {
    Flash(E),
    Corrupted,
}

impl<E: NorFlashError> NorFlashError for HookedError<E> {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            HookedError::Flash(e) => e.kind(),
            HookedError::Corrupted => NorFlashErrorKind::Other,
        }
    }
}

impl<F: NorFlash> ErrorType for HookedFlash<F> {
    type Error = HookedError<F::Error>;
}

impl<F: NorFlash> ReadNorFlash for HookedFlash<F> {
    const READ_SIZE: usize = F::READ_SIZE;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        self.flash
            .read(offset, bytes)
            .await
            .map_err(HookedError::Flash)?;
        if (self.hooks.read_corrupted)(offset, bytes.len()) {
            return Err(HookedError::Corrupted);
        }
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.flash.capacity()
    }
}

impl<F: NorFlash> NorFlash for HookedFlash<F> {
    const WRITE_SIZE: usize = F::WRITE_SIZE;
    const ERASE_SIZE: usize = F::ERASE_SIZE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        let r = self.flash.erase(from, to).await;
        (self.hooks.after_erase)();
        r.map_err(HookedError::Flash)
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        self.flash
            .write(offset, bytes)
            .await
            .map_err(HookedError::Flash)
    }
}

/// `SceneStore::zero_unreadable`'s walk over `range` in units of `unit` bytes.
async fn zero_unreadable_in<F: NorFlash>(
    flash: &mut HookedFlash<F>,
    range: Range<u32>,
    unit: usize,
) -> Result<Option<Zeroed>, StoreError> {
    // Word-aligned, as some flash drivers want a write's buffer (sequential-storage's too).
    #[repr(align(8))]
    struct Unit([u8; MAX_ZERO_UNIT]);
    let zeros = Unit([0; MAX_ZERO_UNIT]);
    let mut buf = Unit([0; MAX_ZERO_UNIT]);
    let mut done: Option<Zeroed> = None;
    for offset in range.step_by(unit) {
        match flash.read(offset, &mut buf.0[..unit]).await {
            Ok(()) => continue,
            Err(HookedError::Flash(_)) => return Err(StoreError::Flash),
            Err(HookedError::Corrupted) => {}
        }
        flash
            .write(offset, &zeros.0[..unit])
            .await
            .map_err(|_| StoreError::Flash)?;
        (flash.hooks.zeroed)(offset, unit);
        let z = done.get_or_insert(Zeroed {
            first: offset,
            count: 0,
        });
        z.count += 1;
    }
    Ok(done)
}

/// `body` decoded as a `T` with nothing after it: `save` writes the scene and nothing after it,
/// so bytes left over mean another layout whose start happened to decode, not this scene
/// (`tests/foreign.rs`).
fn decode_whole<T: serde::de::DeserializeOwned>(body: &[u8]) -> Result<T, StoreError> {
    let (value, rest): (T, &[u8]) =
        postcard::take_from_bytes(body).map_err(|_| StoreError::Undecodable)?;
    if !rest.is_empty() {
        return Err(StoreError::Undecodable);
    }
    Ok(value)
}

/// The map's cache: where the one key's newest item is. Without it, reclaiming a unit looks up
/// every item it holds across the whole store to see whether a newer copy exists — quadratic in
/// the saves a unit holds: a 128 KiB F446 sector holds ~1 900 saves of the default scene, and the
/// board model found one such save still searching after 1.7 s (`board-model check`, save).
type KeyCache = Cache<Uncached, Uncached, ArrayKeyPointers<u8, 1>, u8>;

/// The scene store over `flash`, in `range` (offsets in `flash`), with an item buffer of `N`
/// bytes ([`ITEM_BYTES`] for 1D scenes, [`ITEM_BYTES_2D`] for 2D ones).
pub struct SceneStore<F: NorFlash, const N: usize = ITEM_BYTES> {
    /// Always `Some` between calls: `erase` takes it apart to start the map afresh.
    map: Option<MapStorage<u8, HookedFlash<F>, KeyCache>>,
    range: Range<u32>,
    buf: [u8; N],
}

fn map_over<F: NorFlash>(
    flash: HookedFlash<F>,
    range: Range<u32>,
) -> Result<MapStorage<u8, HookedFlash<F>, KeyCache>, StoreError> {
    let config = MapConfig::try_new(range).map_err(|_| StoreError::BadRange)?;
    Ok(MapStorage::new(
        flash,
        config,
        Cache::new(Uncached, Uncached, ArrayKeyPointers::new()),
    ))
}

impl<F: NorFlash> SceneStore<F> {
    /// A store of 1D scenes over `range` of `flash`: whole erase units, at least two.
    pub fn new(flash: F, range: Range<u32>) -> Result<Self, StoreError> {
        Self::with_hooks(flash, range, Hooks::NONE)
    }

    /// The same, with the board's `hooks` around every read and erase.
    pub fn with_hooks(flash: F, range: Range<u32>, hooks: Hooks) -> Result<Self, StoreError> {
        Self::sized(flash, range, hooks)
    }
}

impl<F: NorFlash, const N: usize> SceneStore<F, N> {
    /// A store with an item buffer of `N` bytes (`SceneStore::<F, ITEM_BYTES_2D>::sized` for 2D
    /// scenes) over `range` of `flash`, with the board's `hooks`.
    pub fn sized(flash: F, range: Range<u32>, hooks: Hooks) -> Result<Self, StoreError> {
        Ok(Self {
            map: Some(map_over(HookedFlash { flash, hooks }, range.clone())?),
            range,
            buf: [0; N],
        })
    }

    /// Erases the whole store (a corrupted one's recovery): nothing is saved afterwards. The map
    /// starts afresh, as at boot: its cache pointed into what was erased.
    pub async fn erase(&mut self) -> Result<(), StoreError> {
        let map = self.map.take().ok_or(StoreError::Corrupted)?;
        let (mut flash, _stale) = map.destroy();
        let r = flash.erase(self.range.start, self.range.end).await;
        self.map = Some(map_over(flash, self.range.clone())?);
        r.map_err(|e| match e {
            HookedError::Corrupted => StoreError::Unreadable,
            HookedError::Flash(_) => StoreError::Flash,
        })
    }

    /// Reads every write unit of the store once and programs each one the board refuses to read
    /// ([`Hooks::read_corrupted`]) to all zeros, then runs [`Hooks::zeroed`] for it; `None` if
    /// none was refused. The map starts afresh afterwards, as at boot (its cache may point at a
    /// zeroed item). Only for a flash that accepts zeros over programmed cells (the G474's ECC
    /// flash: see the crate doc); a read or write the flash itself fails is `Flash`, and the
    /// units zeroed before it stay zeroed (a cut here leaves at worst a unit to zero again).
    pub async fn zero_unreadable(&mut self) -> Result<Option<Zeroed>, StoreError> {
        let unit = F::WRITE_SIZE;
        if unit == 0 || unit > MAX_ZERO_UNIT || !unit.is_multiple_of(F::READ_SIZE) {
            return Err(StoreError::BadRange);
        }
        let map = self.map.take().ok_or(StoreError::Corrupted)?;
        let (mut flash, _stale) = map.destroy();
        let r = zero_unreadable_in(&mut flash, self.range.clone(), unit).await;
        self.map = Some(map_over(flash, self.range.clone())?);
        r
    }

    /// The saved scene; `None` when nothing was ever saved (or the flash is erased).
    pub async fn load(&mut self) -> Result<Option<Saved>, StoreError> {
        let Some(body) = self.fetch(FORMAT).await? else {
            return Ok(None);
        };
        let (scene_id, config) = decode_whole::<(u32, Config)>(body)?;
        Ok(Some(Saved { scene_id, config }))
    }

    /// Stores `saved` as the scene to boot into.
    pub async fn save(&mut self, saved: &Saved) -> Result<(), StoreError> {
        self.save_item(FORMAT, &(saved.scene_id, &saved.config))
            .await
    }

    /// The saved 2D scene; `None` when nothing was ever saved (or the flash is erased).
    #[cfg(feature = "plane")]
    pub async fn load_2d(&mut self) -> Result<Option<Saved2d>, StoreError> {
        let Some(body) = self.fetch(FORMAT_2D).await? else {
            return Ok(None);
        };
        let (scene_id, scene) = decode_whole::<(u32, saw_link::msg::PlaneScene)>(body)?;
        Ok(Some(Saved2d { scene_id, scene }))
    }

    /// Stores the 2D scene `scene` (id `scene_id`) as the scene to boot into; it replaces a 1D
    /// one. By reference: a 2D scene is kilobytes, the firmware's link task does not copy it.
    #[cfg(feature = "plane")]
    pub async fn save_2d(
        &mut self,
        scene_id: u32,
        scene: &saw_link::msg::PlaneScene,
    ) -> Result<(), StoreError> {
        self.save_item(FORMAT_2D, &(scene_id, scene)).await
    }

    /// The stored item's body behind the tag `format`; the tag of the other kind is
    /// `WrongKind`, any other `OtherFormat` (1D) / `OtherFormat2d` (2D).
    async fn fetch(&mut self, format: u8) -> Result<Option<&[u8]>, StoreError> {
        let Some(map) = self.map.as_mut() else {
            return Err(StoreError::Corrupted);
        };
        let item: Option<&[u8]> = map.fetch_item(&mut self.buf, &KEY).await.map_err(from_ss)?;
        let Some(bytes) = item else { return Ok(None) };
        let (&found, body) = bytes.split_first().ok_or(StoreError::Undecodable)?;
        match (found, format) {
            (f, want) if f == want => Ok(Some(body)),
            (FORMAT_2D, FORMAT) => Err(StoreError::WrongKind { saved_2d: true }),
            (FORMAT, FORMAT_2D) => Err(StoreError::WrongKind { saved_2d: false }),
            (found, FORMAT) => Err(StoreError::OtherFormat { found }),
            (found, _) => Err(StoreError::OtherFormat2d { found }),
        }
    }

    /// Writes `format ‖ postcard(value)` as the key's item, then reads it back.
    async fn save_item<T: serde::Serialize>(
        &mut self,
        format: u8,
        value: &T,
    ) -> Result<(), StoreError> {
        let mut item = [0u8; N];
        let (tag, rest) = item.split_first_mut().ok_or(StoreError::TooLarge)?;
        *tag = format;
        let n = postcard::to_slice(value, rest)
            .map_err(|_| StoreError::TooLarge)?
            .len();
        let value: &[u8] = item.get(..1 + n).ok_or(StoreError::TooLarge)?;
        let Some(map) = self.map.as_mut() else {
            return Err(StoreError::Corrupted);
        };
        map.store_item(&mut self.buf, &KEY, &value)
            .await
            .map_err(from_ss)?;
        self.verify(value).await
    }

    /// Reads the scene item back as a boot would (the map started afresh: its cache only knows
    /// where the item was written) and checks it is `value`. sequential-storage writes into
    /// space it takes to be erased; a store region holding stray bytes there (another image's
    /// data, not erased) leaves the item ANDed with them on a flash that programs 1 → 0 without
    /// complaint (the F446, the virtual board's file), its CRC then fails and the load finds an
    /// older item or none. The save said Ok before this check (`tests/power_cut.rs`,
    /// a_save_over_sprinkled_flash_that_says_ok_loads_back).
    async fn verify(&mut self, value: &[u8]) -> Result<(), StoreError> {
        let map = self.map.take().ok_or(StoreError::Corrupted)?;
        let (flash, _cache) = map.destroy();
        let map = self.map.insert(map_over(flash, self.range.clone())?);
        let item: Option<&[u8]> = map.fetch_item(&mut self.buf, &KEY).await.map_err(from_ss)?;
        if item == Some(value) {
            Ok(())
        } else {
            Err(StoreError::NotStored)
        }
    }

    /// The flash back (tests: "reboot" by building a new store over it); None only after an
    /// `erase` that was dropped half way.
    pub fn into_flash(self) -> Option<F> {
        self.map.map(|m| m.destroy().0.flash)
    }
}
