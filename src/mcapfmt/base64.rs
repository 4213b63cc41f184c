//! Standard base64 (RFC 4648, with padding): what Foxglove's JSON schemas use for bytes.

const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

/// Two base64 characters for each 12-bit value: one lookup per 12 bits instead of
/// one per 6 (the recorder base64-encodes every raw frame).
static PAIRS: [[u8; 2]; 4096] = {
    let mut t = [[0u8; 2]; 4096];
    let mut i = 0;
    while i < 4096 {
        t[i] = [ALPHABET[i >> 6], ALPHABET[i & 63]];
        i += 1;
    }
    t
};

/// Appends the base64 text of `data` to `out`.
pub fn encode_into(data: &[u8], out: &mut Vec<u8>) {
    let start = out.len();
    let whole = data.len() / 3;
    // Fill a pre-sized slice: no capacity check per byte.
    out.resize(start + whole * 4, 0);
    let dst = &mut out[start..];
    // Six bytes (two groups) per step from one 8-byte load where the input allows.
    let mut groups = 0;
    let six = data.len().saturating_sub(2) / 6;
    for k in 0..six {
        let w = u64::from_be_bytes(data[k * 6..k * 6 + 8].try_into().expect("8 bytes"));
        let o = &mut dst[k * 8..k * 8 + 8];
        let n = (w >> 16) as usize;
        o[0..2].copy_from_slice(&PAIRS[(n >> 36) & 4095]);
        o[2..4].copy_from_slice(&PAIRS[(n >> 24) & 4095]);
        o[4..6].copy_from_slice(&PAIRS[(n >> 12) & 4095]);
        o[6..8].copy_from_slice(&PAIRS[n & 4095]);
        groups += 2;
    }
    for (c, o) in data[groups * 3..]
        .chunks_exact(3)
        .zip(dst[groups * 4..].chunks_exact_mut(4))
    {
        let n = ((c[0] as usize) << 16) | ((c[1] as usize) << 8) | c[2] as usize;
        o[0..2].copy_from_slice(&PAIRS[n >> 12]);
        o[2..4].copy_from_slice(&PAIRS[n & 4095]);
    }
    let chunks = data.chunks_exact(3);
    match chunks.remainder() {
        [a] => {
            let n = (*a as u32) << 16;
            out.extend_from_slice(&[
                ALPHABET[(n >> 18) as usize & 63],
                ALPHABET[(n >> 12) as usize & 63],
                b'=',
                b'=',
            ]);
        }
        [a, b] => {
            let n = (*a as u32) << 16 | (*b as u32) << 8;
            out.extend_from_slice(&[
                ALPHABET[(n >> 18) as usize & 63],
                ALPHABET[(n >> 12) as usize & 63],
                ALPHABET[(n >> 6) as usize & 63],
                b'=',
            ]);
        }
        _ => {}
    }
}

const fn table() -> [u8; 256] {
    let mut t = [255u8; 256];
    let mut i = 0;
    while i < 64 {
        t[ALPHABET[i] as usize] = i as u8;
        i += 1;
    }
    t
}
const DECODE: [u8; 256] = table();

/// The bytes of base64 `text`, or `None` if it is not valid base64.
pub fn decode(text: &[u8]) -> Option<Vec<u8>> {
    if !text.len().is_multiple_of(4) {
        return None;
    }
    let pad = text.iter().rev().take_while(|&&c| c == b'=').count();
    if pad > 2 {
        return None;
    }
    let mut out = Vec::with_capacity(text.len() / 4 * 3);
    for (k, c) in text.chunks_exact(4).enumerate() {
        let last = (k + 1) * 4 == text.len();
        let mut n = 0u32;
        for (j, &ch) in c.iter().enumerate() {
            let v = if last && ch == b'=' && j >= 4 - pad {
                0
            } else {
                let v = DECODE[ch as usize];
                if v == 255 {
                    return None;
                }
                v
            };
            n = n << 6 | v as u32;
        }
        let bytes = [(n >> 16) as u8, (n >> 8) as u8, n as u8];
        let keep = if last { 3 - pad } else { 3 };
        out.extend_from_slice(&bytes[..keep]);
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    #[test]
    fn known_vectors() {
        for (raw, text) in [
            (&b""[..], &b""[..]),
            (b"f", b"Zg=="),
            (b"fo", b"Zm8="),
            (b"foo", b"Zm9v"),
            (b"foob", b"Zm9vYg=="),
            (b"fooba", b"Zm9vYmE="),
            (b"foobar", b"Zm9vYmFy"),
        ] {
            let mut out = Vec::new();
            super::encode_into(raw, &mut out);
            assert_eq!(out, text);
            assert_eq!(super::decode(text).unwrap(), raw);
        }
        // Every length around the 6-byte fast path, against the plain definition.
        for len in 0..40usize {
            let raw: Vec<u8> = (0..len).map(|i| (i * 37 + 11) as u8).collect();
            let mut out = Vec::new();
            super::encode_into(&raw, &mut out);
            assert_eq!(super::decode(&out).unwrap(), raw, "length {len}");
            let plain: Vec<u8> = raw
                .chunks(3)
                .flat_map(|c| {
                    let n = (c[0] as u32) << 16
                        | (*c.get(1).unwrap_or(&0) as u32) << 8
                        | *c.get(2).unwrap_or(&0) as u32;
                    let a = super::ALPHABET;
                    let mut q = vec![a[(n >> 18) as usize & 63], a[(n >> 12) as usize & 63]];
                    q.push(if c.len() > 1 {
                        a[(n >> 6) as usize & 63]
                    } else {
                        b'='
                    });
                    q.push(if c.len() > 2 {
                        a[n as usize & 63]
                    } else {
                        b'='
                    });
                    q
                })
                .collect();
            assert_eq!(out, plain, "length {len}");
        }
        assert!(super::decode(b"Zm9").is_none());
        assert!(super::decode(b"Zm!v").is_none());
    }
}
