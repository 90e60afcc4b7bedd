//! Fingerprints: 64-bit FNV-1a hashes that say whether two things are the same (a dataset, a
//! config, a file's payload). Identity checks between runs, not a security measure.
//!
//! - [`fnv1a`](crate::fingerprint::fnv1a): FNV-1a 64 over bytes (cell keys, dataset folder
//!   checksums).
//! - [`Words`](crate::fingerprint::Words): the same recurrence over 64-bit little-endian words,
//!   then the bytes of the tail: eight times fewer multiplications, for the checkpoints' payload checksum and the datasets'
//!   in-memory fingerprint (hundreds of MB at 1024^2). Each step `h = (h ^ w) * p` is a
//!   bijection of `h` for a fixed word, so a change in any one word always changes the result.

/// The FNV-1a 64 offset basis.
pub const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
/// The FNV-1a 64 prime.
pub const FNV_PRIME: u64 = 0x0000_0100_0000_01b3;

/// FNV-1a, 64 bit.
pub fn fnv1a(bytes: &[u8]) -> u64 {
    fnv1a_continue(FNV_OFFSET, bytes)
}

/// FNV-1a, 64 bit, continuing from the state `h`.
pub fn fnv1a_continue(mut h: u64, bytes: &[u8]) -> u64 {
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(FNV_PRIME);
    }
    h
}

/// The word-wise hash (see the module header); feed it any number of slices.
#[derive(Clone, Copy, Debug)]
pub struct Words(u64);

impl Default for Words {
    fn default() -> Self {
        Words(FNV_OFFSET)
    }
}

impl Words {
    /// Add `bytes`: whole 8-byte words first, then the remaining bytes one at a time.
    pub fn bytes(&mut self, bytes: &[u8]) -> &mut Self {
        let mut words = bytes.chunks_exact(8);
        for w in &mut words {
            self.0 ^= u64::from_le_bytes(w.try_into().expect("8 bytes"));
            self.0 = self.0.wrapping_mul(FNV_PRIME);
        }
        self.0 = fnv1a_continue(self.0, words.remainder());
        // The length ends each slice, so that moving bytes between slices changes the result.
        self.0 ^= bytes.len() as u64;
        self.0 = self.0.wrapping_mul(FNV_PRIME);
        self
    }
    /// Add f32 values (their little-endian bytes).
    pub fn f32s(&mut self, v: &[f32]) -> &mut Self {
        let mut b = Vec::with_capacity(4 * v.len().min(1 << 16));
        for c in v.chunks(1 << 16) {
            b.clear();
            c.iter().for_each(|x| b.extend_from_slice(&x.to_le_bytes()));
            self.bytes(&b);
        }
        self
    }
    /// Add f64 values (their little-endian bytes).
    pub fn f64s(&mut self, v: &[f64]) -> &mut Self {
        let b: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
        self.bytes(&b)
    }
    /// The hash so far.
    pub fn finish(&self) -> u64 {
        self.0
    }
    /// The hash so far as 16 hex digits.
    pub fn hex(&self) -> String {
        format!("{:016x}", self.0)
    }
}

/// Fingerprint of a config: its JSON without the `data` field (where the dataset is stored is
/// not part of a config's meaning; the dataset has a fingerprint of its own), as 16 hex digits.
pub fn config<T: serde::Serialize>(cfg: &T) -> String {
    let mut v = serde_json::to_value(cfg).expect("a config serialises");
    if let Some(o) = v.as_object_mut() {
        o.remove("data");
    }
    format!("{:016x}", fnv1a(v.to_string().as_bytes()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fnv1a_matches_the_published_test_vectors() {
        // From the FNV reference test suite (Fowler, Noll, Vo): "" and "a", "foobar".
        assert_eq!(fnv1a(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(fnv1a(b"a"), 0xaf63_dc4c_8601_ec8c);
        assert_eq!(fnv1a(b"foobar"), 0x8594_4171_f739_67e8);
    }

    #[test]
    fn every_single_bit_flip_changes_the_word_hash() {
        let data: Vec<u8> = (0..203u32).map(|i| (i * 37 % 251) as u8).collect();
        let h0 = Words::default().bytes(&data).finish();
        for i in 0..data.len() {
            for bit in 0..8 {
                let mut d = data.clone();
                d[i] ^= 1 << bit;
                assert_ne!(
                    Words::default().bytes(&d).finish(),
                    h0,
                    "byte {i} bit {bit}"
                );
            }
        }
        // Moving a byte from one slice to the next changes it too.
        let a = Words::default()
            .bytes(&data[..9])
            .bytes(&data[9..])
            .finish();
        let b = Words::default()
            .bytes(&data[..10])
            .bytes(&data[10..])
            .finish();
        assert_ne!(a, b);
    }

    #[test]
    fn the_config_fingerprint_ignores_only_the_data_field() {
        let a = serde_json::json!({"data": "/x", "seed": 1, "color": "rirf"});
        let b = serde_json::json!({"data": "/y", "seed": 1, "color": "rirf"});
        let c = serde_json::json!({"data": "/x", "seed": 1, "color": "sh"});
        assert_eq!(config(&a), config(&b));
        assert_ne!(config(&a), config(&c));
    }
}
