//! The SIMD instruction set the kernels run with, chosen at run time.
//!
//! The hot kernels (the compositor of `render::composite`) are written once, as plain Rust over
//! fixed-width lane arrays, and compiled several times: for the baseline target ([`Simd::Scalar`],
//! SSE2 on x86-64), with AVX2 and FMA enabled ([`Simd::Avx2`], 8 f32 lanes) and with AVX-512 and
//! FMA enabled ([`Simd::Avx512`], 16 f32 lanes). Every lane performs the same IEEE-754 operations
//! in the same order in every version, so all paths give the same bits; the tests force each path
//! the CPU supports and compare bits. Rust never fuses a multiply and an add by itself; where the
//! kernels ask for a fused multiply-add (`mul_add`, one rounding) the AVX2 and AVX-512 versions
//! run the FMA instruction and the baseline version calls the C library's `fma` / `fmaf`, which
//! is also correctly rounded: the same bits, at a cost (the compositor's scalar path is about
//! 5 x slower than with separate multiplies and adds, see `docs/measurements.md`).
//!
//! [`Simd::active`] is the widest path the CPU supports, capped by the environment variable
//! `UNISPINE_SIMD` (`scalar`, `avx2` or `avx512`) when it is set to one of those names (other
//! values are ignored; [`Simd::from_env`] reports them).

use std::sync::OnceLock;

/// A SIMD instruction set of the kernels, narrowest first.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Simd {
    /// The baseline target (SSE2 on x86-64; whatever the target has elsewhere).
    Scalar,
    /// x86-64 AVX2 and FMA (8 f32 lanes).
    Avx2,
    /// x86-64 AVX-512 F/BW/DQ/VL and FMA (16 f32 lanes).
    Avx512,
}

impl Simd {
    /// Every path, narrowest first.
    pub const ALL: [Simd; 3] = [Simd::Scalar, Simd::Avx2, Simd::Avx512];

    /// Name used by `UNISPINE_SIMD` and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Simd::Scalar => "scalar",
            Simd::Avx2 => "avx2",
            Simd::Avx512 => "avx512",
        }
    }

    /// The path named `s` ([`Simd::name`]), if any.
    pub fn parse(s: &str) -> Option<Simd> {
        Simd::ALL.into_iter().find(|p| p.name() == s.trim())
    }

    /// Whether this CPU can run the path.
    pub fn supported(self) -> bool {
        match self {
            Simd::Scalar => true,
            #[cfg(target_arch = "x86_64")]
            Simd::Avx2 => {
                std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma")
            }
            #[cfg(target_arch = "x86_64")]
            Simd::Avx512 => {
                std::is_x86_feature_detected!("avx512f")
                    && std::is_x86_feature_detected!("avx512bw")
                    && std::is_x86_feature_detected!("avx512dq")
                    && std::is_x86_feature_detected!("avx512vl")
                    && std::is_x86_feature_detected!("fma")
            }
            #[cfg(not(target_arch = "x86_64"))]
            _ => false,
        }
    }

    /// The paths this CPU supports, narrowest first.
    pub fn supported_paths() -> Vec<Simd> {
        Simd::ALL.into_iter().filter(|p| p.supported()).collect()
    }

    /// The widest path this CPU supports.
    pub fn widest() -> Simd {
        Simd::supported_paths()
            .pop()
            .expect("the scalar path is always supported")
    }

    /// `self` if supported, else the widest supported path narrower than `self`.
    pub fn or_narrower(self) -> Simd {
        Simd::ALL
            .into_iter()
            .rfind(|p| *p <= self && p.supported())
            .unwrap_or(Simd::Scalar)
    }

    /// `UNISPINE_SIMD` read from the environment: `Ok(None)` when unset, an error naming the
    /// value when it is not a path name.
    pub fn from_env() -> Result<Option<Simd>, String> {
        match std::env::var("UNISPINE_SIMD") {
            Err(_) => Ok(None),
            Ok(v) => Simd::parse(&v)
                .map(Some)
                .ok_or_else(|| format!("UNISPINE_SIMD=`{v}` is not one of scalar, avx2, avx512")),
        }
    }

    /// The path the kernels use by default: the widest supported one, capped by a valid
    /// `UNISPINE_SIMD` (read once per process).
    pub fn active() -> Simd {
        static ACTIVE: OnceLock<Simd> = OnceLock::new();
        *ACTIVE.get_or_init(|| match Simd::from_env() {
            Ok(Some(p)) => p.or_narrower(),
            _ => Simd::widest(),
        })
    }
}

/// Whether the CPU executes a 512-bit vector operation as two 256-bit halves (AMD Zen 4, the
/// only AVX-512 CPU of AMD's family 19h), so that 16 lanes cost about what two steps of 8 do.
/// Kernels whose best width was measured to differ between such CPUs and those with full-width
/// 512-bit units ([`crate::drr::MarchLanes`]) ask this; it changes no result.
pub fn splits_512_bit() -> bool {
    static SPLITS: OnceLock<bool> = OnceLock::new();
    *SPLITS.get_or_init(|| {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::__cpuid;
            // Leaf 0: the vendor string in ebx, edx, ecx; leaf 1: the family in eax (base
            // family bits 8-11, plus the extended family, bits 20-27, when the base is 15).
            let v = __cpuid(0);
            let amd = (v.ebx, v.edx, v.ecx) == (0x6874_7541, 0x6974_6e65, 0x444d_4163);
            let eax = __cpuid(1).eax;
            let base = (eax >> 8) & 0xf;
            let family = if base == 0xf {
                base + ((eax >> 20) & 0xff)
            } else {
                base
            };
            amd && family == 0x19
        }
        #[cfg(not(target_arch = "x86_64"))]
        false
    })
}

/// Two copies of a kernel entry point with one signature: the first compiled with AVX2 and FMA
/// enabled, the second with AVX-512 F/BW/DQ/VL and FMA (the features [`Simd::supported`]
/// checks), each running its own body. The bodies call `#[inline(always)]` generic code, which is
/// then compiled for that instruction set; the functions are `unsafe` to call (the CPU must have the features) and exist
/// on x86-64 only.
///
/// ```text
/// wide_kernels! {
///     /// Docs of both.
///     unsafe fn [R: Real](x: &mut [R]);
///     scale_avx2 => { scale::<R>(x) }
///     scale_avx512 => { scale::<R>(x) }
/// }
/// ```
///
/// (Bodies must not hand the vector work to a closure: a closure that is not inlined is compiled
/// without the function's target features.)
macro_rules! wide_kernels {
    (
        $(#[$meta:meta])*
        $vis:vis unsafe fn [$($gen:tt)*] ($($arg:ident: $ty:ty),* $(,)?) $(-> $ret:ty)?;
        $avx2:ident => $b2:block
        $avx512:ident => $b5:block
    ) => {
        $(#[$meta])*
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2,fma")]
        $vis unsafe fn $avx2<$($gen)*>($($arg: $ty),*) $(-> $ret)? $b2

        $(#[$meta])*
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx512f,avx512bw,avx512dq,avx512vl,fma")]
        $vis unsafe fn $avx512<$($gen)*>($($arg: $ty),*) $(-> $ret)? $b5
    };
}
pub(crate) use wide_kernels;

/// f32 accumulators of the peak-throughput loop: 12 vectors of 8 lanes or 6 of 16, enough
/// independent multiply-add chains to keep every floating-point pipe busy while they stay in
/// registers.
const PEAK_LANES: usize = 96;

/// One thread's share of [`peak_flops`]: `iters` rounds of `x <- x * m + c` (a multiply and a
/// separate add, like most of the kernels' operations) on [`PEAK_LANES`] accumulators. Returns a value that
/// depends on every accumulator so the work is not optimised away.
#[inline(always)]
fn peak_loop(iters: u64, m: f32, c: f32) -> f32 {
    let mut acc = [1.0f32; PEAK_LANES];
    for _ in 0..iters {
        for a in acc.iter_mut() {
            *a = *a * m + c;
        }
    }
    acc.iter().sum()
}

wide_kernels! {
    unsafe fn [](iters: u64, m: f32, c: f32) -> f32;
    peak_loop_avx2 => { peak_loop(iters, m, c) }
    peak_loop_avx512 => { peak_loop(iters, m, c) }
}

/// Runs the peak-throughput loop of f32 multiplies and adds (not fused: the kernels do not
/// fuse) with the instruction set `simd` (or the widest supported narrower one) on `threads`
/// threads at once, each doing `iters` rounds of `PEAK_LANES` multiply-adds, and returns the
/// number of floating-point operations done. The caller times it: flops over wall time is the
/// machine's peak rate, flops over the process CPU time its peak per busy core (the measure
/// that other load on a shared machine does not lower).
pub fn peak_run(simd: Simd, threads: usize, iters: u64) -> u64 {
    let simd = simd.or_narrower();
    let threads = threads.max(1);
    let (m, c) = (
        std::hint::black_box(0.999_9f32),
        std::hint::black_box(1e-4f32),
    );
    let run = move || -> f32 {
        #[cfg(target_arch = "x86_64")]
        match simd {
            // SAFETY: `or_narrower` returned a supported instruction set.
            Simd::Avx512 => return unsafe { peak_loop_avx512(iters, m, c) },
            Simd::Avx2 => return unsafe { peak_loop_avx2(iters, m, c) },
            Simd::Scalar => {}
        }
        peak_loop(iters, m, c)
    };
    std::thread::scope(|s| {
        let hs: Vec<_> = (0..threads).map(|_| s.spawn(run)).collect();
        for h in hs {
            std::hint::black_box(h.join().expect("the peak loop does not panic"));
        }
    });
    threads as u64 * iters * PEAK_LANES as u64 * 2
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_fallback_is_supported() {
        for p in Simd::ALL {
            assert_eq!(Simd::parse(p.name()), Some(p));
            assert!(p.or_narrower().supported());
            assert!(p.or_narrower() <= p);
        }
        assert_eq!(Simd::parse("sse9"), None);
        assert!(Simd::Scalar.supported());
        assert!(Simd::widest().supported());
        assert!(Simd::active() <= Simd::widest());
    }

    #[test]
    fn peak_loop_runs_on_every_supported_path() {
        // Finite and positive on every path (the ratio between paths depends on load).
        for p in Simd::supported_paths() {
            let t0 = std::time::Instant::now();
            let f = peak_run(p, 2, 20_000);
            assert_eq!(f, 2 * 20_000 * PEAK_LANES as u64 * 2);
            assert!(t0.elapsed().as_secs_f64() > 0.0, "{p:?}");
        }
    }
}
