//! Cuts a byte stream into frames at the delimiter, in a fixed buffer: bytes that do not end
//! within [`MAX_FRAME`] are dropped up to the next delimiter and reported once, so a flood
//! of garbage costs neither memory nor a resynchronisation longer than one frame.

use crate::frame::{DELIMITER, MAX_FRAME};

/// What one byte completed.
#[derive(Debug, PartialEq, Eq)]
pub enum Push<'a> {
    /// Nothing yet.
    More,
    /// A frame's bytes (delimiter excluded), to decode in place before the next push.
    Frame(&'a mut [u8]),
    /// Bytes longer than a frame, dropped up to this delimiter: one corrupt frame.
    Overlong,
}

/// The frame being received.
#[derive(Debug)]
pub struct Deframer {
    buf: [u8; MAX_FRAME],
    len: usize,
    overflowed: bool,
}

impl Default for Deframer {
    fn default() -> Self {
        Self::new()
    }
}

impl Deframer {
    /// An empty deframer.
    pub const fn new() -> Self {
        Self {
            buf: [0; MAX_FRAME],
            len: 0,
            overflowed: false,
        }
    }

    /// Takes one byte. An empty frame (two delimiters in a row) is skipped silently: a
    /// sender may start with a delimiter to end whatever a receiver had half received.
    pub fn push(&mut self, byte: u8) -> Push<'_> {
        if byte == DELIMITER {
            let (len, overflowed) = (self.len, self.overflowed);
            self.len = 0;
            self.overflowed = false;
            return if overflowed {
                Push::Overlong
            } else if len == 0 {
                Push::More
            } else {
                Push::Frame(&mut self.buf[..len])
            };
        }
        if self.len < MAX_FRAME {
            self.buf[self.len] = byte;
            self.len += 1;
        } else {
            self.overflowed = true;
        }
        Push::More
    }

    /// Bytes of a frame received so far (a truncated frame's, when its sender stopped).
    pub fn pending(&self) -> usize {
        self.len
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_split_at_delimiters_and_overlong_ones_are_reported_once() {
        let mut d = Deframer::new();
        let mut frames = 0;
        let mut overlong = 0;
        let stream = core::iter::repeat_n(7u8, 3 * MAX_FRAME).chain([0, 0, 1, 2, 3, 0]);
        for b in stream {
            match d.push(b) {
                Push::More => {}
                Push::Frame(f) => {
                    assert_eq!(f, &[1, 2, 3]);
                    frames += 1;
                }
                Push::Overlong => overlong += 1,
            }
        }
        assert_eq!((frames, overlong, d.pending()), (1, 1, 0));
    }
}
