//! Gradient checks of the neural-field stages ([`crate::field`]) against 5-point central finite
//! differences in f64 ([`crate::math::fd`]), as [`Row`]s:
//! - `field-encoder`: each encoder ([`encoder_cases`]: frequency, hash grid, TensoRF VM with
//!   the upstream and the corrected line factor, dense grid), `L = sum_n g_n . encode(x_n)` for
//!   fixed random `g`, with respect to every parameter group and to the points;
//! - `field-mlp`: the MLP with two skip layers, each output activation (LeakyReLU, sigmoid,
//!   softplus), `L = sum_n c_n mlp(x_n)`, with respect to the parameters and the inputs;
//! - `field-render`: the line integral `acc = sum_i mu_i delta_i`, `L = sum_r c_r acc_r`, with
//!   respect to `mu`;
//! - `field-loss`: the training loss (rays, stratified samples, encoder, MLP, line integral,
//!   MSE) of [`crate::field::train::loss_and_grad`] with each encoder, with respect to the
//!   encoder's and the MLP's parameters.
//!
//! Steps: 1e-5 for parameters (the grid encoders are linear in their parameters, the MLP is
//! smooth away from LeakyReLU's kink), 1e-6 m for points. The points keep at least
//! [`CELL_MARGIN`] of a cell away from every cell face of every grid (asserted by
//! [`cell_margin`] in `tests/field/encoders.rs`), so no stencil crosses a face.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::audit::Row;
use crate::field::encode::{DenseGrid, Encoder, Frequency, GridMap, HashGrid, TensorVm, VmLines};
use crate::field::mlp::{Mlp, OutAct};
use crate::field::render::{self, Ray};
use crate::field::train::{loss_and_grad, Sampling};
use crate::field::{EncoderConfig, Field, FieldConfig};
use crate::math::fd;
use crate::simd::Simd;

/// Half side of the test cube (metres), as the presets.
pub const BOUND: f64 = 0.3;
/// Parameter step.
pub const H_PARAM: f64 = 1e-5;
/// Point step (metres).
pub const H_POINT: f64 = 1e-6;
/// Smallest distance of a test point from a cell face, in cells.
pub const CELL_MARGIN: f64 = 1e-3;

/// The encoders checked: (case, variant, encoder).
pub fn encoder_cases() -> Vec<(&'static str, &'static str, Encoder)> {
    let vm = |lines| TensorVm {
        resolution: 6,
        components: 2,
        out_dim: 4,
        bound: BOUND,
        lines,
    };
    vec![
        (
            "frequency",
            "3 bands",
            Encoder::Frequency(Frequency { bands: 3 }),
        ),
        (
            "hash-grid",
            "3 levels, T 64",
            // R = 2, 4, 8: level 0 dense (27 entries), levels 1-2 hashed.
            Encoder::HashGrid(HashGrid::new(3, 2, 6, 2, BOUND)),
        ),
        (
            "tensorf-vm",
            "upstream lines",
            Encoder::TensorVm(vm(VmLines::Upstream)),
        ),
        (
            "tensorf-vm",
            "corrected lines",
            Encoder::TensorVm(vm(VmLines::Corrected)),
        ),
        (
            "dense-grid",
            "align-corners",
            Encoder::DenseGrid(DenseGrid {
                resolution: 5,
                features: 2,
                bound: BOUND,
                map: GridMap::AlignCorners,
            }),
        ),
    ]
}

/// Uniform numbers in `[lo, hi)`, seeded.
pub fn uniform(n: usize, lo: f64, hi: f64, seed: u64) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n).map(|_| rng.random_range(lo..hi)).collect()
}

/// `n` test points inside the cube (`|x| <= 0.27 m`), each at least [`CELL_MARGIN`] cells
/// from every cell face of [`grid_spacings`] (drawn again when not).
pub fn points(n: usize, seed: u64) -> Vec<[f64; 3]> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        let p: [f64; 3] = std::array::from_fn(|_| rng.random_range(-0.27..0.27));
        if cell_margin(&[p]) >= 2.0 * CELL_MARGIN {
            out.push(p);
        }
    }
    out
}

/// Every (vertices per axis, mapping) of the grids of [`encoder_cases`] and of the
/// `field-loss` encoders.
pub fn grid_spacings() -> Vec<(usize, GridMap)> {
    let v = vec![
        (3, GridMap::Ngp),
        (5, GridMap::Ngp),
        (9, GridMap::Ngp),
        (5, GridMap::AlignCorners),
        (6, GridMap::AlignCorners),
    ];
    // The VM's upstream line reads sit at column (N - 1) / 2: constant, no face to cross.
    v
}

/// Smallest distance (in cells) of any coordinate of `pts` from a cell face of the grids of
/// [`grid_spacings`].
pub fn cell_margin(pts: &[[f64; 3]]) -> f64 {
    let mut m = f64::INFINITY;
    for &(n, map) in &grid_spacings() {
        let g = DenseGrid {
            resolution: n,
            features: 1,
            bound: BOUND,
            map,
        };
        for p in pts {
            for &x in p {
                let (pos, _) = g.pos(x);
                let f = pos - pos.floor();
                m = m.min(f).min(1.0 - f);
            }
        }
    }
    m
}

/// Random parameters of an encoder (U(-0.5, 0.5), so every group matters).
pub fn encoder_params(e: &Encoder, seed: u64) -> Vec<f64> {
    uniform(e.n_params(), -0.5, 0.5, seed)
}

/// Named parameter groups of an encoder: (name, range in the parameter vector).
pub fn groups(e: &Encoder) -> Vec<(&'static str, std::ops::Range<usize>)> {
    match e {
        Encoder::Frequency(_) => vec![],
        Encoder::HashGrid(h) => vec![("table", 0..h.n_params())],
        Encoder::DenseGrid(d) => vec![("table", 0..d.n_params())],
        // Upstream's line parameters are never read: no group to check (their gradient is
        // exactly zero, `tests/field/encoders.rs`).
        Encoder::TensorVm(v) if v.lines == VmLines::Upstream => {
            let (l, b) = v.offsets();
            vec![("planes", 0..l), ("basis", b..v.n_params())]
        }
        Encoder::TensorVm(v) => {
            let (l, b) = v.offsets();
            vec![
                ("planes", 0..l),
                ("lines", l..b),
                ("basis", b..v.n_params()),
            ]
        }
    }
}

fn row(
    stage: &'static str,
    case: &str,
    variant: &str,
    group: &'static str,
    an: &[f64],
    num: &[f64],
) -> Row {
    Row {
        stage,
        case: case.to_string(),
        variant: variant.to_string(),
        group,
        scale: num.iter().map(|x| x.abs()).fold(0.0, f64::max),
        max_abs: an
            .iter()
            .zip(num)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max),
        rel: fd::rel_err_maxabs(an, num),
    }
}

/// `sum_n g_n . encode(x_n)`.
fn encoder_loss(e: &Encoder, p: &[f64], pts: &[[f64; 3]], g: &[f64]) -> f64 {
    let od = e.out_dim();
    let mut o = vec![0.0; od];
    let mut s = 0.0;
    for (n, x) in pts.iter().enumerate() {
        e.encode(p, *x, &mut o);
        for k in 0..od {
            s += g[n * od + k] * o[k];
        }
    }
    s
}

/// The `field-encoder` rows.
pub fn encoder_rows() -> Vec<Row> {
    let mut out = Vec::new();
    for (ci, (case, variant, e)) in encoder_cases().into_iter().enumerate() {
        let p = encoder_params(&e, 100 + ci as u64);
        let pts = points(7, 200 + ci as u64);
        let g = uniform(pts.len() * e.out_dim(), -1.0, 1.0, 300 + ci as u64);
        let mut an = vec![0.0; e.n_params()];
        e.backward(Simd::active(), &p, &pts, &g, e.out_dim(), 0, &mut an);
        for (name, r) in groups(&e) {
            let num = fd::central_diff5(
                |v| {
                    let mut q = p.clone();
                    q[r.clone()].copy_from_slice(v);
                    encoder_loss(&e, &q, &pts, &g)
                },
                &p[r.clone()],
                H_PARAM,
            );
            out.push(row("field-encoder", case, variant, name, &an[r], &num));
        }
        let od = e.out_dim();
        let an_x: Vec<f64> = pts
            .iter()
            .enumerate()
            .flat_map(|(n, x)| e.input_vjp(&p, *x, &g[n * od..(n + 1) * od]))
            .collect();
        let flat: Vec<f64> = pts.concat();
        let num = fd::central_diff5(
            |v| {
                let q: Vec<[f64; 3]> = v.chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
                encoder_loss(&e, &p, &q, &g)
            },
            &flat,
            H_POINT,
        );
        out.push(row("field-encoder", case, variant, "points", &an_x, &num));
    }
    out
}

/// The MLP of the `field-mlp` rows: 5 inputs, 6 hidden, 5 layers, skips at 2 and 3.
pub fn test_mlp(act: OutAct) -> Mlp {
    Mlp::new(5, 6, 5, &[2, 3], act).expect("valid MLP")
}

/// The `field-mlp` rows.
pub fn mlp_rows() -> Vec<Row> {
    let mut out = Vec::new();
    for (k, act) in [OutAct::LeakyRelu, OutAct::Sigmoid, OutAct::Softplus]
        .into_iter()
        .enumerate()
    {
        let m = test_mlp(act);
        let n = 9;
        let p: Vec<f64> = m.init(7 + k as u64);
        let x = uniform(n * m.in_dim, -1.0, 1.0, 40 + k as u64);
        let c = uniform(n, -1.0, 1.0, 50 + k as u64);
        let loss = |p: &[f64], x: &[f64]| -> f64 {
            let (y, _) = m.forward(p, x, n, false);
            y.iter().zip(&c).map(|(a, b)| a * b).sum()
        };
        let (_, cache) = m.forward(&p, &x, n, true);
        let mut gp = vec![0.0; m.n_params];
        let mut gx = vec![0.0; x.len()];
        m.backward(&p, &cache, &c, n, &mut gp, Some(&mut gx));
        let variant = format!("{act:?} skip 2,3").to_lowercase();
        let np = fd::central_diff5(|v| loss(v, &x), &p, H_PARAM);
        out.push(row("field-mlp", "5x6x5", &variant, "params", &gp, &np));
        let nx = fd::central_diff5(|v| loss(&p, v), &x, H_PARAM);
        out.push(row("field-mlp", "5x6x5", &variant, "inputs", &gx, &nx));
    }
    out
}

/// The `field-render` row.
pub fn render_rows() -> Vec<Row> {
    let (rays, n) = (4, 6);
    let mu = uniform(rays * n, 0.0, 1.0, 60);
    let delta = uniform(rays * n, 0.01, 0.1, 61);
    let c = uniform(rays, -1.0, 1.0, 62);
    let loss = |mu: &[f64]| -> f64 {
        (0..rays)
            .map(|r| c[r] * render::line_integral(&mu[r * n..][..n], &delta[r * n..][..n]))
            .sum()
    };
    let mut an = vec![0.0; mu.len()];
    for r in 0..rays {
        render::line_integral_vjp(c[r], &delta[r * n..][..n], &mut an[r * n..][..n]);
    }
    let num = fd::central_diff5(loss, &mu, H_PARAM);
    vec![row(
        "field-render",
        "4 rays x 6",
        "line integral",
        "mu",
        &an,
        &num,
    )]
}

/// The encoders of the `field-loss` rows (settings as [`encoder_cases`]).
pub fn loss_encoders() -> Vec<(&'static str, &'static str, EncoderConfig)> {
    let vm = |lines| EncoderConfig::TensorVm {
        resolution: 6,
        components: 2,
        out_dim: 4,
        lines,
    };
    vec![
        (
            "frequency",
            "2 bands",
            EncoderConfig::Frequency { bands: 2 },
        ),
        (
            "hash-grid",
            "3 levels, T 64",
            EncoderConfig::HashGrid {
                levels: 3,
                features: 2,
                table_size: 64,
                base_resolution: 2,
            },
        ),
        ("tensorf-vm", "upstream lines", vm(VmLines::Upstream)),
        ("tensorf-vm", "corrected lines", vm(VmLines::Corrected)),
        (
            "dense-grid",
            "align-corners",
            EncoderConfig::DenseGrid {
                resolution: 5,
                features: 2,
            },
        ),
    ]
}

/// A small f64 field with encoder `enc` (hidden 8, 4 layers, skip 2, 6 samples per ray) and
/// encoder parameters U(-0.15, 0.15) (U(-0.6, 0.6) for the VM, whose features are products of
/// two reads) so that the encoder matters.
pub fn small_field(enc: EncoderConfig, act: OutAct, seed: u64) -> (FieldConfig, Field<f64>) {
    let a = if matches!(enc, EncoderConfig::TensorVm { .. }) {
        0.6
    } else {
        0.15
    };
    let mut c = FieldConfig::preset("naf", 10).expect("preset");
    c.encoder = enc;
    c.hidden_dim = 8;
    c.num_layers = 4;
    c.skips = vec![2];
    c.n_samples = 6;
    c.last_activation = act;
    let mut f = Field::<f64>::new(&c).expect("valid field");
    let ne = f.n_encoder_params();
    f.params[..ne].copy_from_slice(&uniform(ne, -a, a, seed));
    (c, f)
}

/// Rays through the cube from a source 1 m away (metres, unnormalised directions).
pub fn test_rays(n: usize) -> Vec<Ray> {
    (0..n)
        .map(|i| Ray {
            o: [1.0, 0.0, 0.0],
            d: [-1.0, -0.1 + 0.05 * i as f64, 0.02 * i as f64 - 0.03],
        })
        .collect()
}

/// The seeded jitter of the `field-loss` rows.
pub fn test_jitter(i: usize) -> ChaCha8Rng {
    render::ray_rng(3, 9, 1, i as u64)
}

/// The `field-loss` rows (sigmoid output).
pub fn loss_rows() -> Vec<Row> {
    let mut out = Vec::new();
    for (k, (case, variant, enc)) in loss_encoders().into_iter().enumerate() {
        let (cfg, f) = small_field(enc, OutAct::Sigmoid, 70 + k as u64);
        let rays = test_rays(5);
        let targets: Vec<f64> = (0..rays.len()).map(|i| 0.05 + 0.02 * i as f64).collect();
        let nf = (0.7, 1.3);
        let loss = |p: &[f64]| {
            let mut g = f.clone();
            g.params.copy_from_slice(p);
            loss_and_grad(
                &g,
                &rays,
                &targets,
                &Sampling::new(nf, cfg.n_samples, BOUND, &test_jitter),
            )
            .0
        };
        let (_, an) = loss_and_grad(
            &f,
            &rays,
            &targets,
            &Sampling::new(nf, cfg.n_samples, BOUND, &test_jitter),
        );
        let ne = f.n_encoder_params();
        let mut parts: Vec<(&'static str, std::ops::Range<usize>)> = vec![];
        if ne > 0 {
            parts.push(("encoder", 0..ne));
        }
        parts.push(("mlp", ne..f.params.len()));
        for (name, r) in parts {
            let num = fd::central_diff5(
                |v| {
                    let mut q = f.params.clone();
                    q[r.clone()].copy_from_slice(v);
                    loss(&q)
                },
                &f.params[r.clone()],
                H_PARAM,
            );
            out.push(row("field-loss", case, variant, name, &an[r], &num));
        }
    }
    out
}

/// Every row of the neural-field stages.
pub fn rows() -> Vec<Row> {
    let mut v = encoder_rows();
    v.extend(mlp_rows());
    v.extend(render_rows());
    v.extend(loss_rows());
    v
}
