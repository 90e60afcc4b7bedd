//! Unit tests of the compositing stage: bitwise agreement with the naive per-pixel reference,
//! FD of the splat-level VJP (f64), background of an empty scene.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::*;
use crate::math::fd;

/// `n` random splats on a `w` x `h` image; sizes from tiny to larger than a tile, opacities
/// from below 1/255 to above the 0.99 clamp.
pub(crate) fn random_splats(n: usize, w: usize, h: usize, seed: u64) -> Splats<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut s = Splats::default();
    for _ in 0..n {
        let sx: f64 = rng.random_range(0.6..12.0);
        let sy: f64 = rng.random_range(0.6..12.0);
        let rho: f64 = rng.random_range(-0.8..0.8);
        let (a, b, c) = (sx * sx, rho * sx * sy, sy * sy);
        let det = a * c - b * b;
        s.mean2d.push([
            rng.random_range(-10.0..w as f64 + 10.0),
            rng.random_range(-10.0..h as f64 + 10.0),
        ]);
        s.conic.push([c / det, -b / det, a / det]);
        let mid = 0.5 * (a + c);
        let l = mid + (mid * mid - det).max(0.1).sqrt();
        s.radius.push((3.0 * l.sqrt()).ceil() as u32);
        s.depth.push(rng.random_range(1.0..10.0));
        s.opacity.push(rng.random_range(0.0..1.0f64).powi(2) * 1.02);
        s.color.push(rng.random_range(0.0..1.0));
    }
    s
}

/// The same splats rounded to f32.
fn to_f32(s: &Splats<f64>) -> Splats<f32> {
    Splats {
        mean2d: s.mean2d.iter().map(|a| a.map(|x| x as f32)).collect(),
        conic: s.conic.iter().map(|a| a.map(|x| x as f32)).collect(),
        depth: s.depth.iter().map(|&x| x as f32).collect(),
        radius: s.radius.clone(),
        opacity: s.opacity.iter().map(|&x| x as f32).collect(),
        color: s.color.iter().map(|&x| x as f32).collect(),
    }
}

#[test]
fn forward_equals_naive_reference_bitwise() {
    for (n, w, h, seed) in [(60, 37, 29, 1), (400, 64, 48, 2), (5, 16, 16, 3)] {
        let mut s = random_splats(n, w, h, seed);
        s.radius[0] = 0; // one culled
        for bg in [0.0, 0.3] {
            let (img, _) = forward(&s, w, h, bg);
            let naive = naive_forward(&s, w, h, bg);
            assert_eq!(img, naive, "n {n} {w}x{h} bg {bg}");
            let s32 = to_f32(&s);
            let (i32_, _) = forward(&s32, w, h, bg as f32);
            assert_eq!(i32_, naive_forward(&s32, w, h, bg as f32));
        }
    }
}

#[test]
fn empty_scene_is_the_background() {
    let s = Splats::<f64>::default();
    let (img, saved) = forward(&s, 20, 7, 0.25);
    assert!(img.data.iter().all(|&v| v == 0.25));
    assert!(saved.final_t.iter().all(|&v| v == 1.0));
    let g = backward(&s, &saved, &Image2d::filled(20, 7, 1.0));
    assert!(g.mean2d.is_empty());
}

fn flat(s: &Splats<f64>) -> Vec<f64> {
    let mut v = Vec::new();
    s.mean2d.iter().for_each(|a| v.extend_from_slice(a));
    s.conic.iter().for_each(|a| v.extend_from_slice(a));
    v.extend_from_slice(&s.opacity);
    v.extend_from_slice(&s.color);
    v
}

fn unflat(v: &[f64], like: &Splats<f64>) -> Splats<f64> {
    let n = like.radius.len();
    let mut s = like.clone();
    for i in 0..n {
        s.mean2d[i] = [v[2 * i], v[2 * i + 1]];
        s.conic[i] = [v[2 * n + 3 * i], v[2 * n + 3 * i + 1], v[2 * n + 3 * i + 2]];
        s.opacity[i] = v[5 * n + i];
        s.color[i] = v[6 * n + i];
    }
    s
}

/// Splats covering the whole 32 x 24 image with o G well inside (1/255, 0.99) at every pixel.
fn smooth_splats(seed: u64, bg: f64) -> Splats<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut s = Splats::default();
    for k in 0..5 {
        let sx: f64 = rng.random_range(12.0..18.0);
        let sy: f64 = rng.random_range(12.0..18.0);
        let rho: f64 = rng.random_range(-0.4..0.4);
        let (a, b, c) = (sx * sx, rho * sx * sy, sy * sy);
        let det = a * c - b * b;
        s.mean2d
            .push([rng.random_range(10.0..22.0), rng.random_range(8.0..16.0)]);
        s.conic.push([c / det, -b / det, a / det]);
        s.radius.push(60);
        s.depth.push(1.0 + k as f64);
        s.opacity.push(rng.random_range(0.3..0.7));
        s.color.push(rng.random_range(0.2..1.0));
    }
    let _ = bg;
    s
}

#[test]
fn splat_gradients_match_central_differences() {
    let (w, h) = (32, 24);
    for (seed, bg) in [(1u64, 0.0), (2, 0.4), (3, -0.2)] {
        let s = smooth_splats(seed, bg);
        let mut rng = ChaCha8Rng::seed_from_u64(seed + 50);
        let wts = Image2d::from_vec(
            w,
            h,
            (0..w * h).map(|_| rng.random_range(-1.0..1.0)).collect(),
        );
        let (_, saved) = forward(&s, w, h, bg);
        let an = backward(&s, &saved, &wts);
        let x = flat(&s);
        let num = fd::central_diff5(
            |v| {
                let (img, _) = forward(&unflat(v, &s), w, h, bg);
                img.data.iter().zip(&wts.data).map(|(a, b)| a * b).sum()
            },
            &x,
            1e-5,
        );
        let ns = unflat(&num, &s);
        let groups = [
            (
                "mean2d",
                an.mean2d.concat(),
                ns.mean2d.iter().flatten().copied().collect::<Vec<_>>(),
            ),
            (
                "conic",
                an.conic.concat(),
                ns.conic.iter().flatten().copied().collect(),
            ),
            ("opacity", an.opacity.clone(), ns.opacity.clone()),
            ("color", an.color.clone(), ns.color.clone()),
        ];
        for (name, a, n) in groups {
            let e = fd::rel_err_maxabs(&a, &n);
            println!("seed {seed} {name}: {e:.1e}");
            assert!(e <= 1e-7, "seed {seed} {name}: {e:e}");
        }
    }
}

#[test]
fn alpha_clamp_and_exclusive_stop() {
    // Three splats on one pixel, each o G > 0.99 there (clamped to 0.99), colours 1, 2, 4.
    // T: 1 -> 0.01 -> 1e-4 (not < 1e-4: blended) -> the third would give 1e-6 < 1e-4: the pixel
    // stops without blending it (exclusive).
    let n = 3;
    let s = Splats {
        mean2d: vec![[0.5, 0.5]; n],
        conic: vec![[0.01, 0.0, 0.01]; n],
        depth: vec![1.0, 2.0, 3.0],
        radius: vec![3; n],
        opacity: vec![0.995; n],
        color: vec![1.0, 2.0, 4.0],
    };
    let bg = 0.5;
    let (img, saved) = forward(&s, 1, 1, bg);
    let om = 1.0 - 0.99f64;
    let t2 = om * om;
    assert!(t2 >= T_MIN && t2 * om < T_MIN);
    let want = 0.99 * 1.0 + om * 0.99 * 2.0 + t2 * bg;
    assert!(
        (img.data[0] - want).abs() < 1e-15,
        "{} vs {want}",
        img.data[0]
    );
    assert_eq!(saved.n_contrib[0], 2);
    assert_eq!(saved.final_t[0], t2);
    assert_eq!(saved.blends, 2);
    let g = backward(&s, &saved, &Image2d::filled(1, 1, 1.0));
    // Clamped: no gradient to opacity, mean or conic; colour gets alpha T.
    for i in 0..3 {
        assert_eq!(g.opacity[i], 0.0);
        assert_eq!(g.mean2d[i], [0.0, 0.0]);
        assert_eq!(g.conic[i], [0.0; 3]);
    }
    assert!((g.color[0] - 0.99).abs() < 1e-15);
    assert!((g.color[1] - 0.99 * om).abs() < 1e-15);
    assert_eq!(g.color[2], 0.0, "the stopping splat is not blended");
    // Below the clamp the opacity gradient is G dC/dalpha (non-zero).
    let mut s2 = s.clone();
    s2.opacity = vec![0.5; 3];
    let (_, sv2) = forward(&s2, 1, 1, bg);
    let g2 = backward(&s2, &sv2, &Image2d::filled(1, 1, 1.0));
    assert!(g2.opacity.iter().all(|&v| v != 0.0));
}

#[test]
fn alpha_below_1_over_255_is_skipped() {
    let s = Splats {
        mean2d: vec![[0.5, 0.5], [0.5, 0.5]],
        conic: vec![[0.01, 0.0, 0.01]; 2],
        depth: vec![1.0, 2.0],
        radius: vec![3; 2],
        opacity: vec![0.5 / 255.0, 0.5],
        color: vec![10.0, 1.0],
    };
    let (img, saved) = forward(&s, 1, 1, 0.0);
    assert_eq!(img.data[0], 0.5);
    assert_eq!(saved.blends, 1);
    let g = backward(&s, &saved, &Image2d::filled(1, 1, 1.0));
    assert_eq!((g.opacity[0], g.color[0]), (0.0, 0.0));
}

#[test]
fn nan_splats_are_an_error_and_never_poison_the_image() {
    let mut s = random_splats(30, 40, 30, 9);
    assert!(validate(&s).is_ok());
    s.conic[4][1] = f64::NAN;
    s.radius[4] = 5;
    let e = validate(&s).unwrap_err().to_string();
    assert!(e.contains("splat 4") && e.contains("conic"), "{e}");
    let (img, saved) = forward(&s, 40, 30, 0.0);
    assert!(img.data.iter().all(|v| v.is_finite()));
    let g = backward(&s, &saved, &Image2d::filled(40, 30, 1.0));
    assert_eq!(g.conic[4], [0.0; 3]);
    assert!(g.mean2d.iter().flatten().all(|v| v.is_finite()));
}

#[test]
fn backward_with_saved_work_lists_equals_rebuilt_lists_bitwise() {
    for (n, w, h, seed) in [(400, 64, 48, 11), (60, 37, 29, 12)] {
        let s = random_splats(n, w, h, seed);
        let mut rng = ChaCha8Rng::seed_from_u64(seed + 7);
        let wts = Image2d::from_vec(
            w,
            h,
            (0..w * h).map(|_| rng.random_range(-1.0..1.0)).collect(),
        );
        let (_, saved) = forward(&s, w, h, 0.2);
        assert_eq!(saved.work.tiles.len(), saved.bins.n_tiles());
        let mut bare = saved.clone();
        bare.work = WorkLists::default();
        assert_eq!(backward(&s, &saved, &wts), backward(&s, &bare, &wts));
        let s32 = to_f32(&s);
        let w32 = Image2d::from_vec(w, h, wts.data.iter().map(|&x| x as f32).collect());
        let (_, saved) = forward(&s32, w, h, 0.2f32);
        let mut bare = saved.clone();
        bare.work = WorkLists::default();
        assert_eq!(backward(&s32, &saved, &w32), backward(&s32, &bare, &w32));
    }
}

#[test]
fn a_tile_saturated_early_in_a_long_list_matches_the_reference() {
    // One 16 x 16 tile with a list several gather chunks long, opaque enough that every pixel
    // is done far before its end: the forward gathers the list in chunks and stops reading at
    // the last blend; image, n_contrib, kept work list and gradients must be those of the
    // whole list.
    let (w, h) = (16, 16);
    let mut s = random_splats(700, w, h, 41);
    for o in s.opacity.iter_mut() {
        *o = 0.3 + 0.69 * *o;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    let d = Image2d::from_vec(
        w,
        h,
        (0..w * h).map(|_| rng.random_range(-1.0..1.0)).collect(),
    );
    let (img, saved) = forward(&s, w, h, 0.1);
    assert_eq!(img, naive_forward(&s, w, h, 0.1));
    let listed = saved.bins.list(0).len();
    let visited = saved.forward_work.entries as usize;
    println!(
        "list {listed}, visited {visited}, kept {}",
        saved.work.tiles[0].len()
    );
    assert!(
        listed > 4 * 64 && visited + 2 * 64 < listed,
        "{listed} {visited}"
    );
    let mut bare = saved.clone();
    bare.work = WorkLists::default();
    assert_eq!(backward(&s, &saved, &d), backward(&s, &bare, &d));
}

/// Every compiled kernel this CPU can run: (instruction set, 16 lanes?).
fn kernels() -> Vec<Kernel> {
    let mut k = vec![Kernel {
        simd: Simd::Scalar,
        wide: false,
    }];
    if Simd::Avx2.supported() {
        k.push(Kernel {
            simd: Simd::Avx2,
            wide: false,
        });
        k.push(Kernel {
            simd: Simd::Avx2,
            wide: true,
        });
    }
    if Simd::Avx512.supported() {
        k.push(Kernel::of(Simd::Avx512));
    }
    k
}

/// Bits of an image and of splat gradients.
fn bits<R: Real>(img: &Image2d<R>, g: &SplatGrads<R>, saved: &CompositeSaved<R>) -> Vec<u64> {
    let mut v: Vec<u64> = img.data.iter().map(|x| x.f64().to_bits()).collect();
    v.extend(saved.final_t.iter().map(|x| x.f64().to_bits()));
    v.extend(saved.n_contrib.iter().map(|&x| x as u64));
    v.push(saved.blends);
    for (m, c) in g.mean2d.iter().zip(&g.conic) {
        v.extend(m.iter().chain(c).map(|x| x.f64().to_bits()));
    }
    v.extend(g.opacity.iter().chain(&g.color).map(|x| x.f64().to_bits()));
    v
}

fn run_kernel<R: Real>(k: Kernel, s: &Splats<R>, w: usize, h: usize, d: &Image2d<R>) -> Vec<u64> {
    let bg = R::c(0.2);
    let (img, saved) = forward_kernel(k, s, w, h, bg);
    let g = backward_kernel(k, s, &saved, d);
    let mut bare = saved.clone();
    bare.work = WorkLists::default();
    assert_eq!(
        bits(&img, &backward_kernel(k, s, &bare, d), &saved),
        bits(&img, &g, &saved),
        "{k:?}: rebuilt work lists"
    );
    bits(&img, &g, &saved)
}

#[test]
fn every_simd_path_gives_the_same_bits() {
    let paths = kernels();
    println!("kernels run: {paths:?} (of scalar, avx2 x 8/16 lanes, avx512 x 16 lanes)");
    // Sizes with partial tiles at the right and bottom edges, dense and sparse scenes.
    for (n, w, h, seed) in [(400, 64, 48, 21), (900, 53, 37, 22), (60, 37, 29, 23)] {
        let s = random_splats(n, w, h, seed);
        let mut rng = ChaCha8Rng::seed_from_u64(seed + 3);
        let d = Image2d::from_vec(
            w,
            h,
            (0..w * h).map(|_| rng.random_range(-1.0..1.0)).collect(),
        );
        let s32 = to_f32(&s);
        let d32 = Image2d::from_vec(w, h, d.data.iter().map(|&x| x as f32).collect());
        let want64 = run_kernel(paths[0], &s, w, h, &d);
        let want32 = run_kernel(paths[0], &s32, w, h, &d32);
        assert!(want32.iter().any(|&b| b != 0));
        for &k in &paths[1..] {
            assert!(
                run_kernel(k, &s, w, h, &d) == want64,
                "{k:?} f64 n {n} {w}x{h}"
            );
            assert!(
                run_kernel(k, &s32, w, h, &d32) == want32,
                "{k:?} f32 n {n} {w}x{h}"
            );
        }
        // The public entry points with every path (unsupported ones fall back).
        for p in Simd::ALL {
            let (img, saved) = forward_with(p, &s32, w, h, 0.2f32);
            let g = backward_with(p, &s32, &saved, &d32);
            assert!(bits(&img, &g, &saved) == want32, "{p:?}");
        }
    }
}

#[test]
fn probed_passes_report_their_phases_in_order_and_change_no_bit() {
    let (w, h) = (53, 37);
    let s = to_f32(&random_splats(900, w, h, 31));
    let d = Image2d::filled(w, h, 0.3f32);
    let mut seen = Vec::new();
    let (img, saved) = forward_probed(&s, w, h, 0.2f32, &mut |p| seen.push(p));
    let (g, work) = backward_probed(&s, &saved, &d, &mut |p| seen.push(p));
    use Phase::*;
    assert_eq!(
        seen,
        [BinPack, ForwardTiles, Assemble, BackwardTiles, Reduce]
    );
    let (img2, saved2) = forward(&s, w, h, 0.2f32);
    let g2 = backward(&s, &saved2, &d);
    assert!(bits(&img, &g, &saved) == bits(&img2, &g2, &saved2));
    // The work counters: every blend is an evaluated lane of the forward, lanes come in whole
    // vectors of 8 or 16, each row the forward visits holds at least one vector, and the
    // backward visits exactly the entries the forward kept.
    let fw = saved.forward_work;
    println!("forward {fw:?}, backward {work:?}, blends {}", saved.blends);
    assert!(saved.blends > 0 && fw.lanes >= saved.blends);
    assert!(fw.lanes % 8 == 0 && work.lanes % 8 == 0);
    assert!(fw.lanes >= 8 * fw.rows && fw.rows > 0);
    assert!(work.lanes > 0 && work.rows > 0);
    let kept: usize = saved.work.tiles.iter().map(|t| t.len()).sum();
    assert_eq!(work.entries, kept as u64);
    assert!(work.entries <= fw.entries);
}
