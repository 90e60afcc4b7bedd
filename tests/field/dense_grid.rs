//! The dense grid at and beyond its edges, against trilinear interpolation written as a sum of
//! hat functions over every vertex: vertex `v` weighs `prod_d max(0, 1 - |pos_d - v_d|)`, so a
//! vertex off the grid never enters (PyTorch's zero padding) and a point far outside reads 0.
//! The positions follow the two mappings of the module doc, restated here: torch-ngp's
//! `pos = (x + b) / (2 b) (n - 2) + 1/2` and `grid_sample(align_corners=True)`'s
//! `pos = (x / b + 1) / 2 (n - 1)`.

use unispine::field::encode::{DenseGrid, Encoder, GridMap};
use unispine::simd::Simd;

fn table(n: usize, seed: u64) -> Vec<f64> {
    crate::encoders::rand_vec(n, seed)
}

fn pos(d: &DenseGrid, x: f64) -> f64 {
    let (b, n) = (d.bound, d.resolution as f64);
    match d.map {
        GridMap::Ngp => (x + b) / (2.0 * b) * (n - 2.0) + 0.5,
        GridMap::AlignCorners => (x / b + 1.0) / 2.0 * (n - 1.0),
    }
}

/// The hat-function weight of every vertex (x fastest) for point `x`.
fn hat_weights(d: &DenseGrid, x: [f64; 3]) -> Vec<f64> {
    let n = d.resolution;
    let p = x.map(|c| pos(d, c));
    let hat = |v: usize, p: f64| (1.0 - (p - v as f64).abs()).max(0.0);
    let mut w = vec![0.0; n * n * n];
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                w[i + n * (j + n * k)] = hat(i, p[0]) * hat(j, p[1]) * hat(k, p[2]);
            }
        }
    }
    w
}

/// The coordinate whose position is `p` (the inverse of [`pos`]).
fn coord(d: &DenseGrid, p: f64) -> f64 {
    let (b, n) = (d.bound, d.resolution as f64);
    match d.map {
        GridMap::Ngp => (p - 0.5) / (n - 2.0) * (2.0 * b) - b,
        GridMap::AlignCorners => (p / (n - 1.0) * 2.0 - 1.0) * b,
    }
}

/// Points whose corners leave the grid on each side of each axis (positions -0.6 and
/// n - 0.4), points just inside (0.3, n - 1.3), one far outside (n + 3), and two too far to
/// place (coordinates of +-1e30).
fn edge_points(d: &DenseGrid) -> Vec<[f64; 3]> {
    let n = d.resolution as f64;
    let mut pts = vec![[0.01, -0.02, 0.03]];
    for axis in 0..3 {
        let at = [-0.6, 0.3, n - 1.3, n - 0.4, n + 3.0].map(|p| coord(d, p));
        for x in at.into_iter().chain([1e30, -1e30]) {
            let mut p = [0.3, -0.2, 0.1].map(|c| c * d.bound);
            p[axis] = x;
            pts.push(p);
        }
    }
    pts
}

#[test]
fn a_dense_grid_at_and_beyond_its_edges_is_the_sum_of_its_vertex_hats() {
    for map in [GridMap::Ngp, GridMap::AlignCorners] {
        let d = DenseGrid {
            resolution: 5,
            features: 2,
            bound: 0.4,
            map,
        };
        let t = table(d.n_params(), 31);
        let e = Encoder::DenseGrid(d.clone());
        let pts = edge_points(&d);
        let mut touched = [false; 3];
        for (m, &x) in pts.iter().enumerate() {
            let w = hat_weights(&d, x);
            let mut got = [f64::NAN; 2];
            e.encode(&t, x, &mut got);
            for ch in 0..2 {
                let want: f64 = w.iter().enumerate().map(|(v, wv)| wv * t[2 * v + ch]).sum();
                assert!(
                    (got[ch] - want).abs() <= 1e-13,
                    "{map:?} point {m} {x:?} channel {ch}: {} vs {want}",
                    got[ch]
                );
            }
            // The table gradient of g . encode(x): the same weights times g, off-grid corners
            // never written.
            let g = [0.7, -1.3];
            let mut grad = vec![0.0; d.n_params()];
            e.backward(Simd::active(), &t, &[x], &g, 2, 0, &mut grad);
            for (v, wv) in w.iter().enumerate() {
                for ch in 0..2 {
                    let want = wv * g[ch];
                    assert!(
                        (grad[2 * v + ch] - want).abs() <= 1e-13,
                        "{map:?} point {m} vertex {v}: {} vs {want}",
                        grad[2 * v + ch]
                    );
                }
            }
            let s: f64 = w.iter().sum();
            let k = if s == 0.0 {
                0
            } else if s < 1.0 - 1e-9 {
                1
            } else {
                2
            };
            touched[k] = true;
        }
        // The set holds points outside (every weight 0), across an edge (part of the hat
        // mass off the grid) and inside.
        assert_eq!(touched, [true; 3], "{map:?}");
    }
}
