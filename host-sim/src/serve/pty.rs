//! A pseudo-terminal standing for the ST-LINK's virtual COM port: the virtual board holds the
//! master side; `saw` opens the slave through a symlink at the path the user chose, exactly as
//! it opens `/dev/ttyACM0`.

use std::io;
use std::os::fd::{AsFd, OwnedFd};
use std::path::{Path, PathBuf};

use nix::errno::Errno;
use nix::fcntl::{fcntl, FcntlArg, OFlag};
use nix::pty::openpty;
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
}

impl Pty {
    /// Opens a pty and links `link` to its slave. A file (not a symlink) at `link` is refused.
    pub fn open(link: &Path) -> Result<Self, String> {
        if let Ok(meta) = std::fs::symlink_metadata(link) {
            if !meta.file_type().is_symlink() {
                return Err(format!(
                    "--pty {}: a file is there and is not a symlink; choose another path",
                    link.display()
                ));
            }
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
        std::os::unix::fs::symlink(&slave_path, link)
            .map_err(|e| format!("--pty {}: cannot create the link: {e}", link.display()))?;
        Ok(Self {
            master: pty.master,
            _slave: pty.slave,
            link: link.to_path_buf(),
            slave_path,
        })
    }

    /// The slave's own path (`/dev/pts/N`).
    pub fn slave_path(&self) -> &Path {
        &self.slave_path
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
        // Remove the link only if it is still ours (another virtual board may have taken it).
        if std::fs::read_link(&self.link).is_ok_and(|p| p == self.slave_path) {
            let _ = std::fs::remove_file(&self.link);
        }
    }
}
