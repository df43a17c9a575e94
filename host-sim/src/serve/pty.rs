//! A pseudo-terminal standing for the ST-LINK's virtual COM port: the virtual board holds the
//! master side; `saw` opens the slave through a symlink at the path the user chose, exactly as
//! it opens `/dev/ttyACM0`.
//!
//! The link must not outlive its board: the kernel hands a freed `/dev/pts/N` to the next
//! program that opens a pty, so a link left behind would answer as some other board. So the
//! link is removed on every way out — [`Drop`], and SIGINT, SIGTERM and SIGHUP through
//! [`on_signals`]'s handler — and a board holds an exclusive lock on `PATH.lock` beside its
//! link while it runs: a second `serve` on the same path is refused (naming the first one's
//! pid) instead of taking the link over, and a link whose lock nobody holds is stale and is
//! replaced.

use std::ffi::CString;
use std::io::{self, Read, Seek, Write};
use std::os::fd::{AsFd, OwnedFd};
use std::os::unix::ffi::OsStrExt;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicPtr, Ordering};
use std::sync::Once;

use nix::errno::Errno;
use nix::fcntl::{fcntl, FcntlArg, Flock, FlockArg, OFlag};
use nix::pty::openpty;
use nix::sys::signal::{self, SigHandler, Signal};
use nix::sys::termios::{cfmakeraw, tcgetattr, tcsetattr, SetArg};
use nix::unistd::ttyname;

/// The master side and the symlink to the slave.
pub struct Pty {
    master: OwnedFd,
    /// Held open so the pty lives between clients (a closed slave makes the master read EIO)
    /// and stays raw: no echo, no line editing, no CR/LF translation of frame bytes.
    _slave: OwnedFd,
    link: PathBuf,
    slave_path: PathBuf,
    /// `PATH.lock`, locked while this board runs (unlocked when dropped, after the files go).
    _lock: Flock<std::fs::File>,
    lock_path: PathBuf,
    /// This board's entries in the signal handler's list of files to remove.
    slots: [usize; 2],
}

/// The lock file that goes with a link: `PATH.lock`.
pub fn lock_path(link: &Path) -> PathBuf {
    let mut s = link.as_os_str().to_owned();
    s.push(".lock");
    PathBuf::from(s)
}

/// Takes the lock beside `link` for this process, or says which serve holds it.
fn take_lock(link: &Path) -> Result<(Flock<std::fs::File>, PathBuf), String> {
    let path = lock_path(link);
    // A board stopping now removes its lock file before it unlocks it: a lock taken on the
    // removed file would guard nothing, so it is taken again on the file now at the path.
    for _ in 0..8 {
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(|e| {
                format!(
                    "--pty {}: cannot open {}: {e}",
                    link.display(),
                    path.display()
                )
            })?;
        let mut lock = match Flock::lock(file, FlockArg::LockExclusiveNonblock) {
            Ok(l) => l,
            Err((mut file, Errno::EWOULDBLOCK)) => {
                let mut pid = String::new();
                let _ = file.read_to_string(&mut pid);
                let pid = pid.trim();
                return Err(format!(
                    "--pty {}: another host-sim serve{} runs a board on this link; stop it or \
                     choose another path",
                    link.display(),
                    if pid.is_empty() {
                        String::new()
                    } else {
                        format!(" (pid {pid})")
                    }
                ));
            }
            Err((_, e)) => {
                return Err(format!(
                    "--pty {}: cannot lock {}: {e}",
                    link.display(),
                    path.display()
                ))
            }
        };
        let same = match (lock.metadata(), std::fs::metadata(&path)) {
            (Ok(a), Ok(b)) => a.ino() == b.ino() && a.dev() == b.dev(),
            _ => false,
        };
        if !same {
            continue;
        }
        // The pid, for the refusal a second board gets.
        lock.set_len(0)
            .and_then(|_| lock.rewind())
            .and_then(|_| writeln!(lock, "{}", std::process::id()))
            .map_err(|e| {
                format!(
                    "--pty {}: cannot write {}: {e}",
                    link.display(),
                    path.display()
                )
            })?;
        return Ok((lock, path));
    }
    Err(format!(
        "--pty {}: {} keeps being removed; is another serve starting and stopping on it?",
        link.display(),
        path.display()
    ))
}

impl Pty {
    /// Opens a pty and links `link` to its slave. A file (not a symlink) at `link` is refused,
    /// and so is a link another running `serve` holds; a symlink no running board holds (left
    /// by a killed one) is replaced.
    pub fn open(link: &Path) -> Result<Self, String> {
        if let Ok(meta) = std::fs::symlink_metadata(link) {
            if !meta.file_type().is_symlink() {
                return Err(format!(
                    "--pty {}: a file is there and is not a symlink; choose another path",
                    link.display()
                ));
            }
        }
        let (lock, lock_path) = take_lock(link)?;
        if std::fs::symlink_metadata(link).is_ok() {
            std::fs::remove_file(link).map_err(|e| {
                format!("--pty {}: cannot replace the old link: {e}", link.display())
            })?;
        }
        let pty = openpty(None, None).map_err(|e| format!("cannot open a pseudo-terminal: {e}"))?;
        let mut t = tcgetattr(pty.slave.as_fd()).map_err(|e| format!("pty attributes: {e}"))?;
        cfmakeraw(&mut t);
        tcsetattr(pty.slave.as_fd(), SetArg::TCSANOW, &t)
            .map_err(|e| format!("pty attributes: {e}"))?;
        let flags =
            fcntl(pty.master.as_fd(), FcntlArg::F_GETFL).map_err(|e| format!("pty flags: {e}"))?;
        fcntl(
            pty.master.as_fd(),
            FcntlArg::F_SETFL(OFlag::from_bits_truncate(flags) | OFlag::O_NONBLOCK),
        )
        .map_err(|e| format!("pty flags: {e}"))?;
        let slave_path = ttyname(pty.slave.as_fd()).map_err(|e| format!("pty name: {e}"))?;
        install_handler();
        let slots = [remember(link), remember(&lock_path)];
        let me = Self {
            master: pty.master,
            _slave: pty.slave,
            link: link.to_path_buf(),
            slave_path,
            _lock: lock,
            lock_path,
            slots,
        };
        std::os::unix::fs::symlink(&me.slave_path, link)
            .map_err(|e| format!("--pty {}: cannot create the link: {e}", link.display()))?;
        Ok(me)
    }

    /// The slave's own path (`/dev/pts/N`).
    pub fn slave_path(&self) -> &Path {
        &self.slave_path
    }

    /// The link `saw --port` opens.
    pub fn link(&self) -> &Path {
        &self.link
    }

    /// Reads what the host sent; `Ok(0)` when nothing is waiting.
    pub fn read(&self, buf: &mut [u8]) -> io::Result<usize> {
        match nix::unistd::read(&self.master, buf) {
            Ok(n) => Ok(n),
            Err(Errno::EAGAIN) => Ok(0),
            Err(e) => Err(io::Error::from(e)),
        }
    }

    /// Writes to the host; `Ok(0)` when the pty's buffer is full (no one reading).
    pub fn write(&self, bytes: &[u8]) -> io::Result<usize> {
        match nix::unistd::write(&self.master, bytes) {
            Ok(n) => Ok(n),
            Err(Errno::EAGAIN) => Ok(0),
            Err(e) => Err(io::Error::from(e)),
        }
    }
}

impl Drop for Pty {
    fn drop(&mut self) {
        for &slot in &self.slots {
            forget(slot);
        }
        // Remove the link only if it is still ours (the lock keeps other boards off it, but a
        // user may have pointed it elsewhere by hand).
        if std::fs::read_link(&self.link).is_ok_and(|p| p == self.slave_path) {
            let _ = std::fs::remove_file(&self.link);
        }
        // The lock file goes while still locked; `self._lock` unlocks when dropped after this.
        let _ = std::fs::remove_file(&self.lock_path);
    }
}

/// Files the signal handler removes: the links and lock files of the boards open in this
/// process (null: a free slot). The paths are leaked C strings: the handler may read one on
/// another thread while a board drops, so they are never freed (a few bytes per board).
static CLEANUP: [AtomicPtr<std::ffi::c_char>; 16] =
    [const { AtomicPtr::new(std::ptr::null_mut()) }; 16];

/// The flag a signal sets to stop the serve loop, when [`on_signals`] was given one.
static STOP: AtomicPtr<AtomicBool> = AtomicPtr::new(std::ptr::null_mut());

/// Puts `path` in the handler's list; returns its slot (`usize::MAX`: the list is full, and
/// only [`Drop`] removes it).
fn remember(path: &Path) -> usize {
    let Ok(c) = CString::new(path.as_os_str().as_bytes()) else {
        return usize::MAX;
    };
    let raw = c.into_raw();
    for (i, slot) in CLEANUP.iter().enumerate() {
        if slot
            .compare_exchange(
                std::ptr::null_mut(),
                raw,
                Ordering::SeqCst,
                Ordering::SeqCst,
            )
            .is_ok()
        {
            return i;
        }
    }
    usize::MAX
}

/// Takes slot `i` off the handler's list (the string stays leaked, see [`CLEANUP`]).
fn forget(i: usize) {
    if let Some(slot) = CLEANUP.get(i) {
        slot.store(std::ptr::null_mut(), Ordering::SeqCst);
    }
}

/// SIGINT, SIGTERM, SIGHUP: the links and lock files in [`CLEANUP`] are removed (unlink is
/// async-signal-safe); then the serve loop's flag is set if [`on_signals`] gave one (the board
/// stops as at `--seconds`), else the signal's default action is taken again (the process
/// ends as it did before the handler, killed by the signal).
extern "C" fn on_signal(sig: std::ffi::c_int) {
    for slot in &CLEANUP {
        let p = slot.load(Ordering::SeqCst);
        if !p.is_null() {
            // SAFETY: a slot holds a leaked, never freed, NUL-terminated string or null.
            let path = unsafe { std::ffi::CStr::from_ptr(p) };
            let _ = nix::unistd::unlink(path);
        }
    }
    let stop = STOP.load(Ordering::SeqCst);
    if !stop.is_null() {
        // SAFETY: `on_signals` takes a `&'static AtomicBool`.
        unsafe { (*stop).store(true, Ordering::SeqCst) };
        return;
    }
    if let Ok(s) = Signal::try_from(sig) {
        // SAFETY: restoring the default action; no handler of ours is replaced by it.
        let _ = unsafe { signal::signal(s, SigHandler::SigDfl) };
        let _ = signal::raise(s);
    }
}

/// The signals that end a `serve` from outside: ^C, `kill`, the terminal closing.
const STOPPING: [Signal; 3] = [Signal::SIGINT, Signal::SIGTERM, Signal::SIGHUP];

fn install_handler() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        for s in STOPPING {
            // SAFETY: the handler only unlinks, stores atomics and re-raises.
            let _ = unsafe { signal::signal(s, SigHandler::Handler(on_signal)) };
        }
    });
}

/// From now on SIGINT, SIGTERM and SIGHUP set `stop` (after removing the links) instead of
/// ending the process: the serve loop returns and every board is dropped as at `--seconds`.
pub fn on_signals(stop: &'static AtomicBool) {
    STOP.store(
        stop as *const AtomicBool as *mut AtomicBool,
        Ordering::SeqCst,
    );
    install_handler();
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("host-sim-pty-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// A second board on a link a running board holds is refused with one line naming the
    /// path and this process's pid; the first keeps its link; once it drops, the link and the
    /// lock file are gone and the path is free again.
    #[test]
    fn a_live_link_is_refused_and_a_dropped_one_removed() {
        let d = scratch("live");
        let link = d.join("board");
        let first = Pty::open(&link).unwrap();
        let e = Pty::open(&link).err().unwrap();
        assert_eq!(
            e,
            format!(
                "--pty {}: another host-sim serve (pid {}) runs a board on this link; stop it or \
                 choose another path",
                link.display(),
                std::process::id()
            )
        );
        assert_eq!(std::fs::read_link(&link).unwrap(), first.slave_path());
        drop(first);
        assert!(
            std::fs::symlink_metadata(&link).is_err(),
            "the link outlived its board"
        );
        assert!(
            !lock_path(&link).exists(),
            "the lock file outlived its board"
        );
        let again = Pty::open(&link).unwrap();
        assert_eq!(std::fs::read_link(&link).unwrap(), again.slave_path());
    }

    /// A link left by a killed board (no lock held, pointing at a pts another program now
    /// has) is replaced by the new board's; a plain file at the path is refused.
    #[test]
    fn a_stale_link_is_replaced() {
        let d = scratch("stale");
        let other = Pty::open(&d.join("other")).unwrap();
        let link = d.join("board");
        std::os::unix::fs::symlink(other.slave_path(), &link).unwrap();
        std::fs::write(lock_path(&link), "12345\n").unwrap();
        let p = Pty::open(&link).unwrap();
        assert_eq!(std::fs::read_link(&link).unwrap(), p.slave_path());
        assert_ne!(p.slave_path(), other.slave_path());
        let file = d.join("file");
        std::fs::write(&file, "x").unwrap();
        assert!(Pty::open(&file)
            .err()
            .unwrap()
            .contains("a file is there and is not a symlink"));
    }
}
