//! Reading the little-endian fields of a binary message, I/O free: the one byte reader of the
//! DAQ's serial frames ([`crate::daq::frame`]) and the DAQ-over-CAN messages ([`crate::can::codec`]).
//! Each protocol names its own errors (the frame type or the message), so the reader asks the
//! protocol's [`FieldErrors`] to make them.

use std::string::FromUtf8Error;

/// How a protocol words the errors of reading a message's fields.
pub trait FieldErrors {
    /// The protocol's error type.
    type Error;
    /// The message ends before `field`: `left` bytes remain, `needed` are needed.
    fn ends_before(&self, field: &str, left: usize, needed: usize) -> Self::Error;
    /// `count` bytes remain after the last field.
    fn trailing(&self, count: usize) -> Self::Error;
    /// The trailing text is not UTF-8.
    fn not_utf8(&self, e: FromUtf8Error) -> Self::Error;
}

/// Reads fields front to back from a message body; every read checks the length first, so a
/// short or malformed message is an error, never a panic.
pub struct LeReader<'a, E> {
    rest: &'a [u8],
    errors: E,
}

impl<'a, E: FieldErrors> LeReader<'a, E> {
    /// A reader over `body` whose errors `errors` words.
    pub fn new(body: &'a [u8], errors: E) -> Self {
        LeReader { rest: body, errors }
    }

    /// The next `n` bytes (`field` names them in the error).
    pub fn take(&mut self, n: usize, field: &str) -> Result<&'a [u8], E::Error> {
        if self.rest.len() < n {
            return Err(self.errors.ends_before(field, self.rest.len(), n));
        }
        let (head, tail) = self.rest.split_at(n);
        self.rest = tail;
        Ok(head)
    }

    /// The next `N` bytes as an array.
    fn array<const N: usize>(&mut self, field: &str) -> Result<[u8; N], E::Error> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N, field)?);
        Ok(a)
    }

    /// A `u8`.
    pub fn u8(&mut self, field: &str) -> Result<u8, E::Error> {
        Ok(self.take(1, field)?[0])
    }

    /// A little-endian `u16`.
    pub fn u16(&mut self, field: &str) -> Result<u16, E::Error> {
        self.array(field).map(u16::from_le_bytes)
    }

    /// A little-endian `i16`.
    pub fn i16(&mut self, field: &str) -> Result<i16, E::Error> {
        self.array(field).map(i16::from_le_bytes)
    }

    /// A little-endian `u32`.
    pub fn u32(&mut self, field: &str) -> Result<u32, E::Error> {
        self.array(field).map(u32::from_le_bytes)
    }

    /// A little-endian IEEE 754 `f32`.
    pub fn f32(&mut self, field: &str) -> Result<f32, E::Error> {
        self.array(field).map(f32::from_le_bytes)
    }

    /// A little-endian IEEE 754 `f64`.
    pub fn f64(&mut self, field: &str) -> Result<f64, E::Error> {
        self.array(field).map(f64::from_le_bytes)
    }

    /// The rest of the body as UTF-8 text.
    pub fn text(&mut self) -> Result<String, E::Error> {
        let b = std::mem::take(&mut self.rest);
        String::from_utf8(b.to_vec()).map_err(|e| self.errors.not_utf8(e))
    }

    /// The rest of the body, unread.
    pub fn take_rest(&mut self) -> &'a [u8] {
        std::mem::take(&mut self.rest)
    }

    /// Checks that every byte was read.
    pub fn end(&self) -> Result<(), E::Error> {
        if self.rest.is_empty() {
            Ok(())
        } else {
            Err(self.errors.trailing(self.rest.len()))
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    /// Errors as plain strings, to see which one a read makes.
    struct Words;

    impl FieldErrors for Words {
        type Error = String;
        fn ends_before(&self, field: &str, left: usize, needed: usize) -> String {
            format!("{field}: {left} < {needed}")
        }
        fn trailing(&self, count: usize) -> String {
            format!("{count} trailing")
        }
        fn not_utf8(&self, _: FromUtf8Error) -> String {
            "not utf-8".into()
        }
    }

    #[test]
    fn reads_little_endian_fields_in_order() {
        let mut body = vec![0x7F];
        body.extend_from_slice(&0xBEEFu16.to_le_bytes());
        body.extend_from_slice(&(-2i16).to_le_bytes());
        body.extend_from_slice(&0xDEAD_BEEFu32.to_le_bytes());
        body.extend_from_slice(&1.5f32.to_le_bytes());
        body.extend_from_slice(&(-0.25f64).to_le_bytes());
        body.extend_from_slice("ok".as_bytes());
        let mut r = LeReader::new(&body, Words);
        assert_eq!(r.u8("a").unwrap(), 0x7F);
        assert_eq!(r.u16("b").unwrap(), 0xBEEF);
        assert_eq!(r.i16("c").unwrap(), -2);
        assert_eq!(r.u32("d").unwrap(), 0xDEAD_BEEF);
        assert_eq!(r.f32("e").unwrap(), 1.5);
        assert_eq!(r.f64("f").unwrap(), -0.25);
        assert_eq!(r.text().unwrap(), "ok");
        assert_eq!(r.end(), Ok(()));
    }

    #[test]
    fn short_trailing_and_bad_text_are_errors() {
        let mut r = LeReader::new(&[1, 2, 3], Words);
        assert_eq!(r.u32("seq"), Err("seq: 3 < 4".to_string()));
        assert_eq!(r.u16("code").unwrap(), 0x0201);
        assert_eq!(r.end(), Err("1 trailing".to_string()));
        assert_eq!(r.text(), Ok("\u{3}".to_string()));
        assert_eq!(
            LeReader::new(&[0xFF], Words).text(),
            Err("not utf-8".into())
        );
        assert_eq!(LeReader::new(&[9, 9], Words).take_rest(), &[9, 9]);
    }
}
