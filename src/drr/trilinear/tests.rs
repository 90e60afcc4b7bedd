//! The trilinear ray-march's pieces against their definitions: the zero-padded interpolant
//! summed over the corners in the grid, and each ray's lattice split into the samples before,
//! on and after the fast path found by walking the whole lattice.

use super::super::grid::Grid;
use crate::geometry::{ConeBeam, Mode};
use crate::real::Real;
use crate::volume::Volume;
use rand::{RngExt, SeedableRng};

/// The zero-padded interpolant by its definition: the corners outside the grid skipped.
fn padded_by_definition<R: Real>(grid: &Grid<R>, q: [f64; 3]) -> R {
    let mut at = [[None; 2]; 3];
    let mut wt = [[R::zero(); 2]; 3];
    for a in 0..3 {
        let n = grid.n[a];
        if !(q[a] > -1.0 && q[a] < n as f64) {
            return R::zero();
        }
        let fl = q[a].floor();
        let f = R::c(q[a] - fl);
        let i = fl as i64;
        at[a] = [i, i + 1].map(|i| (i >= 0 && i < n as i64).then_some(i as usize));
        wt[a] = [R::one() - f, f];
    }
    let [nx, ny, _] = grid.n;
    let mut acc = R::zero();
    for corner in 0..8 {
        let (ux, uy, uz) = (corner & 1, (corner >> 1) & 1, corner >> 2);
        if let (Some(x), Some(y), Some(z)) = (at[0][ux], at[1][uy], at[2][uz]) {
            let w = R::one() * wt[0][ux] * wt[1][uy] * wt[2][uz];
            acc += w * grid.data[x + nx * (y + ny * z)];
        }
    }
    acc
}

fn check<R: Real>(seed: u64) {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    for _ in 0..200 {
        let (n, data) = super::super::grid::random_values::<R>(&mut rng, 4);
        let grid = Grid::unit(&data, n);
        for _ in 0..200 {
            // Outside, on the faces' half-voxel shells, on lattice points, inside.
            let q = n.map(|na| match rng.random_range(0..4) {
                0 => rng.random_range(-1.5..na as f64 + 0.5),
                1 => rng.random_range(-1.0..0.0),
                2 => rng.random_range(-1..na as i64) as f64,
                _ => rng.random_range(na as f64 - 1.0..na as f64),
            });
            let fast = super::sample_padded(&grid, q);
            let slow = padded_by_definition(&grid, q);
            assert_eq!(fast.f64().to_bits(), slow.f64().to_bits(), "{n:?} {q:?}");
        }
    }
}

#[test]
fn padded_sample_matches_the_sum_over_the_corners_in_the_grid() {
    check::<f32>(1);
    check::<f64>(2);
}

/// Continuous voxel index (centres at integers) of the lattice point `o + i h d`.
fn index_of<R: Real>(grid: &Grid<R>, ray: ([f64; 3], [f64; 3], f64), i: i64) -> [f64; 3] {
    let (o, d, h) = ray;
    std::array::from_fn(|a| (o[a] + i as f64 * h * d[a] - grid.lo[a]) / grid.s[a] - 0.5)
}

/// The first and last lattice index `i` (`i >= 0` for a cone beam) whose point `o + i h d`, in
/// continuous voxel index, lies in `[lo, n - hi_below_n]` on every axis, found by walking the
/// lattice across the whole scene; `None` when no point does. The points between are checked
/// to lie in the box too (a convex box meets a line in one interval).
fn lattice_span<R: Real>(
    grid: &Grid<R>,
    ray: ([f64; 3], [f64; 3], f64),
    cone: bool,
    lo: f64,
    hi_below_n: f64,
) -> Option<(i64, i64)> {
    let reach = 4000.0;
    let last = (reach / ray.2) as i64;
    let first = if cone { 0 } else { -last };
    let inside = |i: i64| {
        let q = index_of(grid, ray, i);
        (0..3).all(|a| q[a] >= lo && q[a] <= grid.n[a] as f64 - hi_below_n)
    };
    let a = (first..=last).find(|&i| inside(i))?;
    let b = (a..=last).take_while(|&i| inside(i)).last()?;
    assert!(
        !(b + 1..=last).any(inside),
        "the box meets the ray in one interval"
    );
    Some((a, b))
}

/// A random scene: a volume of 1 to 6 voxels per axis (values in [0.5, 2)), spacings, offset,
/// accuracy and angle, a cone beam for even `case` and a parallel one for odd, and a 12 x 12
/// detector a little smaller than the volume's shadow (rays that miss, graze a corner with one
/// sample, and cross).
fn random_scene<R: Real>(rng: &mut impl rand::Rng, case: usize) -> (Volume<R>, ConeBeam, f64) {
    let dims = [0; 3].map(|_| rng.random_range(1..=6usize));
    let spacing = [0; 3].map(|_| rng.random_range(0.5..2.0));
    let mut vol = Volume::<R>::zeros(dims, spacing);
    vol.offset = [0; 3].map(|_| rng.random_range(-1.0..1.0));
    vol.data
        .iter_mut()
        .for_each(|v| *v = R::c(rng.random_range(0.5..2.0)));
    let cone = case.is_multiple_of(2);
    let diag = (0..3)
        .map(|a| (dims[a] as f64 * spacing[a]).powi(2))
        .sum::<f64>()
        .sqrt();
    let (dso, dsd) = (60.0, 90.0);
    let shadow = diag * if cone { dsd / (dso - diag) } else { 1.0 };
    let n_det = 12;
    let pitch = 0.7 * shadow / n_det as f64;
    let geo = ConeBeam {
        dsd,
        dso,
        n_detector: [n_det, n_det],
        d_detector: [pitch * rng.random_range(0.9..1.1), pitch],
        n_voxel: dims,
        d_voxel: spacing,
        off_origin: vol.offset,
        off_detector: [0.0; 2].map(|_| rng.random_range(-0.1..0.1) * shadow),
        mode: if cone { Mode::Cone } else { Mode::Parallel },
        accuracy: rng.random_range(0.3..1.0),
    };
    let angle = rng.random_range(0.0..std::f64::consts::TAU);
    (vol, geo, angle)
}

/// Each ray's zero-padded samples (`plan_runs`' `before_run`, fast path and `after`, and the
/// benchmark's `sample_count`) against the lattice points in the box of the zero-padded
/// interpolant (box + half a voxel) and in the box of voxel centres, found by walking the whole
/// lattice: random volumes (one voxel on an axis included), spacings, offsets, angles,
/// accuracies, both beams, and detectors reaching past the volume's shadow (rays that miss,
/// graze a corner with one sample, and cross).
#[test]
fn each_ray_s_samples_split_where_the_lattice_meets_the_boxes() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let (mut single, mut fast, mut none) = (0, 0, 0);
    for case in 0..60 {
        let (vol, geo, angle) = random_scene::<f32>(&mut rng, case);
        let (grid, cone, n_det) = (Grid::new(&vol), geo.mode == Mode::Cone, geo.n_detector[0]);
        let cam = geo.camera(angle);
        let setup = super::Setup::new(&grid, geo.accuracy);
        for row in 0..n_det {
            for col in 0..n_det {
                let (o, d, h, _) = super::ray(&grid, &setup, &cam, col, row);
                let at = format!("case {case}, pixel ({col}, {row})");
                let outer = lattice_span(&grid, (o, d, h), cone, -1.0, 0.0);
                let inner = lattice_span(&grid, (o, d, h), cone, 0.0, 1.0);
                let plan = super::plan_runs(&grid, &setup, &cam, col, row);
                let count = super::sample_count(&setup, &cam, o, d, h);
                let empty = |r: (i64, i64)| r.0 > r.1;
                let Some((a, b)) = outer else {
                    none += 1;
                    assert_eq!(count, 0, "{at}");
                    assert!(empty(plan.before_run) && empty(plan.after), "{at}");
                    assert_eq!(plan.march.count, 0, "{at}");
                    continue;
                };
                single += usize::from(a == b);
                assert_eq!(count, (b - a + 1) as u64, "{at}");
                match inner.filter(|_| grid.n.iter().all(|&n| n >= 2)) {
                    Some((c, e)) => {
                        fast += 1;
                        assert_eq!(plan.before_run, (a, c - 1), "{at}");
                        assert_eq!(plan.march.count, (e - c + 1) as usize, "{at}");
                        assert_eq!(plan.after, (e + 1, b), "{at}");
                        let q = index_of(&grid, (o, d, h), c);
                        for ax in 0..3 {
                            let q = q[ax];
                            let p = plan.march.p[ax] as f64 / super::FIX;
                            assert!((p - q).abs() < 1e-9, "{at}: axis {ax}: {p} vs {q}");
                            let dq = plan.march.dp[ax] as f64 / super::FIX;
                            assert!((dq - h * d[ax] / grid.s[ax]).abs() < 1e-9, "{at}");
                        }
                    }
                    None => {
                        assert_eq!(plan.before_run, (a, b), "{at}");
                        assert_eq!(plan.march.count, 0, "{at}");
                        assert!(empty(plan.after), "{at}");
                    }
                }
            }
        }
    }
    eprintln!("rays: {none} without samples, {single} with one, {fast} with a fast path");
    assert!(
        none > 100 && single > 0 && fast > 1000,
        "{none} {single} {fast}"
    );
}

/// Each ray's value against `h x` the sum, over every lattice point the walk of the scene finds
/// in the box + half a voxel, of the zero-padded interpolant by its definition (the fast path,
/// its ends moved to the zero-padded path, and the samples before and after, all at once): on
/// the random scenes, and on parallel beams along `+x` and `-x` whose samples land on voxel
/// centres (pixel centres on the centre lines of `y` and `z`), where the fast path's end samples
/// on the last voxel centre, and whole rays on the last centre line of `y` or `z`, take the
/// zero-padded path.
#[test]
fn each_ray_is_h_times_the_sum_of_the_interpolant_over_its_lattice() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(8);
    let mut scenes: Vec<_> = (0..40)
        .map(|case| random_scene::<f64>(&mut rng, case))
        .collect();
    for angle in [0.0, std::f64::consts::PI] {
        let mut vol = Volume::<f64>::zeros([5, 4, 3], [1.0; 3]);
        vol.data
            .iter_mut()
            .for_each(|v| *v = rng.random_range(0.5..2.0));
        let mut geo = ConeBeam::centred([3, 4], [1.0, 1.0], vol.dims, vol.spacing);
        geo.mode = Mode::Parallel;
        geo.accuracy = 0.5;
        scenes.push((vol, geo, angle));
    }
    let mut moved = 0;
    for (case, (vol, geo, angle)) in scenes.iter().enumerate() {
        let (grid, cone) = (Grid::new(vol), geo.mode == Mode::Cone);
        let cam = geo.camera(*angle);
        let setup = super::Setup::new(&grid, geo.accuracy);
        for row in 0..geo.n_detector[0] {
            for col in 0..geo.n_detector[1] {
                let (got, _) = super::pixel(&grid, &setup, &cam, col, row);
                let (o, d, h, _) = super::ray(&grid, &setup, &cam, col, row);
                let span = lattice_span(&grid, (o, d, h), cone, -1.0, 0.0);
                let sum: f64 = span
                    .into_iter()
                    .flat_map(|(a, b)| a..=b)
                    .map(|i| padded_by_definition(&grid, index_of(&grid, (o, d, h), i)))
                    .sum();
                let want = h * sum;
                let at = format!("case {case}, pixel ({col}, {row})");
                assert!(
                    (got - want).abs() <= 1e-9 * want.max(1.0),
                    "{at}: {got} vs {want}"
                );
                let plan = super::plan_runs(&grid, &setup, &cam, col, row);
                let inner = lattice_span(&grid, (o, d, h), cone, 0.0, 1.0);
                let fast = inner.map_or(0, |(c, e)| (e - c + 1) as usize);
                moved += usize::from(plan.fast && plan.march.count < fast);
                if case == 40 {
                    // Exact positions (angle 0): the fast path holds the samples in [0, n - 1)
                    // on every axis (one on the last centre of any axis takes the zero-padded
                    // path).
                    let strict = span.into_iter().flat_map(|(a, b)| a..=b).filter(|&i| {
                        let q = index_of(&grid, (o, d, h), i);
                        (0..3).all(|a| q[a] >= 0.0 && q[a] < grid.n[a] as f64 - 1.0)
                    });
                    assert_eq!(plan.march.count, strict.count(), "{at}");
                }
            }
        }
    }
    assert!(
        moved >= 6,
        "{moved} rays with end samples moved off the fast path"
    );
}

/// `fast_range` on exact positions: a sample on the last voxel centre of any axis, at either
/// end of the range, leaves the fast path (its 8 neighbours are not all inside the grid) and is
/// added to `moved` through the zero-padded path; the others stay, from the first sample kept.
#[test]
fn end_samples_on_the_last_centre_of_each_axis_take_the_padded_path() {
    let n = [4, 5, 6];
    let data: Vec<f64> = (0..120).map(|i| 1.0 + i as f64 * 0.125).collect();
    let grid = Grid::unit(&data, n);
    for axis in 0..3 {
        for leading in [false, true] {
            // Four steps from the centre box's middle to the last centre of `axis`, or back.
            let mut q0 = [1.0, 1.5, 2.0];
            let mut dq = [0.125, 0.25, 0.375];
            let last = (n[axis] - 1) as f64;
            dq[axis] = (last - q0[axis]) / 4.0;
            if leading {
                // The same four steps walked back from the last centre.
                q0 = std::array::from_fn(|a| q0[a] + 4.0 * dq[a]);
                dq = dq.map(|v| -v);
            }
            let mut moved = 0.0;
            let m = super::fast_range(&grid, q0, dq, 0, 4, &mut moved);
            let on_last = if leading { 0 } else { 4 };
            let q = super::at(q0, dq, on_last);
            assert_eq!(q[axis], last, "axis {axis}");
            assert_eq!(m.count, 4, "axis {axis}, leading {leading}");
            let first = if leading { 1 } else { 0 };
            let p = super::at(q0, dq, first).map(|v| (v * super::FIX) as i64);
            assert_eq!(m.p, p, "axis {axis}, leading {leading}");
            assert_eq!(moved, padded_by_definition(&grid, q), "axis {axis}");
        }
    }
}

/// `fast_range` when every sample lies on the last centre line of `y`: all leave the fast path,
/// each added to `moved` once, in order, and none past the range.
#[test]
fn a_range_on_the_last_centre_line_takes_the_padded_path_whole() {
    let n = [4, 5, 6];
    let data: Vec<f64> = (0..120).map(|i| 1.0 + i as f64 * 0.125).collect();
    let grid = Grid::unit(&data, n);
    let (q0, dq) = ([0.5, 4.0, 1.0], [0.25, 0.0, 0.5]);
    let mut moved = 0.0;
    let m = super::fast_range(&grid, q0, dq, 1, 4, &mut moved);
    assert_eq!(m.count, 0);
    let want = (1..=4).fold(0.0, |acc, i| {
        acc + padded_by_definition(&grid, super::at(q0, dq, i))
    });
    assert_eq!(moved, want);
}
