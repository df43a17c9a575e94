//! Opening the serial port: raw 8N1 at the link's rate, short reads so the client keeps its own
//! deadlines, and an exclusive lock (serialport takes a `flock` on open) so a second `saw` (or
//! the web panel) on the same port is told the port is busy instead of interleaving frames with
//! the first.

use std::io::{self, Read, Write};
use std::path::Path;
use std::time::Duration;

use serialport::{SerialPort, TTYPort};

/// The link's rate (the firmware's UART; a pty ignores it): boards/README.md.
pub const BAUD: u32 = 921_600;

/// An open, locked port.
pub struct Port {
    tty: TTYPort,
}

/// Opens `path` for the link; one line naming the port and the reason when it cannot.
pub fn open(path: &Path) -> Result<Port, String> {
    let name = path.display();
    if let Err(e) = std::fs::metadata(path) {
        return Err(match e.kind() {
            io::ErrorKind::NotFound => format!(
                "port {name} does not exist: is the board plugged in (or `host-sim serve --pty {name}` / `board-model serve … --pty {name}` running; board-model's link appears once the image has booted)?"
            ),
            _ => format!("port {name}: {e}"),
        });
    }
    let tty = serialport::new(path.to_string_lossy(), BAUD)
        .timeout(Duration::from_millis(2))
        .open_native()
        .map_err(|e| {
            let text = e.to_string();
            if text.contains("lock") {
                format!("port {name} is busy: another `saw` or the web panel has it open")
            } else if matches!(
                e.kind(),
                serialport::ErrorKind::Io(io::ErrorKind::PermissionDenied)
            ) {
                format!("port {name}: permission denied (add yourself to the `dialout` group)")
            } else {
                format!("port {name}: {text}")
            }
        })?;
    let _ = tty.clear(serialport::ClearBuffer::Input);
    Ok(Port { tty })
}

impl Read for Port {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        self.tty.read(buf)
    }
}

impl Write for Port {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.tty.write(buf)
    }
    fn flush(&mut self) -> io::Result<()> {
        self.tty.flush()
    }
}
