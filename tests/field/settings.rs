//! `FieldConfig`: every range `validate` checks, at both of its endpoints (the last value
//! refused and the first accepted), the presets' schedule arithmetic, and the names tables use.

use unispine::field::{EncoderConfig, FieldConfig, RayPixels, MAX_GRID_PARAMS, MAX_ITERATIONS};

use super::{dense, small_cfg, vm};

fn base() -> FieldConfig {
    small_cfg(EncoderConfig::Frequency { bands: 2 })
}

/// `set` applied to the base settings is accepted (`ok`) or refused naming `name`.
fn check(what: &str, set: impl Fn(&mut FieldConfig), ok: bool, name: &str) {
    let mut c = base();
    set(&mut c);
    match (c.validate(), ok) {
        (Ok(()), true) => {}
        (Err(e), false) => {
            let e = e.to_string();
            assert!(e.contains(name), "{what}: {e}");
        }
        (r, _) => panic!(
            "{what}: expected {}, got {r:?}",
            if ok { "ok" } else { "an error" }
        ),
    }
}

#[test]
fn every_count_is_refused_at_zero_and_accepted_at_one() {
    type Set = fn(&mut FieldConfig, usize);
    let counts: [(&str, Set); 5] = [
        ("n_rays", |c, v| c.n_rays = v),
        ("n_samples", |c, v| c.n_samples = v),
        ("iterations", |c, v| c.iterations = v),
        ("lr_step", |c, v| c.lr_step = v),
        ("eval_stride", |c, v| c.eval_stride = v),
    ];
    for (name, set) in counts {
        check(name, |c| set(c, 0), false, name);
        check(name, |c| set(c, 1), true, name);
    }
    check("iterations", |c| c.iterations = MAX_ITERATIONS, true, "");
    check(
        "iterations",
        |c| c.iterations = MAX_ITERATIONS + 1,
        false,
        "iterations",
    );
}

#[test]
fn every_rate_and_the_bound_must_be_finite_and_above_their_floor() {
    type Set = fn(&mut FieldConfig, f64);
    let reals: [(&str, Set, f64); 3] = [
        ("lr", |c, v| c.lr = v, 0.0),
        ("lr_gamma", |c, v| c.lr_gamma = v, 0.0),
        ("bound", |c, v| c.bound = v, 1e-5),
    ];
    for (name, set, floor) in reals {
        for bad in [floor, -1.0, f64::INFINITY, f64::NAN, f64::NEG_INFINITY] {
            check(&format!("{name} = {bad}"), |c| set(c, bad), false, name);
        }
        // The smallest value above the floor.
        let next = f64::from_bits(floor.to_bits() + 1);
        check(&format!("{name} = {next:e}"), |c| set(c, next), true, "");
        check(&format!("{name} = 1e300"), |c| set(c, 1e300), true, "");
    }
}

#[test]
fn every_encoder_size_is_checked_at_both_ends() {
    let hash = |levels, features, table_size, base_resolution| EncoderConfig::HashGrid {
        levels,
        features,
        table_size,
        base_resolution,
    };
    let cases: Vec<(EncoderConfig, bool, &str)> = vec![
        (EncoderConfig::Frequency { bands: 30 }, true, ""),
        (EncoderConfig::Frequency { bands: 31 }, false, "bands"),
        (EncoderConfig::Frequency { bands: 0 }, true, ""),
        // Hash grid: counts, the table's size (a power of two in 2..=2^26) and the finest
        // resolution base * 2^(levels - 1) <= 2^30 with at most 24 levels.
        (hash(0, 2, 64, 4), false, "levels"),
        (hash(1, 0, 64, 4), false, "features"),
        (hash(1, 2, 64, 0), false, "base_resolution"),
        (hash(1, 1, 64, 1), true, ""),
        (hash(1, 2, 1, 4), false, "table_size"),
        (hash(1, 2, 2, 4), true, ""),
        (hash(1, 2, 1 << 26, 4), true, ""),
        (hash(1, 2, 1 << 27, 4), false, "table_size"),
        (hash(1, 2, 96, 4), false, "table_size"),
        (hash(24, 2, 64, 1), true, ""),
        (hash(25, 2, 64, 1), false, "levels"),
        (hash(11, 2, 64, 1 << 20), true, ""),
        (hash(11, 2, 64, (1 << 20) + 1), false, "levels"),
        (hash(1, 2, 64, 1 << 30), true, ""),
        (hash(1, 2, 64, (1 << 30) + 1), false, "levels"),
        // TensoRF VM: rank and out_dim >= 1, out_dim <= 4096, resolution in 2..=65536 and at
        // most MAX_GRID_PARAMS plane values (3 x 1 x 8192^2 = 1.5 x 2^27 fits, x 2 does not).
        (vm(16, 0, 8), false, "components"),
        (vm(16, 1, 1), true, ""),
        (vm(16, 1, 0), false, "out_dim"),
        (vm(16, 1, 4096), true, ""),
        (vm(16, 1, 4097), false, "out_dim"),
        (vm(1, 1, 8), false, "resolution"),
        (vm(2, 1, 8), true, ""),
        (vm(8192, 1, 8), true, ""),
        (vm(8192, 2, 8), false, "plane values"),
        (vm(65537, 1, 8), false, "2..=65536"),
        // Dense grid: features >= 1, resolution in 2..=65536, resolution^3 x features values
        // at most MAX_GRID_PARAMS (512^3 x 2 = 2^28 exactly fits).
        (dense(2, 1), true, ""),
        (dense(1, 1), false, "resolution"),
        (dense(2, 0), false, "features"),
        (dense(512, 2), true, ""),
        (dense(512, 3), false, "at most"),
        (dense(65537, 1), false, "2..=65536"),
    ];
    assert_eq!(MAX_GRID_PARAMS, 1 << 28);
    for (enc, ok, name) in cases {
        check(&format!("{enc:?}"), |c| c.encoder = enc.clone(), ok, name);
    }
}

/// Upstream schedules count epochs (one pass over the training views): iterations and the
/// StepLR step scale with the view count; `set_iterations` keeps their ratio.
#[test]
fn schedules_scale_with_the_views_and_with_set_iterations() {
    let naf = FieldConfig::preset("naf-full", 50).unwrap();
    assert_eq!((naf.iterations, naf.lr_step), (1500 * 50, 500 * 50));
    let one = FieldConfig::preset("naf-full", 0).unwrap();
    assert_eq!((one.iterations, one.lr_step), (1500, 500));
    let mut c = naf.clone();
    c.set_iterations(3000);
    assert_eq!((c.iterations, c.lr_step), (3000, 1000));
    // Rounded to the nearest step: 1001 / 3 = 333.67.
    c.set_iterations(3003);
    assert_eq!(c.lr_step, 1001);
    let mut c = naf.clone();
    c.set_iterations(3004);
    assert_eq!(c.lr_step, 1001);
    let mut c = naf.clone();
    c.set_iterations(3005);
    assert_eq!(c.lr_step, 1002);
    // Never below one iteration.
    let mut c = naf;
    c.set_iterations(1);
    assert_eq!((c.iterations, c.lr_step), (1, 1));
}

#[test]
fn names_and_descriptions_of_the_presets() {
    assert!(FieldConfig::is_reduced("naf") && FieldConfig::is_reduced("nerf"));
    assert!(!FieldConfig::is_reduced("naf-full"));
    assert!(!FieldConfig::is_reduced("no-such-preset"));
    let mut c = FieldConfig::preset("naf-full", 50).unwrap();
    assert_eq!(
        c.describe(),
        "naf-full: hash grid 16 levels x 2 features, table 2^19, base 16; MLP 4 x 32 (skip 2); \
         1024 rays x 192 samples"
    );
    c.ray_pixels = RayPixels::All;
    assert_eq!(c.label(), "naf-full (all pixels)");
    c.reduced = true;
    assert_eq!(c.label(), "naf-full (reduced, all pixels)");
    c.skips.clear();
    c.encoder = EncoderConfig::DenseGrid {
        resolution: 32,
        features: 4,
    };
    assert_eq!(
        c.describe(),
        "naf-full (reduced, all pixels): dense grid 32^3 x 4; MLP 4 x 32; 1024 rays x 192 samples"
    );
    let t = FieldConfig::preset("tensorf", 50).unwrap();
    assert_eq!(
        t.describe(),
        "tensorf (reduced): TensoRF VM 3 x 8 x 256^2; MLP 4 x 64 (skip 2); 512 rays x 128 samples"
    );
    let i = FieldConfig::preset("intratomo-full", 50).unwrap();
    assert_eq!(
        i.describe(),
        "intratomo-full: frequency encoding, 6 bands; MLP 8 x 32 (skip 4); 1024 rays x 320 \
         samples"
    );
    // NeRF's presets evaluate every fifth test view, the others every one.
    assert_eq!(FieldConfig::preset("nerf", 50).unwrap().eval_stride, 5);
    assert_eq!(i.eval_stride, 1);
}
