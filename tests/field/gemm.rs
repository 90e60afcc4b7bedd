//! The blocked matrix products of the field MLP (`field::gemm`): against an f64 reference and
//! against plain f32 loops with the documented operation order (same bits), on random shapes
//! with edges smaller than the register tiles; every SIMD path gives the same bits; a few
//! training iterations (loss, gradient, Adam) give the same bits for 1, 2 and 8 threads, every
//! SIMD path, and a workspace reused across batches of different sizes.

use crate::common::panic_text;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use unispine::field::gemm;
use unispine::field::render::{self, Ray};
use unispine::field::train::{loss_and_grad, Sampling, Workspace};
use unispine::field::{Field, FieldConfig};
use unispine::optim::FlatAdam;
use unispine::simd::Simd;

/// Shapes `(rows, inner, cols)`: tile multiples, ragged edges below every tile size, the MLP's.
const SHAPES: [(usize, usize, usize); 19] = [
    (1, 1, 1),
    (3, 5, 7),
    (7, 16, 15),
    (9, 17, 33),
    (13, 32, 32),
    (64, 48, 32),
    (65, 33, 17),
    (100, 63, 256),
    (97, 256, 63),
    (200, 32, 1),
    (11, 1, 40),
    (130, 319, 47),
    // Larger than a row block (96) and an inner block (128), remainder panels of every width
    // class, and one or a few output columns (`dW` with rows in the vector lanes: 64, 16 and
    // single-row remainders).
    (300, 300, 20),
    (97, 129, 50),
    (1030, 40, 1),
    (200, 70, 1),
    (150, 85, 5),
    (129, 256, 1),
    (40, 3, 300),
];

fn rand_vec(rng: &mut ChaCha8Rng, n: usize) -> Vec<f32> {
    (0..n).map(|_| rng.random_range(-1.0f32..1.0)).collect()
}

/// The three products in f64 (reference) and as plain f32 loops in the documented order.
struct Products<T> {
    z: Vec<T>,
    dx: Vec<T>,
    gw: Vec<T>,
    gb: Vec<T>,
}

#[allow(clippy::too_many_arguments)]
fn plain_f32(
    x: &[f32],
    w: &[f32],
    b: &[f32],
    g: &[f32],
    gw0: &[f32],
    n: usize,
    k: usize,
    m: usize,
) -> Products<f32> {
    // Forward: z[r][o] = b[o], then + x[r][k] w[k][o] for k in order.
    let mut z = vec![0.0f32; n * m];
    for r in 0..n {
        for o in 0..m {
            let mut acc = b[o];
            for t in 0..k {
                acc += x[r * k + t] * w[t * m + o];
            }
            z[r * m + o] = acc;
        }
    }
    // dX (g is n x m): dx[r][t] = 0, then + g[r][o] w[t][o] for o in order.
    let mut dx = vec![0.0f32; n * k];
    for r in 0..n {
        for t in 0..k {
            let mut acc = 0.0f32;
            for o in 0..m {
                acc += g[r * m + o] * w[t * m + o];
            }
            dx[r * k + t] = acc;
        }
    }
    // dW, db: start from the given values, + x[r][t] g[r][o] for r in order.
    let mut gw = gw0.to_vec();
    let mut gb = vec![0.0f32; m];
    for t in 0..k {
        for o in 0..m {
            let mut acc = gw[t * m + o];
            for r in 0..n {
                acc += x[r * k + t] * g[r * m + o];
            }
            gw[t * m + o] = acc;
        }
    }
    for o in 0..m {
        let mut acc = 0.0f32;
        for r in 0..n {
            acc += g[r * m + o];
        }
        gb[o] = acc;
    }
    Products { z, dx, gw, gb }
}

#[allow(clippy::too_many_arguments)]
fn fast(
    simd: Simd,
    x: &[f32],
    w: &[f32],
    b: &[f32],
    g: &[f32],
    gw0: &[f32],
    n: usize,
    k: usize,
    m: usize,
) -> Products<f32> {
    let mut z = vec![f32::NAN; n * m];
    gemm::forward(simd, x, w, b, n, k, m, &mut z);
    let mut wt = vec![0.0f32; k * m];
    gemm::transpose(w, k, m, &mut wt);
    let mut dx = vec![f32::NAN; n * k];
    gemm::grad_input(simd, g, &wt, n, k, m, &mut dx);
    let mut gw = gw0.to_vec();
    let mut gb = vec![0.0f32; m];
    gemm::grad_weight(simd, x, g, n, k, m, &mut gw, &mut gb);
    Products { z, dx, gw, gb }
}

fn bits(p: &Products<f32>) -> Vec<u32> {
    [&p.z, &p.dx, &p.gw, &p.gb]
        .iter()
        .flat_map(|v| v.iter().map(|x| x.to_bits()))
        .collect()
}

#[test]
fn gemm_matches_f64_reference_and_plain_loops_bit_for_bit() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for &(n, k, m) in &SHAPES {
        let x = rand_vec(&mut rng, n * k);
        let w = rand_vec(&mut rng, k * m);
        let b = rand_vec(&mut rng, m);
        let g = rand_vec(&mut rng, n * m);
        let gw0 = rand_vec(&mut rng, k * m);
        // f64 reference (independent of any order) with an error bound per element:
        // |f32 - exact| <= (terms) * eps * sum |products| (sequential summation bound).
        let eps = f32::EPSILON as f64;
        let check = |name: &str, got: &[f32], want: &[f64], mag: &[f64], terms: usize| {
            for i in 0..got.len() {
                let tol = (terms as f64 + 2.0) * eps * mag[i] + 1e-30;
                assert!(
                    (got[i] as f64 - want[i]).abs() <= tol,
                    "{name} ({n},{k},{m}) [{i}]: {} vs {} (tol {tol:e})",
                    got[i],
                    want[i]
                );
            }
        };
        let d = |v: f32| v as f64;
        let (mut z, mut zm) = (vec![0.0; n * m], vec![0.0; n * m]);
        for r in 0..n {
            for o in 0..m {
                z[r * m + o] = d(b[o]);
                zm[r * m + o] = d(b[o]).abs();
                for t in 0..k {
                    z[r * m + o] += d(x[r * k + t]) * d(w[t * m + o]);
                    zm[r * m + o] += (d(x[r * k + t]) * d(w[t * m + o])).abs();
                }
            }
        }
        let (mut dx, mut dxm) = (vec![0.0; n * k], vec![0.0; n * k]);
        for r in 0..n {
            for t in 0..k {
                for o in 0..m {
                    dx[r * k + t] += d(g[r * m + o]) * d(w[t * m + o]);
                    dxm[r * k + t] += (d(g[r * m + o]) * d(w[t * m + o])).abs();
                }
            }
        }
        let (mut gw, mut gwm) = (vec![0.0; k * m], vec![0.0; k * m]);
        for t in 0..k {
            for o in 0..m {
                gw[t * m + o] = d(gw0[t * m + o]);
                gwm[t * m + o] = d(gw0[t * m + o]).abs();
                for r in 0..n {
                    gw[t * m + o] += d(x[r * k + t]) * d(g[r * m + o]);
                    gwm[t * m + o] += (d(x[r * k + t]) * d(g[r * m + o])).abs();
                }
            }
        }
        let plain = plain_f32(&x, &w, &b, &g, &gw0, n, k, m);
        for simd in Simd::supported_paths() {
            let f = fast(simd, &x, &w, &b, &g, &gw0, n, k, m);
            check("forward", &f.z, &z, &zm, k);
            check("grad_input", &f.dx, &dx, &dxm, m);
            check("grad_weight", &f.gw, &gw, &gwm, n);
            assert_eq!(
                bits(&f),
                bits(&plain),
                "{simd:?} ({n},{k},{m}): not the bits of the plain loops"
            );
        }
        // The f64 path (gradient checks) against the same reference.
        let (x64, w64, b64, g64): (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>) = (
            x.iter().map(|&v| d(v)).collect(),
            w.iter().map(|&v| d(v)).collect(),
            b.iter().map(|&v| d(v)).collect(),
            g.iter().map(|&v| d(v)).collect(),
        );
        let mut z64 = vec![0.0; n * m];
        gemm::forward(Simd::active(), &x64, &w64, &b64, n, k, m, &mut z64);
        for i in 0..n * m {
            assert!((z64[i] - z[i]).abs() <= 1e-12 * (1.0 + zm[i]));
        }
        let mut wt64 = vec![0.0; k * m];
        gemm::transpose(&w64, k, m, &mut wt64);
        let mut dx64 = vec![0.0; n * k];
        gemm::grad_input(Simd::active(), &g64, &wt64, n, k, m, &mut dx64);
        for i in 0..n * k {
            assert!((dx64[i] - dx[i]).abs() <= 1e-12 * (1.0 + dxm[i]));
        }
    }
}

fn naf_like() -> FieldConfig {
    let mut cfg = FieldConfig::preset("naf", 4).unwrap();
    cfg.encoder = unispine::field::EncoderConfig::HashGrid {
        levels: 4,
        features: 2,
        table_size: 1 << 10,
        base_resolution: 4,
    };
    cfg.n_samples = 24;
    cfg
}

fn batch(it: usize, n_rays: usize) -> (Vec<Ray>, Vec<f32>) {
    let mut rng = ChaCha8Rng::seed_from_u64(100 + it as u64);
    let rays = (0..n_rays)
        .map(|_| Ray {
            o: [1.0, 0.0, 0.0],
            d: [
                -1.0,
                rng.random_range(-0.12..0.12),
                rng.random_range(-0.12..0.12),
            ],
        })
        .collect();
    let t = (0..n_rays).map(|_| rng.random_range(0.0..0.05)).collect();
    (rays, t)
}

/// Parameter bits after `iters` iterations of loss, gradient and Adam (ray counts vary, one
/// batch ragged against the block size), with one reused workspace.
fn train_bits(cfg: &FieldConfig, simd: Simd, iters: usize) -> Vec<u32> {
    let mut f = Field::<f32>::new(cfg).unwrap();
    let mut adam = FlatAdam::<f32>::new(f.params.len());
    let mut ws = Workspace::<f32>::default();
    for it in 0..iters {
        let (rays, t) = batch(it, [37, 64, 13][it % 3]);
        let jitter = |i: usize| render::ray_rng(0, 2, it as u64, i as u64);
        let loss = ws.loss_and_grad(
            simd,
            &f,
            &rays,
            &t,
            &Sampling::new((0.7, 1.3), cfg.n_samples, 0.3, &jitter),
        );
        assert!(loss.is_finite() && loss > 0.0);
        // A fresh workspace gives the same gradient as the reused one.
        if simd == Simd::active() {
            let (l2, g2) = loss_and_grad(
                &f,
                &rays,
                &t,
                &Sampling::new((0.7, 1.3), cfg.n_samples, 0.3, &jitter),
            );
            assert_eq!(loss.to_bits(), l2.to_bits());
            assert!(ws
                .grad
                .iter()
                .zip(&g2)
                .all(|(a, b)| a.to_bits() == b.to_bits()));
        }
        adam.update(&mut f.params, &ws.grad, 1e-2);
    }
    f.params.iter().map(|v| v.to_bits()).collect()
}

#[test]
fn training_iterations_are_bit_identical_for_threads_and_simd_paths() {
    for cfg in [
        naf_like(),
        {
            let mut c = FieldConfig::preset("intratomo", 4).unwrap();
            c.hidden_dim = 40; // ragged against every tile width
            c.n_samples = 16;
            c
        },
        {
            // TensoRF: the basis and its gradients run the blocked products (out_dim 20 and
            // 3 x 5 features: ragged against every tile width).
            let mut c = FieldConfig::preset("tensorf", 4).unwrap();
            c.encoder = unispine::field::EncoderConfig::TensorVm {
                resolution: 12,
                components: 5,
                out_dim: 20,
                lines: unispine::field::encode::VmLines::Corrected,
            };
            c.hidden_dim = 24;
            c.n_samples = 16;
            c
        },
    ] {
        let mut runs = Vec::new();
        for threads in [1, 2, 8] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            for simd in Simd::supported_paths() {
                runs.push((threads, simd, pool.install(|| train_bits(&cfg, simd, 4))));
            }
        }
        let init: Vec<u32> = Field::<f32>::new(&cfg)
            .unwrap()
            .params
            .iter()
            .map(|v| v.to_bits())
            .collect();
        assert_ne!(runs[0].2, init, "training changed nothing");
        for (t, s, b) in &runs[1..] {
            assert!(b == &runs[0].2, "{t} threads, {s:?}: bits differ");
        }
    }
}

/// The element-wise passes between the products (LeakyReLU forward / backward over row-strided
/// blocks, column sums of `db`): every SIMD path gives the bits of the plain loops, including
/// negative values, zeros and widths that are not a multiple of any vector width.
#[test]
fn elementwise_passes_match_plain_loops_on_every_path() {
    use unispine::field::act::{self, Rows};
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    for &(n, w, ld, off) in &[
        (1, 1, 1, 0),
        (7, 5, 9, 3),
        (33, 32, 48, 16),
        (100, 39, 295, 256),
    ] {
        let mut d = rand_vec(&mut rng, off + n * ld);
        d[off] = 0.0;
        let mut z = rand_vec(&mut rng, n * w);
        z[0] = 0.0;
        // A zero input where the upstream value is not zero: LeakyReLU takes the slope at 0
        // (PyTorch: `x > 0 ? g : g * slope`).
        z[n * w - 1] = 0.0;
        assert!(n * w == 1 || d[off + (n - 1) * ld + w - 1] != 0.0);
        let slope = 0.01f32;
        let mut want = vec![f32::NAN; n * w];
        for r in 0..n {
            for k in 0..w {
                let dv = d[off + r * ld + k];
                want[r * w + k] = if z[r * w + k] > 0.0 { dv } else { dv * slope };
            }
        }
        let mut want_sum = rand_vec(&mut rng, w);
        let acc0 = want_sum.clone();
        for r in 0..n {
            for k in 0..w {
                want_sum[k] += z[r * w + k];
            }
        }
        for simd in Simd::supported_paths() {
            let mut got = vec![f32::NAN; n * w];
            let src = Rows { ld, off };
            let dense = Rows { ld: w, off: 0 };
            act::leaky(simd, &d, src, &z, n, w, slope, &mut got, dense);
            let b = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(b(&got), b(&want), "leaky {simd:?} ({n},{w},{ld},{off})");
            let mut sum = acc0.clone();
            act::sum_rows(simd, &z, n, w, &mut sum);
            assert_eq!(b(&sum), b(&want_sum), "sum_rows {simd:?} ({n},{w})");
        }
    }
}

/// An empty block (no rows, or rows of no values) is nothing to do on every path, whatever the
/// row stride: no bound is computed from `n - 1` rows when there is none.
#[test]
fn elementwise_passes_on_an_empty_block_do_nothing() {
    use unispine::field::act::{self, Rows};
    for simd in Simd::supported_paths() {
        for (n, w) in [(0, 3), (4, 0), (0, 0)] {
            let mut out = vec![7.0f32; 2];
            let src = Rows { ld: 5, off: 0 };
            let dst = Rows { ld: 4, off: 0 };
            act::leaky(simd, &[], src, &[], n, w, 0.01, &mut out, dst);
            assert_eq!(out, vec![7.0; 2], "{simd:?} n {n} w {w}");
        }
    }
}

/// A layer with no inputs (inner dimension 0): every output row is the bias, on every path
/// and for f32 (the blocked kernel) and f64.
#[test]
fn a_product_with_no_inner_dimension_is_the_bias_per_row() {
    let (n, out) = (5, 3);
    let b = [0.5f32, -1.25, 2.0];
    for simd in Simd::supported_paths() {
        let mut z = vec![f32::NAN; n * out];
        gemm::forward(simd, &[], &[], &b, n, 0, out, &mut z);
        let want: Vec<f32> = (0..n).flat_map(|_| b).collect();
        assert_eq!(z, want, "{simd:?}");
        let b64 = b.map(f64::from);
        let mut z = vec![f64::NAN; n * out];
        gemm::forward(simd, &[], &[], &b64, n, 0, out, &mut z);
        let want: Vec<f64> = (0..n).flat_map(|_| b64).collect();
        assert_eq!(z, want, "{simd:?} f64");
    }
}

/// An empty batch (no rows) or a layer with no outputs touches nothing; an operand one value
/// too short for its shape is refused, naming it, before anything is written.
#[test]
fn empty_products_do_nothing_and_short_operands_are_refused() {
    let (n, inp, out) = (3, 4, 5);
    let x = vec![0.5f32; n * inp];
    let w = vec![0.25f32; inp * out];
    let b = vec![1.0f32; out];
    for simd in Simd::supported_paths() {
        let mut z = vec![7.0f32; n * out];
        gemm::forward(simd, &x, &w, &b, 0, inp, out, &mut z);
        gemm::forward(simd, &x, &w, &b, n, inp, 0, &mut z);
        assert!(z.iter().all(|&v| v == 7.0), "{simd:?}");
        let short = |x: &[f32], w: &[f32], b: &[f32], zl: usize| {
            let (x, w, b) = (x.to_vec(), w.to_vec(), b.to_vec());
            panic_text(move || {
                let mut z = vec![7.0f32; zl];
                gemm::forward(simd, &x, &w, &b, n, inp, out, &mut z);
            })
        };
        let m = n * inp - 1;
        assert!(
            short(&x[..m], &w, &b, n * out).is_some_and(|t| t.contains("A too short")),
            "{simd:?}"
        );
        let m = inp * out - 1;
        assert!(
            short(&x, &w[..m], &b, n * out).is_some_and(|t| t.contains("B too short")),
            "{simd:?}"
        );
        assert!(
            short(&x, &w, &b, n * out - 1).is_some_and(|t| t.contains("C too short")),
            "{simd:?}"
        );
        assert!(
            short(&x, &w, &b[..out - 1], n * out).is_some_and(|t| t.contains("bias too short")),
            "{simd:?}"
        );
        assert_eq!(
            short(&x, &w, &b, n * out),
            None,
            "{simd:?}: the exact sizes pass"
        );
        // dW = X^T dY reads X column by column (a column-major A): one value short is refused.
        let g = vec![0.5f32; n * out];
        // (length of X, whether it panics naming A)
        for (xl, want) in [(n * inp - 1, Some(true)), (n * inp, None)] {
            let (xs, g) = (x[..xl].to_vec(), g.clone());
            let text = panic_text(move || {
                let (mut gw, mut gb) = (vec![0.0f32; inp * out], vec![0.0f32; out]);
                gemm::grad_weight(simd, &xs, &g, n, inp, out, &mut gw, &mut gb);
            });
            let refused = text.as_deref().map(|t| t.contains("A too short"));
            assert_eq!(refused, want, "{simd:?}: {text:?}");
        }
    }
    assert_eq!(gemm::flops(3, 5, 7), 210);
}
