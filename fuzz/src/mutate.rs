//! A small seeded mutator for the stable driver: libFuzzer-style byte mutations plus tokens that
//! matter to these inputs (huge and non-finite numbers, XML and JSON brackets, the oversized
//! network settings that once aborted a run), spliced between the seeds of a corpus.

/// SplitMix64: a tiny, seedable generator (no dependency, identical on every platform).
#[derive(Debug, Clone)]
pub struct SplitMix(u64);

impl SplitMix {
    /// A generator seeded by `seed`.
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// A uniform index in `0..n` (`n > 0`).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
}

/// Tokens inserted or substituted by [`Mutator`]: numbers at and beyond the edges of `f64`,
/// `u64` and `usize`, JSON/TOML/XML syntax, and settings that once aborted a run.
pub const TOKENS: &[&str] = &[
    "0",
    "-0",
    "1",
    "-1",
    "1e200",
    "-1e200",
    "1e308",
    "1.7e308",
    "-1.7e308",
    "1e-320",
    "NaN",
    "Infinity",
    "-Infinity",
    "nan",
    "inf",
    "18446744073709551615",
    "9223372036854775807",
    "-9223372036854775808",
    "4294967296",
    "1000000000000",
    "[",
    "]",
    "{",
    "}",
    ",",
    "\"",
    "\n",
    "=",
    "[[",
    "]]",
    "<",
    ">",
    "/>",
    "</",
    "<x>",
    "<robot name=\"r\">",
    "</robot>",
    "<link name=\"l\"/>",
    "<joint name=\"j\" type=\"revolute\">",
    "<mass value=\"1.7e308\"/>",
    "<origin xyz=\"1e308 0 0\"/>",
    "<axis xyz=\"0 0 0\"/>",
    "hidden = [16384, 16384, 16384, 16384]\n",
    "buffer_size = 1000000000000\n",
    "batch_size = 1000000\n",
    "network = \"conv\"\n[conv]\nchannels = [100000]\nkernels = [3]\nstrides = [1]\n",
    "[agent]\n",
    "[train]\n",
    "[ddpg]\n",
    "[residual]\n",
];

/// Mutates inputs drawn from a seed corpus.
#[derive(Debug, Clone)]
pub struct Mutator {
    rng: SplitMix,
    seeds: Vec<Vec<u8>>,
    max_len: usize,
}

impl Mutator {
    /// A mutator over `seeds` (at least one), seeded by `seed`, whose outputs are at most
    /// `max_len` bytes.
    pub fn new(seeds: Vec<Vec<u8>>, seed: u64, max_len: usize) -> Self {
        assert!(!seeds.is_empty(), "a mutator needs at least one seed input");
        Self {
            rng: SplitMix::new(seed),
            seeds,
            max_len,
        }
    }

    /// The next input: a seed with one to eight mutations (a seed unchanged now and then).
    pub fn next_input(&mut self) -> Vec<u8> {
        let mut x = self.seeds[self.rng.below(self.seeds.len())].clone();
        if self.rng.below(32) == 0 {
            return x;
        }
        for _ in 0..1 + self.rng.below(8) {
            self.mutate(&mut x);
        }
        x.truncate(self.max_len);
        x
    }

    fn mutate(&mut self, x: &mut Vec<u8>) {
        let r = &mut self.rng;
        let pos = |r: &mut SplitMix, x: &Vec<u8>| r.below(x.len() + 1);
        match r.below(9) {
            // Flip one bit.
            0 if !x.is_empty() => {
                let i = r.below(x.len());
                x[i] ^= 1 << r.below(8);
            }
            // Overwrite a byte with a random or a syntax byte.
            1 if !x.is_empty() => {
                let i = r.below(x.len());
                const SYNTAX: &[u8] = b"<>/\"'=[]{},.:-+eE0 \n\t\\";
                x[i] = if r.below(2) == 0 {
                    r.next_u64() as u8
                } else {
                    SYNTAX[r.below(SYNTAX.len())]
                };
            }
            // Delete a range.
            2 if !x.is_empty() => {
                let i = r.below(x.len());
                let n = 1 + r.below(16.min(x.len() - i));
                x.drain(i..i + n);
            }
            // Duplicate a range somewhere (repeats elements, deepens nesting).
            3 if !x.is_empty() => {
                let i = r.below(x.len());
                let n = 1 + r.below(64.min(x.len() - i));
                let chunk = x[i..i + n].to_vec();
                let at = pos(r, x);
                for _ in 0..1 + r.below(4) {
                    x.splice(at..at, chunk.iter().copied());
                }
            }
            // Insert a token.
            4 | 5 => {
                let t = TOKENS[r.below(TOKENS.len())].as_bytes();
                let at = pos(r, x);
                x.splice(at..at, t.iter().copied());
            }
            // Replace a number (a run of digits, dots, signs, exponents) by a token.
            6 => {
                let starts: Vec<usize> = (0..x.len())
                    .filter(|&i| x[i].is_ascii_digit() && (i == 0 || !x[i - 1].is_ascii_digit()))
                    .collect();
                if starts.is_empty() {
                    return;
                }
                let i = starts[r.below(starts.len())];
                let end = (i..x.len())
                    .find(|&j| !(x[j].is_ascii_alphanumeric() || b".-+".contains(&x[j])))
                    .unwrap_or(x.len());
                let t = TOKENS[r.below(20)].as_bytes();
                x.splice(i..end, t.iter().copied());
            }
            // Splice: a prefix of this input and a suffix of another seed.
            7 => {
                let other = &self.seeds[r.below(self.seeds.len())];
                let cut = r.below(x.len() + 1);
                let from = r.below(other.len() + 1);
                x.truncate(cut);
                x.extend_from_slice(&other[from..]);
            }
            // Random bytes.
            _ => {
                let at = pos(r, x);
                let n = 1 + r.below(8);
                let bytes: Vec<u8> = (0..n).map(|_| r.next_u64() as u8).collect();
                x.splice(at..at, bytes);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_inputs_and_lengths_bounded() {
        let seeds = vec![b"[0, 1, 2]".to_vec(), b"<robot name=\"r\"/>".to_vec()];
        let mut a = Mutator::new(seeds.clone(), 7, 64);
        let mut b = Mutator::new(seeds, 7, 64);
        for _ in 0..1000 {
            let x = a.next_input();
            assert!(x.len() <= 64);
            assert_eq!(x, b.next_input());
        }
    }
}
