//! Deterministic pseudo-random numbers: every seeded sequence the project draws (the brush's
//! jitter, the stress matrix's random cases, the benchmark scenes, the reference's sample
//! points and the randomized test scenes) comes from one of the three small generators here,
//! so that each recurrence is written once and a seed names the same numbers everywhere.
//! None of them is for anything but reproducible sampling.

use glam::Vec3;

/// Multiplies a seed into a well-mixed, odd state: the start of sequences whose seeds are
/// small counters (a stroke's tag, a case number).
pub fn scrambled(seed: u64) -> u64 {
    seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1
}

/// Uniform draws in [0, 1) from the top bits of a 64-bit word, and the shapes built on them.
macro_rules! draws {
    ($t:ty) => {
        impl $t {
            /// Uniform in [0, 1), from the top 24 bits of the next word.
            pub fn f32(&mut self) -> f32 {
                (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
            }
            /// Uniform in [0, 1), from the top 53 bits of the next word.
            pub fn f64(&mut self) -> f64 {
                (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
            }
            /// Uniform in [lo, hi).
            pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
                lo + (hi - lo) * self.f32()
            }
            /// Each component uniform in [lo, hi), drawn x, y, z.
            pub fn vec3(&mut self, lo: f32, hi: f32) -> Vec3 {
                Vec3::new(self.range(lo, hi), self.range(lo, hi), self.range(lo, hi))
            }
            /// A unit direction: a point of the cube [-1, 1)³ kept where it lies in the shell
            /// between radius 0.2 and 1, normalized.
            pub fn direction(&mut self) -> Vec3 {
                loop {
                    let v = self.vec3(-1.0, 1.0);
                    if v.length() > 0.2 && v.length() < 1.0 {
                        return v.normalize();
                    }
                }
            }
            /// An index in 0..n.
            pub fn pick(&mut self, n: usize) -> usize {
                ((self.f32() * n as f32) as usize).min(n - 1)
            }
            /// −1 or +1, evenly.
            pub fn sign(&mut self) -> f32 {
                if self.f32() < 0.5 {
                    -1.0
                } else {
                    1.0
                }
            }
        }
    };
}

/// The 64-bit linear congruential generator with Knuth's MMIX constants; the state is the
/// last word drawn.
#[derive(Clone, Debug)]
pub struct Lcg(pub u64);

impl Lcg {
    /// The next word.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        self.0
    }
}

draws!(Lcg);

/// Marsaglia's xorshift with shifts 13, 7, 17; the state (never zero) is the last word drawn.
#[derive(Clone, Debug)]
pub struct XorShift(pub u64);

impl XorShift {
    /// The next word.
    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
}

draws!(XorShift);

/// xorshift64*: shifts 12, 25, 27 and an output multiplier, seeded through [`scrambled`].
#[derive(Clone, Debug)]
pub struct XorShiftStar(u64);

impl XorShiftStar {
    pub fn new(seed: u64) -> Self {
        Self(scrambled(seed))
    }
    /// The next word.
    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
}

draws!(XorShiftStar);

#[cfg(test)]
mod tests {
    use super::*;

    /// The recurrences as they were written out where each sequence is drawn, step by step:
    /// the generators must reproduce them exactly, or every seeded scene and stroke changes.
    #[test]
    fn the_generators_reproduce_the_written_out_recurrences() {
        let (mut lcg, mut state) = (Lcg(0x5EED_0036), 0x5EED_0036u64);
        for _ in 0..100 {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            assert_eq!(lcg.f32(), (state >> 40) as f32 / (1u64 << 24) as f32);
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            assert_eq!(lcg.f64(), (state >> 11) as f64 / (1u64 << 53) as f64);
        }
        let (mut xs, mut s) = (XorShift(0x2545_f491_4f6c_dd1d), 0x2545_f491_4f6c_dd1du64);
        for _ in 0..100 {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            assert_eq!(xs.f32(), (s >> 40) as f32 / (1u64 << 24) as f32);
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            assert_eq!(xs.f64(), (s >> 11) as f64 / (1u64 << 53) as f64);
        }
        let (mut star, mut s) = (XorShiftStar::new(42), 42u64.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1);
        for _ in 0..100 {
            s ^= s >> 12;
            s ^= s << 25;
            s ^= s >> 27;
            let v = s.wrapping_mul(0x2545_F491_4F6C_DD1D);
            assert_eq!(star.f32(), (v >> 40) as f32 / (1u64 << 24) as f32);
        }
    }

    /// The first words of each sequence from one seed, worked out apart from this code.
    #[test]
    fn the_first_values_are_the_recorded_ones() {
        let mut lcg = Lcg(12345);
        let got: Vec<u64> = (0..3).map(|_| lcg.next_u64()).collect();
        assert_eq!(got, RECORDED_LCG);
        let mut xs = XorShift(7);
        let got: Vec<u64> = (0..3).map(|_| xs.next_u64()).collect();
        assert_eq!(got, RECORDED_XORSHIFT);
        let mut star = XorShiftStar::new(1);
        let got: Vec<u64> = (0..3).map(|_| star.next_u64()).collect();
        assert_eq!(got, RECORDED_XORSHIFT_STAR);
    }

    const RECORDED_LCG: [u64; 3] = [2021368500568277588, 4895494634720187923, 16336879138292273062];
    const RECORDED_XORSHIFT: [u64; 3] = [7575888327, 8070950887952051652, 13931920357059763743];
    const RECORDED_XORSHIFT_STAR: [u64; 3] = [973819730272012410, 6108091081255984487, 12125365036566318712];
}
