//! Byte transports under the driver: a serial port (a real tty, or the simulator's pty — the
//! same code path) and an in-memory pair for unit tests.

use std::io;
use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender, channel};
use std::time::Duration;

/// How long one read waits for bytes: how often a silent link's driver thread wakes to send
/// the keep-alive and check its timeouts. (Commands do not wait for it: the device process
/// writes a changed command itself, through [`Transport::writer`].)
pub const READ_TIMEOUT: Duration = Duration::from_millis(50);

/// A bidirectional byte stream.
pub trait Transport: Send {
    /// Reads what is there, waiting at most [`READ_TIMEOUT`]; `Ok(0)` when nothing came.
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize>;
    /// Writes all bytes.
    fn write_all(&mut self, bytes: &[u8]) -> io::Result<()>;
    /// A second handle that writes to the same stream, for another thread.
    fn writer(&self) -> io::Result<Box<dyn Writer>>;
}

/// The writing half of a [`Transport`].
pub trait Writer: Send {
    /// Writes all bytes.
    fn write_all(&mut self, bytes: &[u8]) -> io::Result<()>;
}

impl Writer for serialport::TTYPort {
    fn write_all(&mut self, bytes: &[u8]) -> io::Result<()> {
        io::Write::write_all(self, bytes)?;
        io::Write::flush(self)
    }
}

impl Writer for Sender<Vec<u8>> {
    fn write_all(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.send(bytes.to_vec())
            .map_err(|_| io::Error::new(io::ErrorKind::BrokenPipe, "peer gone"))
    }
}

/// A serial port, opened exclusively.
pub struct Serial {
    port: serialport::TTYPort,
}

impl Serial {
    /// Opens `path` at `baud` (8N1, no flow control), exclusively.
    pub fn open(path: &str, baud: u32) -> io::Result<Serial> {
        let mut port = serialport::new(path, baud)
            .timeout(READ_TIMEOUT)
            .open_native()
            .map_err(io::Error::from)?;
        port.set_exclusive(true).map_err(io::Error::from)?;
        Ok(Serial { port })
    }
}

impl Transport for Serial {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        match io::Read::read(&mut self.port, buf) {
            Ok(0) => Err(io::Error::new(io::ErrorKind::UnexpectedEof, "port closed")),
            Ok(n) => Ok(n),
            Err(e)
                if e.kind() == io::ErrorKind::TimedOut || e.kind() == io::ErrorKind::WouldBlock =>
            {
                Ok(0)
            }
            Err(e) => Err(e),
        }
    }
    fn write_all(&mut self, bytes: &[u8]) -> io::Result<()> {
        Writer::write_all(&mut self.port, bytes)
    }
    fn writer(&self) -> io::Result<Box<dyn Writer>> {
        Ok(Box::new(
            self.port.try_clone_native().map_err(io::Error::from)?,
        ))
    }
}

/// One end of an in-memory byte pipe pair.
pub struct Memory {
    rx: Receiver<Vec<u8>>,
    tx: Sender<Vec<u8>>,
    pending: Vec<u8>,
}

/// Two connected in-memory ends.
pub fn memory_pair() -> (Memory, Memory) {
    let (a_tx, b_rx) = channel();
    let (b_tx, a_rx) = channel();
    (
        Memory {
            rx: a_rx,
            tx: a_tx,
            pending: Vec::new(),
        },
        Memory {
            rx: b_rx,
            tx: b_tx,
            pending: Vec::new(),
        },
    )
}

impl Transport for Memory {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        if self.pending.is_empty() {
            match self.rx.recv_timeout(READ_TIMEOUT) {
                Ok(b) => self.pending = b,
                Err(RecvTimeoutError::Timeout) => return Ok(0),
                Err(RecvTimeoutError::Disconnected) => {
                    return Err(io::Error::new(io::ErrorKind::BrokenPipe, "peer gone"));
                }
            }
        }
        let n = buf.len().min(self.pending.len());
        buf[..n].copy_from_slice(&self.pending[..n]);
        self.pending.drain(..n);
        Ok(n)
    }
    fn write_all(&mut self, bytes: &[u8]) -> io::Result<()> {
        Writer::write_all(&mut self.tx, bytes)
    }
    fn writer(&self) -> io::Result<Box<dyn Writer>> {
        Ok(Box::new(self.tx.clone()))
    }
}
