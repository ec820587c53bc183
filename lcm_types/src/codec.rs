//! Runtime of the generated codec: the [`Message`] trait, the bounds-checked [`Reader`], and
//! the error types. Written by hand; everything type-specific is generated.
//!
//! Wire format (identical to lcm-gen's): an 8-byte big-endian fingerprint (top-level messages
//! only), then the members in declaration order, big-endian, without padding; booleans and
//! bytes as one byte; strings as a big-endian i32 length that counts the trailing NUL, the
//! UTF-8 bytes and the NUL; arrays row-major, nested structs without fingerprint.
//!
//! Decoding never panics and never allocates more than the input can hold: every array length
//! is checked against the remaining bytes (times the smallest possible element encoding)
//! before its storage is reserved.

/// How many array rows beyond the remaining byte count a decoder accepts (see
/// [`Reader::check_array`]).
pub const EMPTY_ROW_ALLOWANCE: usize = 4096;

/// Bounds applied while decoding on top of the always-on "no more elements than bytes" rule.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DecodeLimits {
    /// Largest value accepted for any variable array dimension.
    pub max_array_len: usize,
    /// Deepest nesting of structs (guards recursive types against stack exhaustion).
    pub max_depth: usize,
}

impl Default for DecodeLimits {
    fn default() -> Self {
        DecodeLimits {
            max_array_len: usize::MAX,
            max_depth: 64,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    #[error(
        "fingerprint mismatch for {type_name}: expected {expected:#018x}, found {found:#018x}"
    )]
    FingerprintMismatch {
        type_name: &'static str,
        expected: u64,
        found: u64,
    },
    #[error("no type of this schema has fingerprint {found:#018x}")]
    UnknownFingerprint { found: u64 },
    #[error("message truncated: needed {needed} more bytes at offset {offset}, {available} left")]
    Truncated {
        offset: usize,
        needed: usize,
        available: usize,
    },
    #[error("{type_name}.{field}: negative array length {value}")]
    NegativeLength {
        type_name: &'static str,
        field: &'static str,
        value: i64,
    },
    #[error("{type_name}.{field}: array length {value} exceeds the limit {limit}")]
    ArrayTooLong {
        type_name: &'static str,
        field: &'static str,
        value: usize,
        limit: usize,
    },
    #[error("{type_name}.{field}: {elements} elements cannot fit in the {available} bytes left")]
    ArrayExceedsBuffer {
        type_name: &'static str,
        field: &'static str,
        elements: u128,
        available: usize,
    },
    #[error("string at offset {offset}: invalid length {length}")]
    BadStringLength { offset: usize, length: i64 },
    #[error("string at offset {offset} is not NUL-terminated")]
    StringNotTerminated { offset: usize },
    #[error("string at offset {offset} is not valid UTF-8")]
    StringNotUtf8 { offset: usize },
    #[error("{type_name}: nesting deeper than {limit}")]
    TooDeep {
        type_name: &'static str,
        limit: usize,
    },
    #[error("{extra} bytes left over after the message")]
    TrailingBytes { extra: usize },
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum EncodeError {
    #[error(
        "{type_name}.{field}: array has {actual} elements but its length member says {declared}"
    )]
    LengthMismatch {
        type_name: &'static str,
        field: &'static str,
        declared: usize,
        actual: usize,
    },
    #[error("{type_name}.{field}: negative array length {value}")]
    NegativeLength {
        type_name: &'static str,
        field: &'static str,
        value: i64,
    },
    #[error("string of {len} bytes is too long for LCM (max 2^31 - 2)")]
    StringTooLong { len: usize },
}

/// A generated LCM type.
pub trait Message: Sized {
    /// `package.type` as in the .lcm file.
    const TYPE_NAME: &'static str;
    /// The fingerprint sent in front of a top-level encoding (lcm-gen's recursive hash).
    const FINGERPRINT: u64;
    /// lcm-gen's per-type hash, before nested types are mixed in.
    const BASE_HASH: u64;
    /// Fewest bytes `encode_one` can produce (variable arrays empty, strings empty).
    const MIN_ENCODED_LEN: usize;

    /// Length of `encode_one`'s output.
    fn encoded_len_one(&self) -> usize;
    /// Appends the encoding without fingerprint (as nested inside another message).
    fn encode_one(&self, out: &mut Vec<u8>) -> Result<(), EncodeError>;
    /// Reads one value without fingerprint.
    fn decode_one(reader: &mut Reader<'_>) -> Result<Self, DecodeError>;

    /// Fingerprint followed by the encoding: the payload to publish.
    fn encode(&self) -> Result<Vec<u8>, EncodeError> {
        let mut out = Vec::new();
        self.encode_into(&mut out)?;
        Ok(out)
    }

    /// [`Message::encode`] into `out`, replacing its contents and reusing its allocation: a
    /// sender on a fixed period allocates nothing once the buffer has grown.
    fn encode_into(&self, out: &mut Vec<u8>) -> Result<(), EncodeError> {
        out.clear();
        out.reserve(8 + self.encoded_len_one());
        out.extend_from_slice(&Self::FINGERPRINT.to_be_bytes());
        self.encode_one(out)
    }

    /// Decodes a published payload: checks the fingerprint, every length and that nothing is
    /// left over.
    fn decode_with_limits(buf: &[u8], limits: &DecodeLimits) -> Result<Self, DecodeError> {
        let found = peek_fingerprint(buf)?;
        if found != Self::FINGERPRINT {
            return Err(DecodeError::FingerprintMismatch {
                type_name: Self::TYPE_NAME,
                expected: Self::FINGERPRINT,
                found,
            });
        }
        let mut reader = Reader::new(&buf[8..], *limits);
        let value = Self::decode_one(&mut reader)?;
        match reader.remaining() {
            0 => Ok(value),
            extra => Err(DecodeError::TrailingBytes { extra }),
        }
    }

    /// [`Message::decode_with_limits`] with [`DecodeLimits::default`].
    fn decode(buf: &[u8]) -> Result<Self, DecodeError> {
        Self::decode_with_limits(buf, &DecodeLimits::default())
    }
}

/// The first 8 bytes of a payload as a big-endian fingerprint.
pub fn peek_fingerprint(buf: &[u8]) -> Result<u64, DecodeError> {
    let head: [u8; 8] =
        buf.get(..8)
            .and_then(|s| s.try_into().ok())
            .ok_or(DecodeError::Truncated {
                offset: 0,
                needed: 8,
                available: buf.len(),
            })?;
    Ok(u64::from_be_bytes(head))
}

/// Fixed-size scalar types of the wire format.
pub trait WirePrimitive: Copy {
    const SIZE: usize;
    /// `bytes` has exactly `SIZE` elements.
    fn from_be(bytes: &[u8]) -> Self;
    fn put(self, out: &mut Vec<u8>);
    /// Writes the big-endian bytes into `dst`, which has exactly `SIZE` elements.
    fn write_be(self, dst: &mut [u8]);
}

/// Appends a slice of scalars. Resizing once and filling fixed-size chunks lets the compiler
/// vectorise the byte swaps, which per-element `extend_from_slice` prevents.
pub fn put_slice<T: WirePrimitive>(values: &[T], out: &mut Vec<u8>) {
    let start = out.len();
    out.resize(start + values.len() * T::SIZE, 0);
    for (dst, value) in out[start..].chunks_exact_mut(T::SIZE).zip(values) {
        value.write_be(dst);
    }
}

macro_rules! wire_number {
    ($($t:ty),*) => {$(
        impl WirePrimitive for $t {
            const SIZE: usize = std::mem::size_of::<$t>();
            #[inline]
            fn from_be(bytes: &[u8]) -> Self {
                let mut raw = [0u8; std::mem::size_of::<$t>()];
                raw.copy_from_slice(bytes);
                <$t>::from_be_bytes(raw)
            }
            #[inline]
            fn put(self, out: &mut Vec<u8>) {
                out.extend_from_slice(&self.to_be_bytes());
            }
            #[inline]
            fn write_be(self, dst: &mut [u8]) {
                dst.copy_from_slice(&self.to_be_bytes());
            }
        }
    )*};
}
wire_number!(i8, i16, i32, i64, u8, f32, f64);

impl WirePrimitive for bool {
    const SIZE: usize = 1;
    /// Any non-zero byte is true, as in lcm-gen's C and Python decoders.
    #[inline]
    fn from_be(bytes: &[u8]) -> Self {
        bytes.first().is_some_and(|&b| b != 0)
    }
    #[inline]
    fn put(self, out: &mut Vec<u8>) {
        out.push(u8::from(self));
    }
    #[inline]
    fn write_be(self, dst: &mut [u8]) {
        if let Some(b) = dst.first_mut() {
            *b = u8::from(self);
        }
    }
}

/// Appends an LCM string: i32 length including the NUL, the bytes, the NUL.
pub fn put_string(out: &mut Vec<u8>, s: &str) -> Result<(), EncodeError> {
    let len = i32::try_from(s.len() + 1)
        .ok()
        .filter(|&l| l < i32::MAX)
        .ok_or(EncodeError::StringTooLong { len: s.len() })?;
    out.extend_from_slice(&len.to_be_bytes());
    out.extend_from_slice(s.as_bytes());
    out.push(0);
    Ok(())
}

/// Converts a length member to an array size before encoding.
pub fn encode_dim(
    value: i64,
    type_name: &'static str,
    field: &'static str,
) -> Result<usize, EncodeError> {
    usize::try_from(value).map_err(|_| EncodeError::NegativeLength {
        type_name,
        field,
        value,
    })
}

/// Checks that an array has as many elements as its length member says.
pub fn check_len(
    actual: usize,
    declared: usize,
    type_name: &'static str,
    field: &'static str,
) -> Result<(), EncodeError> {
    if actual == declared {
        Ok(())
    } else {
        Err(EncodeError::LengthMismatch {
            type_name,
            field,
            declared,
            actual,
        })
    }
}

/// Bounds-checked cursor over an encoded message.
#[derive(Debug)]
pub struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
    depth: usize,
    limits: DecodeLimits,
}

impl<'a> Reader<'a> {
    pub fn new(buf: &'a [u8], limits: DecodeLimits) -> Self {
        Reader {
            buf,
            pos: 0,
            depth: 0,
            limits,
        }
    }

    pub fn remaining(&self) -> usize {
        self.buf.len() - self.pos
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], DecodeError> {
        let available = self.remaining();
        if n > available {
            return Err(DecodeError::Truncated {
                offset: self.pos,
                needed: n,
                available,
            });
        }
        let bytes = &self.buf[self.pos..self.pos + n];
        self.pos += n;
        Ok(bytes)
    }

    #[inline]
    pub fn read_prim<T: WirePrimitive>(&mut self) -> Result<T, DecodeError> {
        self.take(T::SIZE).map(T::from_be)
    }

    /// Reads `n` scalars; the caller has checked `n` with [`Reader::check_array`].
    pub fn read_prim_vec<T: WirePrimitive>(&mut self, n: usize) -> Result<Vec<T>, DecodeError> {
        let total = n.checked_mul(T::SIZE).ok_or(DecodeError::Truncated {
            offset: self.pos,
            needed: usize::MAX,
            available: self.remaining(),
        })?;
        let bytes = self.take(total)?;
        Ok(bytes.chunks_exact(T::SIZE).map(T::from_be).collect())
    }

    pub fn read_string(&mut self) -> Result<String, DecodeError> {
        let offset = self.pos;
        let length: i32 = self.read_prim()?;
        let len = usize::try_from(length).ok().filter(|&l| l >= 1).ok_or(
            DecodeError::BadStringLength {
                offset,
                length: i64::from(length),
            },
        )?;
        let bytes = self.take(len)?;
        let (body, nul) = bytes.split_at(len - 1);
        if nul != [0] {
            return Err(DecodeError::StringNotTerminated { offset });
        }
        String::from_utf8(body.to_vec()).map_err(|_| DecodeError::StringNotUtf8 { offset })
    }

    /// Converts a decoded length member to an array size, applying the limits.
    pub fn decode_dim(
        &self,
        value: i64,
        type_name: &'static str,
        field: &'static str,
    ) -> Result<usize, DecodeError> {
        let n = usize::try_from(value).map_err(|_| DecodeError::NegativeLength {
            type_name,
            field,
            value,
        })?;
        if n > self.limits.max_array_len {
            return Err(DecodeError::ArrayTooLong {
                type_name,
                field,
                value: n,
                limit: self.limits.max_array_len,
            });
        }
        Ok(n)
    }

    /// Rejects an array of shape `dims` whose elements (each at least `elem_min_len` bytes,
    /// counted as at least 1) cannot fit in the rest of the buffer. Partial products (rows of
    /// a multi-dimensional array) may exceed the remaining bytes by at most
    /// [`EMPTY_ROW_ALLOWANCE`]: rows whose inner length is 0 take no bytes on the wire, and
    /// without this bound `v[huge][0]` would make us build a huge number of empty rows.
    pub fn check_array(
        &self,
        dims: &[usize],
        elem_min_len: usize,
        type_name: &'static str,
        field: &'static str,
    ) -> Result<(), DecodeError> {
        let available = self.remaining();
        let mut count: u128 = 1;
        let too_big = |elements: u128| DecodeError::ArrayExceedsBuffer {
            type_name,
            field,
            elements,
            available,
        };
        let row_limit = available as u128 + EMPTY_ROW_ALLOWANCE as u128;
        for &d in dims {
            count = count.saturating_mul(d as u128);
            if count > row_limit {
                return Err(too_big(count));
            }
        }
        if count.saturating_mul(elem_min_len.max(1) as u128) > available as u128 {
            return Err(too_big(count));
        }
        Ok(())
    }

    /// Called by every struct decoder before its members.
    pub fn enter(&mut self, type_name: &'static str) -> Result<(), DecodeError> {
        if self.depth >= self.limits.max_depth {
            return Err(DecodeError::TooDeep {
                type_name,
                limit: self.limits.max_depth,
            });
        }
        self.depth += 1;
        Ok(())
    }

    /// Called by every struct decoder after its members.
    pub fn leave(&mut self) {
        self.depth = self.depth.saturating_sub(1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strings_are_length_bytes_nul() {
        let mut out = Vec::new();
        put_string(&mut out, "ab").unwrap();
        assert_eq!(out, [0, 0, 0, 3, b'a', b'b', 0]);
        let mut r = Reader::new(&out, DecodeLimits::default());
        assert_eq!(r.read_string().unwrap(), "ab");
        assert_eq!(r.remaining(), 0);
    }

    #[test]
    fn malformed_strings_are_rejected() {
        let cases: [(&[u8], &str); 4] = [
            (&[0, 0, 0, 0], "length"),
            (&[0xff, 0xff, 0xff, 0xff], "length"),
            (&[0, 0, 0, 2, b'a', b'b'], "NUL"),
            (&[0, 0, 0, 3, 0xff, 0xfe, 0], "UTF-8"),
        ];
        for (bytes, what) in cases {
            let err = Reader::new(bytes, DecodeLimits::default())
                .read_string()
                .unwrap_err();
            assert!(err.to_string().contains(what), "{err}");
        }
        let err = Reader::new(&[0, 0, 0, 9, b'a'], DecodeLimits::default())
            .read_string()
            .unwrap_err();
        assert!(matches!(
            err,
            DecodeError::Truncated {
                needed: 9,
                available: 1,
                ..
            }
        ));
    }

    #[test]
    fn array_check_counts_partial_products() {
        let buf = [0u8; 16];
        let r = Reader::new(&buf, DecodeLimits::default());
        assert!(r.check_array(&[2], 8, "t", "f").is_ok());
        assert!(r.check_array(&[3], 8, "t", "f").is_err());
        // A million empty rows claim nothing per element but must still be refused.
        assert!(r.check_array(&[1_000_000, 0], 8, "t", "f").is_err());
        assert!(r
            .check_array(&[usize::MAX, usize::MAX], 1, "t", "f")
            .is_err());
        assert!(r.check_array(&[16, 0], 8, "t", "f").is_ok());
        // Legitimate: three empty rows at the very end of a message.
        let end = Reader::new(&[], DecodeLimits::default());
        assert!(end.check_array(&[3, 0], 5, "t", "f").is_ok());
        assert!(end
            .check_array(&[EMPTY_ROW_ALLOWANCE + 1, 0], 5, "t", "f")
            .is_err());
        assert!(end.check_array(&[1], 5, "t", "f").is_err());
    }
}
