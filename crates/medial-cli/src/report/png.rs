//! A small PNG encoder for the report's rendered images (8-bit RGB, no filtering), in plain
//! Rust: the pixels are deflated with the fixed Huffman code and back-references to the pixel
//! before (distance 3) and to the row above, which is what flat-shaded renderings repeat.

/// The PNG file of a `width × height` RGB image, `rgb` row by row, 3 bytes a pixel.
///
/// # Panics
/// When `rgb.len() != 3 · width · height` or the image is empty (the report's own images never
/// are).
pub fn encode(width: usize, height: usize, rgb: &[u8]) -> Vec<u8> {
    assert!(width > 0 && height > 0 && rgb.len() == 3 * width * height);
    let stride = 1 + 3 * width;
    let mut raw = Vec::with_capacity(stride * height);
    for row in rgb.chunks(3 * width) {
        raw.push(0); // filter type None
        raw.extend_from_slice(row);
    }
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut header = Vec::new();
    header.extend_from_slice(&(width as u32).to_be_bytes());
    header.extend_from_slice(&(height as u32).to_be_bytes());
    header.extend_from_slice(&[8, 2, 0, 0, 0]);
    chunk(&mut out, b"IHDR", &header);
    chunk(&mut out, b"IDAT", &zlib(&raw, stride));
    chunk(&mut out, b"IEND", &[]);
    out
}

/// `bytes` in base64 (RFC 4648, with padding), for a `data:` address.
pub fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for group in bytes.chunks(3) {
        let n = group
            .iter()
            .enumerate()
            .fold(0u32, |n, (k, &b)| n | u32::from(b) << (16 - 8 * k));
        for k in 0..4 {
            out.push(if k <= group.len() {
                char::from(ALPHABET[(n >> (18 - 6 * k) & 63) as usize])
            } else {
                '='
            });
        }
    }
    out
}

/// Appends a chunk: length, type, data, CRC-32 of type and data.
fn chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
    out.extend_from_slice(&(data.len() as u32).to_be_bytes());
    let start = out.len();
    out.extend_from_slice(kind);
    out.extend_from_slice(data);
    let crc = crc32(&out[start..]);
    out.extend_from_slice(&crc.to_be_bytes());
}

/// CRC-32 (ISO-HDLC, as PNG uses it).
fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 == 1 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

/// Adler-32 (zlib's checksum).
fn adler32(bytes: &[u8]) -> u32 {
    let (mut a, mut b) = (1u32, 0u32);
    for &x in bytes {
        a = (a + u32::from(x)) % 65521;
        b = (b + a) % 65521;
    }
    (b << 16) | a
}

/// Bits written least significant first, as deflate packs them.
#[derive(Default)]
struct Bits {
    bytes: Vec<u8>,
    acc: u64,
    count: u32,
}

impl Bits {
    /// The low `n` bits of `value`, least significant first.
    fn put(&mut self, value: u32, n: u32) {
        self.acc |= u64::from(value) << self.count;
        self.count += n;
        while self.count >= 8 {
            self.bytes.push(self.acc as u8);
            self.acc >>= 8;
            self.count -= 8;
        }
    }

    /// A Huffman code of `n` bits, most significant first.
    fn code(&mut self, code: u32, n: u32) {
        self.put(code.reverse_bits() >> (32 - n), n);
    }

    fn finish(mut self) -> Vec<u8> {
        if self.count > 0 {
            self.bytes.push(self.acc as u8);
        }
        self.bytes
    }
}

/// The fixed Huffman code of literal/length symbol `s`.
fn literal(bits: &mut Bits, s: u32) {
    match s {
        0..=143 => bits.code(0x30 + s, 8),
        144..=255 => bits.code(0x190 + s - 144, 9),
        256..=279 => bits.code(s - 256, 7),
        _ => bits.code(0xC0 + s - 280, 8),
    }
}

/// The symbol, extra bits and their count of a match length `3 ..= 258`.
fn length_code(len: usize) -> (u32, u32, u32) {
    if len == 258 {
        return (285, 0, 0);
    }
    if len < 11 {
        return (257 + len as u32 - 3, 0, 0);
    }
    for k in 8..28u32 {
        let extra = (k - 4) / 4;
        let base = ((4 + k % 4) << extra) + 3;
        if (len as u32) < base + (1 << extra) {
            return (257 + k, len as u32 - base, extra);
        }
    }
    unreachable!("lengths are at most 258")
}

/// The code, extra bits and their count of a distance `1 ..= 32768`.
fn distance_code(distance: usize) -> (u32, u32, u32) {
    let d = distance as u32;
    if d <= 4 {
        return (d - 1, 0, 0);
    }
    for c in 4..30u32 {
        let extra = c / 2 - 1;
        let base = ((2 + (c & 1)) << extra) + 1;
        if d < base + (1 << extra) {
            return (c, d - base, extra);
        }
    }
    unreachable!("distances are at most 32768")
}

/// `data` as a zlib stream of one fixed-Huffman deflate block, matching against the bytes 3
/// back and `stride` back (greedy, the longer match).
fn zlib(data: &[u8], stride: usize) -> Vec<u8> {
    let mut bits = Bits::default();
    bits.put(1, 1); // the final block
    bits.put(1, 2); // fixed Huffman codes
    let run = |p: usize, d: usize| -> usize {
        if d > p || d > 32768 {
            return 0;
        }
        let limit = (data.len() - p).min(258);
        (0..limit)
            .take_while(|&k| data[p + k] == data[p + k - d])
            .count()
    };
    let mut p = 0;
    while p < data.len() {
        let (len, d) = [3, stride]
            .into_iter()
            .map(|d| (run(p, d), d))
            .fold((0, 0), |best, m| if m.0 > best.0 { m } else { best });
        if len >= 3 {
            let (symbol, extra, n) = length_code(len);
            literal(&mut bits, symbol);
            bits.put(extra, n);
            let (code, extra, n) = distance_code(d);
            bits.code(code, 5);
            bits.put(extra, n);
            p += len;
        } else {
            literal(&mut bits, u32::from(data[p]));
            p += 1;
        }
    }
    literal(&mut bits, 256);
    let mut out = vec![0x78, 0x01];
    out.extend(bits.finish());
    out.extend_from_slice(&adler32(data).to_be_bytes());
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Decodes a PNG with the `png` crate: width, height, RGB bytes.
    fn decode(bytes: &[u8]) -> (u32, u32, Vec<u8>) {
        let mut reader = png::Decoder::new(std::io::Cursor::new(bytes))
            .read_info()
            .unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!(info.color_type, png::ColorType::Rgb);
        buf.truncate(info.buffer_size());
        (info.width, info.height, buf)
    }

    #[test]
    fn base64_of_known_strings() {
        assert_eq!(base64(b""), "");
        assert_eq!(base64(b"f"), "Zg==");
        assert_eq!(base64(b"fo"), "Zm8=");
        assert_eq!(base64(b"foobar"), "Zm9vYmFy");
        assert_eq!(base64(&[0xFF, 0xEF]), "/+8=");
    }

    #[test]
    fn known_checksums() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(adler32(b"Wikipedia"), 0x11E6_0398);
    }

    #[test]
    fn every_length_and_distance_code_is_in_range() {
        assert_eq!(length_code(3), (257, 0, 0));
        assert_eq!(length_code(11), (265, 0, 1));
        assert_eq!(length_code(12), (265, 1, 1));
        assert_eq!(length_code(227), (284, 0, 5));
        assert_eq!(length_code(257), (284, 30, 5));
        assert_eq!(distance_code(5), (4, 0, 1));
        assert_eq!(distance_code(1081), (20, 56, 9));
        assert_eq!(distance_code(32768), (29, 8191, 13));
    }

    #[test]
    fn images_decode_to_their_pixels() {
        // Flat areas (long matches), a gradient (literals) and noise, odd sizes.
        for (w, h) in [(1, 1), (7, 5), (300, 40)] {
            let mut rgb = Vec::new();
            for j in 0..h {
                for i in 0..w {
                    let noise = ((i * 7919 + j * 104_729) % 251) as u8;
                    rgb.extend_from_slice(&match (i / 20 + j / 10) % 3 {
                        0 => [255, 255, 255],
                        1 => [(i % 256) as u8, (j % 256) as u8, 90],
                        _ => [noise, noise / 2, 255 - noise],
                    });
                }
            }
            let bytes = encode(w, h, &rgb);
            assert_eq!(decode(&bytes), (w as u32, h as u32, rgb));
        }
        // A white image compresses to little.
        let white = vec![255; 3 * 400 * 300];
        assert!(encode(400, 300, &white).len() < 3000);
    }
}
