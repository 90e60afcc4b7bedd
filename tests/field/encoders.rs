//! The field encoders beyond the gradient checks of `tests/field/gradcheck.rs`:
//! - every `unispine gradcheck` field row (`unispine::audit::field`) within the tolerance, with
//!   a non-zero reference gradient, and the CLI's `--json` listing;
//! - the dense grid as an oracle: a collision-free hash level equals it bit for bit (dense
//!   indexing, and a hashed level whose touched corners have distinct slots); a full-rank
//!   TensoRF VM (corrected lines) built from a dense grid reproduces it;
//! - TensoRF's upstream line factor: the plane's column at x = 0, the line parameters unused;
//! - bit-identical encoder backward and training gradients for 1, 2 and 8 threads;
//! - bad encoder settings are errors naming the setting.

use unispine::audit::{self, field as fc};
use unispine::field::encode::{DenseGrid, Encoder, GridMap, HashGrid, TensorVm, VmLines};
use unispine::field::mlp::OutAct;
use unispine::field::train::{loss_and_grad, Sampling};
use unispine::field::{EncoderConfig, Field, FieldConfig};
use unispine::simd::Simd;

use crate::common;
use crate::{dense, vm};

#[test]
fn field_gradcheck_rows_pass() {
    let rows = fc::rows();
    for r in &rows {
        eprintln!(
            "{} {} {} {}: rel {:.2e} (scale {:.2e})",
            r.stage, r.case, r.variant, r.group, r.rel, r.scale
        );
        assert!(r.passes(), "{r:?}");
        assert!(r.scale > 1e-6, "a zero reference checks nothing: {r:?}");
    }
    let has = |stage: &str, case: &str, variant: &str, group: &str| {
        rows.iter().any(|r| {
            r.stage == stage && r.case == case && r.variant.contains(variant) && r.group == group
        })
    };
    for (case, variant, groups) in [
        ("frequency", "", &["points"][..]),
        ("hash-grid", "", &["table", "points"]),
        ("tensorf-vm", "upstream", &["planes", "basis", "points"]),
        (
            "tensorf-vm",
            "corrected",
            &["planes", "lines", "basis", "points"],
        ),
        ("dense-grid", "", &["table", "points"]),
    ] {
        for g in groups {
            assert!(
                has("field-encoder", case, variant, g),
                "{case} {variant} {g}"
            );
        }
        let enc = if case == "frequency" {
            "mlp"
        } else {
            "encoder"
        };
        assert!(
            has("field-loss", case, variant, enc),
            "loss {case} {variant}"
        );
    }
    for act in ["leakyrelu", "sigmoid", "softplus"] {
        assert!(has("field-mlp", "5x6x5", act, "params"), "{act}");
        assert!(has("field-mlp", "5x6x5", act, "inputs"), "{act}");
    }
    assert!(has("field-render", "4 rays x 6", "", "mu"));
    assert!(audit::worst(&rows) < audit::TOLERANCE);
}

#[test]
fn gradcheck_points_keep_off_cell_faces() {
    // Every grid of the checked encoders is in the list the points are kept away from.
    for (_, _, e) in fc::encoder_cases() {
        let grids: Vec<(usize, GridMap)> = match &e {
            Encoder::HashGrid(h) => (0..h.levels)
                .map(|l| ((h.base << l) + 1, GridMap::Ngp))
                .collect(),
            Encoder::TensorVm(v) => vec![(v.resolution, GridMap::AlignCorners)],
            Encoder::DenseGrid(d) => vec![(d.resolution, d.map)],
            Encoder::Frequency(_) => vec![],
        };
        for g in grids {
            assert!(fc::grid_spacings().contains(&g), "{g:?}");
        }
    }
    for seed in 200..205 {
        let m = fc::cell_margin(&fc::points(7, seed));
        // The 5-point stencil moves a point by 2 x 1e-6 m, far less than the margin.
        assert!(m >= fc::CELL_MARGIN, "{m}");
        assert!(m * 0.6 / 8.0 > 4.0 * fc::H_POINT);
    }
}

#[test]
fn gradcheck_json_lists_every_row() {
    let o = common::cli::bin()
        .args(["gradcheck", "--stage", "field", "--json"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let rows = v["rows"].as_array().unwrap();
    assert_eq!(rows.len(), fc::rows().len());
    for r in rows {
        for k in ["stage", "case", "variant", "group"] {
            assert!(r[k].as_str().is_some_and(|s| !s.is_empty()), "{r}");
        }
        let rel = r["rel"].as_f64().unwrap();
        assert!(
            rel <= v["tolerance"].as_f64().unwrap() && r["pass"] == true,
            "{r}"
        );
    }
    assert!(v["worst"].as_f64().unwrap() < 1e-6);
    let o = common::cli::bin()
        .args(["gradcheck", "--stage", "mlp"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--stage"));
}

pub(crate) fn rand_vec(n: usize, seed: u64) -> Vec<f64> {
    fc::uniform(n, -1.0, 1.0, seed)
}

fn encode_all(e: &Encoder, p: &[f64], pts: &[[f64; 3]]) -> Vec<f64> {
    let od = e.out_dim();
    let mut out = vec![0.0; pts.len() * od];
    for (x, o) in pts.iter().zip(out.chunks_mut(od)) {
        e.encode(p, *x, o);
    }
    out
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

#[test]
fn collision_free_hash_levels_equal_dense_grids() {
    // T = 2^12: levels R = 2, 4, 8 (27, 125, 729 vertices) are all dense-indexed.
    let h = HashGrid::new(3, 2, 12, 2, 0.3);
    let table = rand_vec(h.n_params(), 1);
    let pts = fc::points(40, 2);
    let g = rand_vec(pts.len() * h.out_dim(), 3);
    let hash = Encoder::HashGrid(h.clone());
    let out = encode_all(&hash, &table, &pts);
    let mut gh = vec![0.0; h.n_params()];
    hash.backward(Simd::active(), &table, &pts, &g, h.out_dim(), 0, &mut gh);
    for l in 0..3 {
        let d = DenseGrid {
            resolution: (2 << l) + 1,
            features: 2,
            bound: 0.3,
            map: GridMap::Ngp,
        };
        let r = h.offsets[l] * 2..h.offsets[l + 1] * 2;
        assert_eq!(r.len(), d.n_params());
        let dense = Encoder::DenseGrid(d);
        let od = encode_all(&dense, &table[r.clone()], &pts);
        let level: Vec<f64> = out
            .chunks(6)
            .flat_map(|o| o[2 * l..2 * l + 2].to_vec())
            .collect();
        assert_eq!(bits(&od), bits(&level), "level {l}");
        let mut gd = vec![0.0; r.len()];
        dense.backward(
            Simd::active(),
            &table[r.clone()],
            &pts,
            &g,
            6,
            2 * l,
            &mut gd,
        );
        assert_eq!(bits(&gd), bits(&gh[r]), "level {l} gradient");
    }
}

#[test]
fn hashed_level_with_distinct_slots_equals_dense_grid() {
    // One level, R = 16 (17^3 = 4913 vertices) in T = 2^12 slots: hashed. Points whose corners
    // would share a slot with another vertex already used are skipped, so the table built from
    // the dense grid (slot(i, j, k) = D[i, j, k], the hash written out here) is exact for them.
    let t = 1usize << 12;
    let h = HashGrid::new(1, 2, 12, 16, 0.3);
    assert_eq!(h.offsets[1], t);
    let d = DenseGrid {
        resolution: 17,
        features: 2,
        bound: 0.3,
        map: GridMap::Ngp,
    };
    let slot = |v: usize| {
        let (i, j, k) = (v % 17, (v / 17) % 17, v / 289);
        ((i as u32) ^ (j as u32).wrapping_mul(19_349_663) ^ (k as u32).wrapping_mul(83_492_791))
            as usize
            % t
    };
    let dense_table = rand_vec(d.n_params(), 4);
    let mut used: std::collections::HashMap<usize, usize> = Default::default();
    let mut pts = Vec::new();
    for p in fc::points(60, 5) {
        let (idx, _, _, _) = d.corners(p);
        let mut trial = used.clone();
        let ok = idx.iter().all(|&v| *trial.entry(slot(v)).or_insert(v) == v);
        if ok {
            used = trial;
            pts.push(p);
        }
    }
    assert!(pts.len() >= 10, "{} points", pts.len());
    let mut table = rand_vec(h.n_params(), 6);
    for (&s, &v) in &used {
        table[2 * s..2 * s + 2].copy_from_slice(&dense_table[2 * v..2 * v + 2]);
    }
    let (hash, dense) = (Encoder::HashGrid(h.clone()), Encoder::DenseGrid(d.clone()));
    assert_eq!(
        bits(&encode_all(&hash, &table, &pts)),
        bits(&encode_all(&dense, &dense_table, &pts))
    );
    let g = rand_vec(pts.len() * 2, 7);
    let (mut gh, mut gd) = (vec![0.0; h.n_params()], vec![0.0; d.n_params()]);
    hash.backward(Simd::active(), &table, &pts, &g, 2, 0, &mut gh);
    dense.backward(Simd::active(), &dense_table, &pts, &g, 2, 0, &mut gd);
    for (&s, &v) in &used {
        assert_eq!(bits(&gh[2 * s..2 * s + 2]), bits(&gd[2 * v..2 * v + 2]));
    }
    let touched = gh.iter().filter(|x| **x != 0.0).count();
    assert_eq!(touched, gd.iter().filter(|x| **x != 0.0).count());
}

#[test]
fn full_rank_vm_reproduces_its_dense_grid() {
    // D(x, y, z) = sum_k bilinear(D[:, :, k])(x, y) lin_k(z): the (x, y) plane holds the slice
    // z = k of feature f in component k F + f, the z line is the indicator of k, the basis sums
    // the components of each feature; planes (x, z), (y, z) are zero.
    let (n, nf) = (5, 2);
    let d = DenseGrid {
        resolution: n,
        features: nf,
        bound: 0.3,
        map: GridMap::AlignCorners,
    };
    let c = n * nf;
    let vm = TensorVm {
        resolution: n,
        components: c,
        out_dim: nf,
        bound: 0.3,
        lines: VmLines::Corrected,
    };
    let dt = rand_vec(d.n_params(), 8);
    let (loff, boff) = vm.offsets();
    let mut p = vec![0.0; vm.n_params()];
    for k in 0..n {
        for f in 0..nf {
            let r = k * nf + f;
            for y in 0..n {
                for x in 0..n {
                    p[r * n * n + y * n + x] = dt[((x + n * (y + n * k)) * nf) + f];
                }
            }
            // Line 0 (the z axis) of component r.
            p[loff + r * n + k] = 1.0;
            p[boff + f * 3 * c + r] = 1.0;
        }
    }
    let pts = fc::points(50, 9);
    let a = encode_all(&Encoder::TensorVm(vm), &p, &pts);
    let b = encode_all(&Encoder::DenseGrid(d), &dt, &pts);
    let err = a
        .iter()
        .zip(&b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max);
    assert!(err < 1e-14, "{err}");
    assert!(b.iter().any(|v| v.abs() > 0.1));
}

#[test]
fn upstream_vm_line_factor_is_the_plane_column_at_zero() {
    // One component, basis = identity (3 outputs): output i = P_i(a, b) P_i(0, v). N = 5:
    // x = 0 is texel column 2 exactly, so the line factor interpolates that column only.
    let n = 5;
    let vm = TensorVm {
        resolution: n,
        components: 1,
        out_dim: 3,
        bound: 0.3,
        lines: VmLines::Upstream,
    };
    let mut p = rand_vec(vm.n_params(), 10);
    let (loff, boff) = vm.offsets();
    for a in 0..3 {
        for k in 0..3 {
            p[boff + a * 3 + k] = (a == k) as u8 as f64;
        }
    }
    let pix = |x: f64| (x / 0.3 + 1.0) / 2.0 * (n - 1) as f64;
    let sample = |plane: &[f64], px: f64, py: f64| {
        let (x0, y0) = (px.floor() as usize, py.floor() as usize);
        let (fx, fy) = (px - x0 as f64, py - y0 as f64);
        let at = |x: usize, y: usize| {
            if x < n && y < n {
                plane[y * n + x]
            } else {
                0.0
            }
        };
        at(x0, y0) * (1.0 - fx) * (1.0 - fy)
            + at(x0 + 1, y0) * fx * (1.0 - fy)
            + at(x0, y0 + 1) * (1.0 - fx) * fy
            + at(x0 + 1, y0 + 1) * fx * fy
    };
    let e = Encoder::TensorVm(vm.clone());
    for x in fc::points(10, 11) {
        let mut o = vec![0.0; 3];
        e.encode(&p, x, &mut o);
        for (i, (ab, v)) in [((0, 1), 2), ((0, 2), 1), ((1, 2), 0)]
            .into_iter()
            .enumerate()
        {
            let plane = &p[i * n * n..(i + 1) * n * n];
            let want = sample(plane, pix(x[ab.0]), pix(x[ab.1])) * sample(plane, 2.0, pix(x[v]));
            assert!((o[i] - want).abs() < 1e-15, "{i}: {} {want}", o[i]);
        }
        // The line parameters are never read: changing them changes no bit.
        let mut q = p.clone();
        q[loff..boff].iter_mut().for_each(|v| *v += 1.0);
        let mut o2 = vec![0.0; 3];
        e.encode(&q, x, &mut o2);
        assert_eq!(bits(&o), bits(&o2));
    }
    let pts = fc::points(10, 12);
    let g = rand_vec(30, 13);
    let mut gr = vec![0.0; vm.n_params()];
    e.backward(Simd::active(), &p, &pts, &g, 3, 0, &mut gr);
    assert!(gr[loff..boff].iter().all(|v| *v == 0.0));
    assert!(gr[..loff].iter().filter(|v| **v != 0.0).count() > 20);
    // The corrected mode reads the lines (and gives them a gradient).
    let mut vc = vm.clone();
    vc.lines = VmLines::Corrected;
    let mut gc = vec![0.0; vc.n_params()];
    Encoder::TensorVm(vc).backward(Simd::active(), &p, &pts, &g, 3, 0, &mut gc);
    assert!(gc[loff..boff].iter().filter(|v| **v != 0.0).count() > 5);
}

fn f32_field(enc: EncoderConfig) -> (FieldConfig, Field<f32>) {
    let (cfg, f) = fc::small_field(enc, OutAct::LeakyRelu, 14);
    let params = f.params.iter().map(|&v| v as f32).collect();
    let f32f = Field::<f32> {
        encoder: f.encoder.clone(),
        mlp: f.mlp.clone(),
        params,
    };
    (cfg, f32f)
}

#[test]
fn encoders_are_bit_identical_for_1_2_8_threads() {
    let rays: Vec<_> = (0..41)
        .map(|i| unispine::field::render::Ray {
            o: [1.0, 0.0, 0.0],
            d: [-1.0, -0.1 + 0.005 * i as f64, 0.002 * i as f64 - 0.03],
        })
        .collect();
    let targets: Vec<f32> = (0..rays.len()).map(|i| 0.01 * i as f32).collect();
    for (case, variant, enc) in fc::loss_encoders() {
        let (cfg, f) = f32_field(enc);
        let ne = f.n_encoder_params();
        // 700 points: several of the VM backward's 256-point chunks.
        let pts: Vec<[f32; 3]> = fc::points(700, 15)
            .iter()
            .map(|p| p.map(|v| v as f32))
            .collect();
        let od = f.encoder.out_dim();
        let g: Vec<f32> = rand_vec(pts.len() * od, 16)
            .iter()
            .map(|&v| v as f32)
            .collect();
        let mut out = Vec::new();
        for t in [1, 2, 8] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(t)
                .build()
                .unwrap();
            let (l, grad) = pool.install(|| {
                loss_and_grad(
                    &f,
                    &rays,
                    &targets,
                    &Sampling::new((0.7, 1.3), cfg.n_samples, 0.3, &fc::test_jitter),
                )
            });
            let mut ge = vec![0.0f32; ne];
            pool.install(|| {
                f.encoder
                    .backward(Simd::active(), &f.params[..ne], &pts, &g, od, 0, &mut ge)
            });
            let enc = f.encode(&pts);
            out.push((
                l.to_bits(),
                grad.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                ge.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                enc.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            ));
        }
        assert!(out[0].1.iter().any(|&b| b != 0), "{case} {variant}");
        assert_eq!(out[0], out[1], "{case} {variant}: 1 vs 2 threads");
        assert_eq!(out[0], out[2], "{case} {variant}: 1 vs 8 threads");
    }
}

#[test]
fn bad_encoder_settings_name_the_setting() {
    let base = FieldConfig::preset("tensorf", 10).unwrap();
    for (enc, name, also) in [
        (vm(16, 0, 8), "components", "rank"),
        (vm(0, 4, 8), "resolution", "got 0"),
        (vm(1, 4, 8), "resolution", "2..="),
        (vm(16, 4, 0), "out_dim", "> 0"),
        (vm(65536, 8, 32), "components", "at most"),
        (dense(0, 2), "resolution", "got 0"),
        (dense(8, 0), "features", "> 0"),
        (dense(4096, 8), "resolution", "at most"),
        (
            EncoderConfig::HashGrid {
                levels: 2,
                features: 2,
                table_size: 3000,
                base_resolution: 4,
            },
            "table_size",
            "power of two",
        ),
    ] {
        let mut c = base.clone();
        c.encoder = enc.clone();
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains(name) && e.contains(also), "{enc:?}: {e}");
        // Field::new validates first: no allocation of a huge grid.
        assert!(Field::<f32>::new(&c).is_err());
    }
    let mut c = base.clone();
    c.n_samples = 0;
    assert!(c.validate().unwrap_err().to_string().contains("n_samples"));
    let mut c = base;
    c.skips = vec![3];
    let e = c.validate().unwrap_err().to_string();
    assert!(e.contains("skips") && e.contains("last layer"), "{e}");
}

#[test]
fn tensorf_presets_follow_the_upstream_config() {
    // SAX-NeRF config/tensorf/*_50.yaml: num_levels 256, 4 x 64 skip 2, relu (LeakyReLU),
    // 1024 rays, 192 + 192 samples, 3000 epochs, lrate_step 1500, gamma 0.1;
    // tensorf_encoder.py: density_n_comp 8, app_dim 32.
    let full = FieldConfig::preset("tensorf-full", 50).unwrap();
    assert!(!full.reduced);
    assert_eq!(
        full.encoder,
        EncoderConfig::TensorVm {
            resolution: 256,
            components: 8,
            out_dim: 32,
            lines: VmLines::Upstream
        }
    );
    assert_eq!(
        (full.hidden_dim, full.num_layers, full.skips.clone()),
        (64, 4, vec![2])
    );
    assert_eq!(full.last_activation, OutAct::LeakyRelu);
    assert_eq!((full.n_rays, full.n_samples), (1024, 384));
    assert_eq!((full.iterations, full.lr_step), (150_000, 75_000));
    // 3 x 8 x 256^2 plane values (1.57 M), 3 x 8 x 256 line values, 32 x 24 basis.
    assert_eq!(full.build_encoder().n_params(), 1_572_864 + 6144 + 768);
    let red = FieldConfig::preset("tensorf", 50).unwrap();
    assert!(red.reduced && red.label() == "tensorf (reduced)");
    assert_eq!(
        (red.n_rays, red.n_samples, red.iterations),
        (512, 128, 15_000)
    );
    assert!(unispine::field::PRESETS.contains(&"tensorf"));
    assert!(unispine::method::Baseline::names().contains(&"tensorf-full"));
    // The initial planes are 0.1 N(0, 1): mean ~ 0, standard deviation ~ 0.1.
    let f = Field::<f64>::new(&red).unwrap();
    let (loff, _) = match &f.encoder {
        Encoder::TensorVm(v) => v.offsets(),
        _ => panic!("tensorf uses the VM"),
    };
    let pl = &f.params[..loff];
    let mean = pl.iter().sum::<f64>() / pl.len() as f64;
    let sd = (pl.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / pl.len() as f64).sqrt();
    assert!(mean.abs() < 1e-3 && (sd - 0.1).abs() < 1e-3, "{mean} {sd}");
}

/// A point that `grid_sample` cannot place on the grid (a NaN or infinite coordinate) falls
/// outside every texel and reads the zero padding: its VM encoding is 0, not NaN, in both line
/// modes.
#[test]
fn a_vm_point_off_every_grid_reads_the_zero_padding() {
    for lines in [VmLines::Upstream, VmLines::Corrected] {
        let vm = TensorVm {
            resolution: 5,
            components: 2,
            out_dim: 3,
            bound: 0.3,
            lines,
        };
        let p = rand_vec(vm.n_params(), 11);
        let e = Encoder::TensorVm(vm);
        let mut out = vec![f64::NAN; 3];
        e.encode(&p, [0.1, -0.05, 0.2], &mut out);
        assert!(out.iter().all(|v| *v != 0.0 && v.is_finite()), "{out:?}");
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            for axis in 0..3 {
                let mut x = [0.1, -0.05, 0.2];
                x[axis] = bad;
                e.encode(&p, x, &mut out);
                assert_eq!(out, [0.0; 3], "{lines:?}: x[{axis}] = {bad}");
            }
        }
    }
}

/// The VM's backward over more points than one of its chunks (256) equals the gradients of the
/// points taken one at a time and added in order, in both line modes (each chunk reads its own
/// rows of the output gradient, strided and offset).
#[test]
fn vm_backward_over_many_chunks_is_the_sum_of_its_points() {
    for lines in [VmLines::Upstream, VmLines::Corrected] {
        let e = Encoder::TensorVm(TensorVm {
            resolution: 4,
            components: 2,
            out_dim: 3,
            bound: 0.3,
            lines,
        });
        let p = rand_vec(e.n_params(), 21);
        let pts = fc::points(600, 22);
        let (stride, off) = (5, 2);
        let g = rand_vec(pts.len() * stride, 23);
        let mut block = vec![0.0; e.n_params()];
        e.backward(Simd::active(), &p, &pts, &g, stride, off, &mut block);
        let mut one = vec![0.0; e.n_params()];
        for (n, x) in pts.iter().enumerate() {
            let gn = &g[n * stride + off..n * stride + off + 3];
            e.backward(Simd::active(), &p, &[*x], gn, 3, 0, &mut one);
        }
        for (k, (a, b)) in block.iter().zip(&one).enumerate() {
            assert!(
                (a - b).abs() <= 1e-12 * b.abs().max(1.0),
                "{lines:?} {k}: {a} vs {b}"
            );
        }
        assert!(one.iter().filter(|v| **v != 0.0).count() > e.n_params() / 2);
    }
}
