//! One serial link to a sensor node: a byte stream (a unix socket, QEMU's `-chardev socket`,
//! or `socat` in front of a real board's tty; a TCP chardev) cut into frames.
//!
//! Reads wait at most until a deadline; bytes past a complete frame stay for the next
//! receive; a frame longer than [`MAX_FRAME`] is dropped and reported as corrupt. Nothing the
//! node sends can make the gateway allocate without bound or wait for ever.

use std::io::{ErrorKind, Read, Write};
use std::net::TcpStream;
use std::os::unix::net::UnixStream;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use estpipe_sensor_node::{Deframer, Push, MAX_FRAME};

/// Where a node's serial line is.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Endpoint {
    /// `unix:PATH`: a unix stream socket (QEMU's `-chardev socket,path=…,server=on`).
    Unix(PathBuf),
    /// `tcp:HOST:PORT`: a TCP stream (QEMU's `-chardev socket,host=…,port=…,server=on`).
    Tcp(String),
}

impl Endpoint {
    /// Parses `unix:PATH` or `tcp:HOST:PORT`.
    pub fn parse(s: &str) -> Result<Self, String> {
        if let Some(p) = s.strip_prefix("unix:") {
            if p.is_empty() {
                return Err(format!("{s:?}: empty socket path"));
            }
            Ok(Self::Unix(PathBuf::from(p)))
        } else if let Some(a) = s.strip_prefix("tcp:") {
            if !a.contains(':') {
                return Err(format!("{s:?}: expected tcp:HOST:PORT"));
            }
            Ok(Self::Tcp(a.to_string()))
        } else {
            Err(format!(
                "{s:?}: expected unix:PATH or tcp:HOST:PORT (a tty: put `socat \
                 UNIX-LISTEN:PATH /dev/ttyX,raw,b115200` in front, docs/sensor-node.md)"
            ))
        }
    }
}

impl std::fmt::Display for Endpoint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Unix(p) => write!(f, "unix:{}", p.display()),
            Self::Tcp(a) => write!(f, "tcp:{a}"),
        }
    }
}

enum Stream {
    Unix(UnixStream),
    Tcp(TcpStream),
}

impl Stream {
    fn set_read_timeout(&self, d: Duration) -> std::io::Result<()> {
        match self {
            Self::Unix(s) => s.set_read_timeout(Some(d)),
            Self::Tcp(s) => s.set_read_timeout(Some(d)),
        }
    }
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        match self {
            Self::Unix(s) => s.read(buf),
            Self::Tcp(s) => s.read(buf),
        }
    }
    fn write_all(&mut self, buf: &[u8]) -> std::io::Result<()> {
        match self {
            Self::Unix(s) => s.write_all(buf),
            Self::Tcp(s) => s.write_all(buf),
        }
    }
}

/// What one receive gave.
#[derive(Debug, PartialEq, Eq)]
pub enum Received {
    /// A frame's bytes (delimiter excluded), in the link's buffer.
    Frame(Vec<u8>),
    /// Bytes longer than a frame, dropped up to a delimiter.
    Overlong,
    /// The deadline passed.
    Timeout,
}

/// A connected link.
pub struct Link {
    endpoint: Endpoint,
    stream: Stream,
    deframer: Deframer,
    /// Bytes read but not yet pushed through the deframer.
    pending: Vec<u8>,
    at: usize,
}

impl std::fmt::Debug for Link {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Link")
            .field("endpoint", &self.endpoint)
            .finish_non_exhaustive()
    }
}

impl Link {
    /// Connects, trying again until `give_up` while nobody listens yet (QEMU creates its
    /// socket a moment after it starts), unless `stop` says to give up first.
    pub fn connect(
        endpoint: &Endpoint,
        give_up: Instant,
        stop: &dyn Fn() -> bool,
    ) -> Result<Self, String> {
        loop {
            let r = match endpoint {
                Endpoint::Unix(p) => UnixStream::connect(p).map(Stream::Unix),
                Endpoint::Tcp(a) => TcpStream::connect(a.as_str()).map(|s| {
                    let _ = s.set_nodelay(true);
                    Stream::Tcp(s)
                }),
            };
            match r {
                Ok(stream) => {
                    // A node that stops reading must not hold the gateway for ever.
                    let t = Some(Duration::from_secs(10));
                    let _ = match &stream {
                        Stream::Unix(s) => s.set_write_timeout(t),
                        Stream::Tcp(s) => s.set_write_timeout(t),
                    };
                    return Ok(Self {
                        endpoint: endpoint.clone(),
                        stream,
                        deframer: Deframer::new(),
                        pending: Vec::with_capacity(512),
                        at: 0,
                    });
                }
                Err(e)
                    if matches!(e.kind(), ErrorKind::NotFound | ErrorKind::ConnectionRefused)
                        && Instant::now() < give_up =>
                {
                    if stop() {
                        return Err(format!("{endpoint}: stopped while waiting for the node"));
                    }
                    std::thread::sleep(Duration::from_millis(20));
                }
                Err(e) => return Err(format!("{endpoint}: cannot connect: {e}")),
            }
        }
    }

    /// The endpoint.
    pub fn endpoint(&self) -> &Endpoint {
        &self.endpoint
    }

    /// Sends one encoded frame (delimiter included).
    pub fn send(&mut self, frame: &[u8]) -> Result<(), String> {
        self.stream
            .write_all(frame)
            .map_err(|e| format!("{}: write: {e}", self.endpoint))
    }

    /// The next frame, waiting at most until `deadline`. An error when the line is closed.
    pub fn receive(&mut self, deadline: Instant) -> Result<Received, String> {
        loop {
            while self.at < self.pending.len() {
                let b = self.pending[self.at];
                self.at += 1;
                match self.deframer.push(b) {
                    Push::More => {}
                    Push::Frame(f) => return Ok(Received::Frame(f.to_vec())),
                    Push::Overlong => return Ok(Received::Overlong),
                }
            }
            self.pending.clear();
            self.at = 0;
            let now = Instant::now();
            if now >= deadline {
                return Ok(Received::Timeout);
            }
            self.stream
                .set_read_timeout((deadline - now).max(Duration::from_millis(1)))
                .map_err(|e| format!("{}: {e}", self.endpoint))?;
            self.pending.resize(4 * MAX_FRAME, 0);
            match self.stream.read(&mut self.pending) {
                Ok(0) => {
                    self.pending.clear();
                    return Err(format!("{}: the node closed the line", self.endpoint));
                }
                Ok(n) => self.pending.truncate(n),
                Err(e)
                    if matches!(
                        e.kind(),
                        ErrorKind::WouldBlock | ErrorKind::TimedOut | ErrorKind::Interrupted
                    ) =>
                {
                    self.pending.clear();
                }
                Err(e) => {
                    self.pending.clear();
                    return Err(format!("{}: read: {e}", self.endpoint));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn endpoints_parse_or_say_why() {
        assert_eq!(
            Endpoint::parse("unix:/tmp/n0.sock"),
            Ok(Endpoint::Unix("/tmp/n0.sock".into()))
        );
        assert_eq!(
            Endpoint::parse("tcp:127.0.0.1:4444"),
            Ok(Endpoint::Tcp("127.0.0.1:4444".into()))
        );
        for bad in ["/dev/ttyUSB0", "unix:", "tcp:4444", ""] {
            assert!(Endpoint::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn frames_split_across_reads_and_garbage_between_them() {
        let (a, mut b) = UnixStream::pair().unwrap();
        let mut link = Link {
            endpoint: Endpoint::Unix("pair".into()),
            stream: Stream::Unix(a),
            deframer: Deframer::new(),
            pending: Vec::new(),
            at: 0,
        };
        let mut bytes = vec![1, 2, 0, 3];
        bytes.extend(std::iter::repeat_n(9u8, 3 * MAX_FRAME));
        bytes.extend([0, 4, 5, 0]);
        b.write_all(&bytes).unwrap();
        let soon = || Instant::now() + Duration::from_secs(2);
        assert_eq!(link.receive(soon()), Ok(Received::Frame(vec![1, 2])));
        assert_eq!(link.receive(soon()), Ok(Received::Overlong));
        assert_eq!(link.receive(soon()), Ok(Received::Frame(vec![4, 5])));
        let t = Instant::now();
        assert_eq!(
            link.receive(Instant::now() + Duration::from_millis(50)),
            Ok(Received::Timeout)
        );
        assert!(t.elapsed() < Duration::from_secs(2));
        drop(b);
        assert!(link.receive(soon()).unwrap_err().contains("closed"));
    }
}
